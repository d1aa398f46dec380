// vellum collection: a folder of scans reprocessed by provenance (collection/collection.h):
// plan, run (a local pool of worker processes), status, and one (a single scan, what each
// worker runs).
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "cli/commands.h"
#include "cli/progress.h"
#include "collection/collection.h"
#include "flags/options.h"
#include "io/iiif.h"
#include "runtime/memory.h"
#include "station/contact_sheet.h"

namespace vellum {
namespace fs = std::filesystem;
using collection::PlannedScan;
using collection::State;

namespace {

constexpr char kSummary[] =
    "Reprocesses a collection: a folder of scan folders as the station writes them (each with\n"
    "raw/ and its calibration, results/ and manifest-sha256.txt). A scan is up to date when its\n"
    "results were made from the same raw captures (their SHA-256), the same calibration, the same\n"
    "processing flags and the same vellum build (results/provenance.json); otherwise it is stale.\n"
    "  plan    lists the stale scans and why; the failed, parked and busy ones apart\n"
    "  run     processes the stale scans, --jobs at a time, each into a new folder that takes\n"
    "          the scan's place whole (a killed run leaves every scan wholly old or wholly new);\n"
    "          a failure is recorded and the others go on; run again to finish what is left.\n"
    "          Then rebuilds the contact sheet (ROOT/index.html) and, with --iiif-base, the\n"
    "          collection's IIIF manifest (ROOT/iiif-manifest.json)\n"
    "  status  counts by state, the failures' reasons, and how often each scan was processed\n"
    "  one     processes one scan (--scan FOLDER): what each worker of run does\n"
    "The ledger is ROOT/vellum-collection/ (deletable: no scan depends on it). The processing\n"
    "flags are those of `vellum process`. Exit status: 0 every scan done; 1 an error or a scan\n"
    "failed; 2 bad flags; 4 (plan, status) scans left to do.";

constexpr int kExitLeft = 4;

std::vector<Flags::Spec> Specs() {
  return Join(
      {
          {"root", "DIR", "the collection: a folder of scan folders", ""},
          {"jobs", "N", "run: scans processed at once (0: one per core)", "0"},
          {"verify", "", "plan, status: hash the raw captures again (else the manifests say)", ""},
          {"retry-failed", "", "run: also process the scans whose last run failed", ""},
          {"iiif-base", "URL",
           "run: the web server's URL for ROOT, for the collection's IIIF manifest", ""},
          {"label", "TEXT", "run: the IIIF manifest's label", "vellum collection"},
          {"list", "", "status: a line for every scan", ""},
          {"scan", "FOLDER", "one: the scan folder's name under ROOT", ""},
          {"job", "TEXT", "one: who runs it, for the ledger", "local"},
      },
      PipelineFlagSpecs());
}

struct Counts {
  std::map<State, int> by_state;
  int Left() const {
    int n = 0;
    for (const auto& [state, count] : by_state) n += state == State::kDone ? 0 : count;
    return n;
  }
};

Counts Count(const std::vector<PlannedScan>& plan) {
  Counts c;
  for (const PlannedScan& p : plan) ++c.by_state[p.state];
  return c;
}

void PrintCounts(const std::vector<PlannedScan>& plan) {
  const Counts c = Count(plan);
  std::printf("%zu scan(s):", plan.size());
  const char* sep = " ";
  for (State s : {State::kDone, State::kStale, State::kRunning, State::kFailed, State::kParked,
                  State::kAtStation}) {
    const auto it = c.by_state.find(s);
    std::printf("%s%d %s", sep, it == c.by_state.end() ? 0 : it->second, collection::StateName(s));
    sep = ", ";
  }
  std::printf("\n");
}

// The scans in `states`, with their reasons.
void PrintScans(const std::vector<PlannedScan>& plan, const std::vector<State>& states) {
  for (const PlannedScan& p : plan) {
    if (std::find(states.begin(), states.end(), p.state) == states.end()) continue;
    std::printf("%s: %s", p.folder.c_str(), collection::StateName(p.state));
    for (size_t i = 0; i < p.reasons.size(); ++i) {
      std::printf("%s%s", i == 0 ? ": " : "; ", p.reasons[i].c_str());
    }
    std::printf("\n");
  }
}

int RunPlan(const std::string& root, const Flags& flags) {
  std::vector<PlannedScan> plan;
  const Status s = collection::Plan(root, collection::OptionsOf(flags), flags.Has("verify"), &plan);
  if (!s.ok()) throw std::runtime_error(s.message());
  PrintScans(plan, {State::kStale});
  PrintScans(plan, {State::kRunning, State::kFailed, State::kParked, State::kAtStation});
  PrintCounts(plan);
  return Count(plan).by_state.count(State::kStale) ? kExitLeft : 0;
}

int RunStatus(const std::string& root, const Flags& flags) {
  std::vector<PlannedScan> plan;
  const Status s = collection::Plan(root, collection::OptionsOf(flags), flags.Has("verify"), &plan);
  if (!s.ok()) throw std::runtime_error(s.message());
  PrintCounts(plan);
  PrintScans(plan, {State::kFailed, State::kParked});
  std::map<int, int> by_runs;
  for (const PlannedScan& p : plan) ++by_runs[p.runs];
  std::printf("processed by collection runs:");
  for (const auto& [runs, scans] : by_runs) std::printf(" %d scan(s) %d time(s);", scans, runs);
  std::printf("\n");
  if (flags.Has("list")) {
    for (const PlannedScan& p : plan) {
      std::printf("%s  %s  runs %d\n", p.folder.c_str(), collection::StateName(p.state), p.runs);
    }
  }
  return Count(plan).Left() > 0 ? kExitLeft : 0;
}

collection::RunSettings Settings(const Flags& flags) {
  collection::RunSettings run;
  run.options = collection::OptionsOf(flags);
  run.retry_failed = flags.Has("retry-failed");
  run.job = flags.Get("job");
  return run;
}

int RunOne(const std::string& root, const Flags& flags) {
  UseMemoryForOneRun();  // One scan in this process, as `vellum process`.
  std::string what;
  const Status s = collection::ProcessScan(root, flags.Require("scan"), Settings(flags), &what);
  if (!s.ok()) {
    std::fprintf(stderr, "vellum collection: %s: %s\n", flags.Get("scan").c_str(),
                 s.message().c_str());
    return 1;
  }
  return 0;
}

// A worker: `vellum collection one` for `folder`, killed with this process.
pid_t StartWorker(const std::string& root, const std::string& folder,
                  const collection::RunSettings& run) {
  std::vector<std::string> args = {"vellum", "collection", "one",   "--root", root,
                                   "--scan", folder,       "--job", run.job};
  if (run.retry_failed) args.push_back("--retry-failed");
  for (const auto& [name, value] : run.options) args.push_back("--" + name + "=" + value);
  const pid_t pid = fork();
  if (pid != 0) return pid;
  prctl(PR_SET_PDEATHSIG, SIGKILL);  // A run killed takes its workers with it.
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  execv("/proc/self/exe", argv.data());
  std::perror("vellum collection: cannot start a worker");
  _exit(127);
}

// Rebuilds the contact sheet and, with --iiif-base, the collection's IIIF manifest.
bool RebuildViews(const std::string& root, const Flags& flags,
                  const std::vector<PlannedScan>& plan) {
  bool ok = true;
  Status s = station::WriteContactSheet(root);
  if (!s.ok()) {
    std::fprintf(stderr, "vellum collection: %s\n", s.message().c_str());
    ok = false;
  }
  std::string base = flags.Get("iiif-base");
  if (base.empty()) return ok;
  while (!base.empty() && base.back() == '/') base.pop_back();
  std::vector<IiifCanvas> all;
  for (const PlannedScan& p : plan) {
    if (p.state != State::kDone) continue;
    std::vector<IiifCanvas> canvases;
    s = ReadIiifCanvases(root + "/" + p.folder + "/results", root, base + "/iiif", &canvases);
    if (s.ok()) all.insert(all.end(), canvases.begin(), canvases.end());
  }
  const std::string file = root + "/" + kIiifManifestName;
  std::string url;
  s = UrlUnderRoot(base, root, file, &url);
  if (s.ok()) s = WriteJsonFile(file, IiifManifest(url, flags.Get("label"), all));
  if (!s.ok()) {
    std::fprintf(stderr, "vellum collection: %s\n", s.message().c_str());
    return false;
  }
  std::printf("%zu page(s) in the collection's IIIF manifest -> %s\n", all.size(), file.c_str());
  return ok;
}

int RunLocal(const std::string& root, const Flags& flags) {
  collection::CleanUp(root);
  const collection::RunSettings run = Settings(flags);
  std::vector<PlannedScan> plan;
  Status s = collection::Plan(root, run.options, false, &plan);
  if (!s.ok()) throw std::runtime_error(s.message());
  std::vector<std::string> todo;
  for (const PlannedScan& p : plan) {
    if (p.state == State::kStale || (p.state == State::kFailed && run.retry_failed)) {
      todo.push_back(p.folder);
    }
  }
  int jobs = flags.GetInt("jobs", 0, 256);
  if (jobs == 0) jobs = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  std::printf("%zu scan(s) to process, %d at a time\n", todo.size(), jobs);
  std::fflush(stdout);
  Progress progress;
  const auto start = std::chrono::steady_clock::now();
  std::map<pid_t, std::string> workers;
  size_t next = 0, finished = 0;
  int failed = 0;
  while (next < todo.size() || !workers.empty()) {
    while (next < todo.size() && static_cast<int>(workers.size()) < jobs) {
      workers[StartWorker(root, todo[next], run)] = todo[next];
      ++next;
    }
    int status = 0;
    const pid_t pid = waitpid(-1, &status, 0);
    if (pid < 0) break;
    const auto it = workers.find(pid);
    if (it == workers.end()) continue;
    const std::string folder = it->second;
    workers.erase(it);
    ++finished;
    if (WIFSIGNALED(status)) {
      static_cast<void>(collection::RecordFailure(
          root, folder, run, "the worker died of signal " + std::to_string(WTERMSIG(status))));
    }
    collection::LedgerEntry entry;
    const bool noted = collection::ReadLedger(root, folder, &entry).ok();
    const bool ok = WIFEXITED(status) && WEXITSTATUS(status) == 0;
    if (!ok) ++failed;
    progress.Clear();
    std::printf("%s: %s\n", folder.c_str(),
                ok ? "done" : ("failed: " + (noted ? entry.message : "no record")).c_str());
    std::fflush(stdout);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    progress.Update(std::to_string(finished) + "/" + std::to_string(todo.size()) + " scans, " +
                        std::to_string(static_cast<int>(finished * 3600 / seconds)) + " per hour",
                    static_cast<double>(finished) / todo.size());
  }
  progress.Clear();
  s = collection::Plan(root, run.options, false, &plan);
  if (!s.ok()) throw std::runtime_error(s.message());
  const bool views = RebuildViews(root, flags, plan);
  PrintCounts(plan);
  return failed > 0 || !views ? 1 : 0;
}

}  // namespace

int RunCollection(const std::vector<std::string>& args) {
  Flags flags("vellum collection plan|run|status|one --root DIR [processing flags]", kSummary,
              Specs());
  std::vector<std::string> positional, rest;
  SplitPositional(args, &positional, &rest, {"--verify", "--retry-failed", "--list"});
  if (!flags.Parse(rest)) return 0;
  if (positional.size() != 1) {
    throw UsageError("give one of plan, run, status, one (see --help)");
  }
  const std::string& what = positional[0];
  const std::string root = flags.Require("root");
  if (what == "plan") return RunPlan(root, flags);
  if (what == "status") return RunStatus(root, flags);
  if (what == "run") return RunLocal(root, flags);
  if (what == "one") return RunOne(root, flags);
  throw UsageError("unknown subcommand '" + what + "': plan, run, status or one");
}

}  // namespace vellum
