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
#include <fstream>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "cli/commands.h"
#include "cli/progress.h"
#include "collection/collection.h"
#include "collection/slurm.h"
#include "flags/options.h"
#include "io/iiif.h"
#include "io/json.h"
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
    "  plan    lists the stale scans and why; the running, failed, parked and at the station "
    "apart\n"
    "  run     processes the stale scans, --jobs at a time, each into a new folder that takes\n"
    "          the scan's place whole (a killed run leaves every scan wholly old or wholly new);\n"
    "          a failure is recorded and the others go on; run again to finish what is left.\n"
    "          With --slurm, as a Slurm job array (--chunk scans a task), followed with squeue;\n"
    "          the scans of a failed or cancelled task are submitted again (--resubmit).\n"
    "          Then rebuilds the contact sheet (ROOT/index.html) and, with --iiif-base, the\n"
    "          collection's IIIF manifest (ROOT/iiif-manifest.json)\n"
    "  status  counts by state, the failures' reasons, and how often each scan was processed\n"
    "  one     processes one scan (--scan FOLDER): what each worker of run does\n"
    "  task    processes one chunk of a Slurm array's scans (--list, --chunk, --index)\n"
    "The ledger is ROOT/vellum-collection/ (deletable: no scan depends on it). The processing\n"
    "flags are those of `vellum process`; give plan, run and status the same. More in\n"
    "docs/collection.md. Exit status: 0 every scan done (the parked aside); 1 an error or a scan\n"
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
          {"all", "", "status: a line for every scan", ""},
          {"slurm", "", "run: as a Slurm job array (sbatch), followed with squeue", ""},
          {"chunk", "N", "run --slurm: scans per task", "10"},
          {"partition", "NAME", "run --slurm: the partition (else the cluster's default)", ""},
          {"account", "NAME", "run --slurm: the account to charge (else yours)", ""},
          {"cpus-per-task", "N", "run --slurm: cores per task", "2"},
          {"resubmit", "N",
           "run --slurm: times the scans of a failed or cancelled task are submitted again", "1"},
          {"steal", "yes|no",
           "run --slurm: a task done with its chunk takes scans of tasks not yet begun", "yes"},
          {"sbatch", "FLAGS", "run --slurm: more sbatch flags, ';' between (--qos=long;...)", ""},
          {"scan", "FOLDER", "one: the scan folder's name under ROOT", ""},
          {"job", "TEXT", "one, task: who runs it, for the ledger", "local"},
          {"list", "FILE", "task: the array's scans, one folder a line", ""},
          {"index", "K", "task: this task's chunk of the list (chunk K)", "0"},
          {"steal-for", "SECONDS",
           "task: then take other tasks' scans not yet begun, for this long from its start", "0"},
      },
      PipelineFlagSpecs());
}

struct Counts {
  std::map<State, int> by_state;
  // Scans still to be done: all but the done and the parked (given up at the station).
  int Left() const {
    int n = 0;
    for (const auto& [state, count] : by_state) {
      n += state == State::kDone || state == State::kParked ? 0 : count;
    }
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
  if (flags.Has("all")) {
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

// A worker's exit status when it left its scan alone: done meanwhile, or running elsewhere.
constexpr int kExitLeftAlone = 5;

int RunOne(const std::string& root, const Flags& flags) {
  UseMemoryForOneRun();  // One scan in this process, as `vellum process`.
  std::string what;
  const Status s = collection::ProcessScan(root, flags.Require("scan"), Settings(flags), &what);
  if (!s.ok()) {
    std::fprintf(stderr, "vellum collection: %s: %s\n", flags.Get("scan").c_str(),
                 s.message().c_str());
    return 1;
  }
  return what == "processed" ? 0 : kExitLeftAlone;
}

// A worker: `vellum collection one` for `folder`, killed with this process.
pid_t StartWorker(const std::string& root, const std::string& folder,
                  const collection::RunSettings& run) {
  std::vector<std::string> args = {"vellum", "collection", "one",   "--root", root,
                                   "--scan", folder,       "--job", run.job};
  if (run.retry_failed) args.push_back("--retry-failed");
  for (const auto& [name, value] : run.options) args.push_back("--" + name + "=" + value);
  const pid_t parent = getpid();
  const pid_t pid = fork();
  if (pid != 0) return pid;
  prctl(PR_SET_PDEATHSIG, SIGKILL);   // A run killed takes its workers with it,
  if (getppid() != parent) _exit(1);  // even one killed before this worker could ask so.
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

// Processes `folders` in worker processes, `jobs` at a time, a line for each as it finishes and
// a progress bar with the rate and the time left. Returns how many failed.
int RunPool(const std::string& root, const std::vector<std::string>& folders, int jobs,
            const collection::RunSettings& run) {
  Progress progress;
  const auto start = std::chrono::steady_clock::now();
  std::map<pid_t, std::pair<std::string, std::chrono::steady_clock::time_point>> workers;
  size_t next = 0, finished = 0;
  int failed = 0;
  while (next < folders.size() || !workers.empty()) {
    while (next < folders.size() && static_cast<int>(workers.size()) < jobs) {
      workers[StartWorker(root, folders[next], run)] = {folders[next],
                                                        std::chrono::steady_clock::now()};
      ++next;
    }
    int status = 0;
    const pid_t pid = waitpid(-1, &status, 0);
    if (pid < 0) break;
    const auto it = workers.find(pid);
    if (it == workers.end()) continue;
    const std::string folder = it->second.first;
    const double took =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - it->second.second).count();
    workers.erase(it);
    ++finished;
    if (WIFSIGNALED(status)) {
      static_cast<void>(collection::RecordFailure(
          root, folder, run, "the worker died of signal " + std::to_string(WTERMSIG(status))));
    }
    collection::LedgerEntry entry;
    const bool noted = collection::ReadLedger(root, folder, &entry).ok();
    const int code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    std::string said = "done";
    if (code == kExitLeftAlone) {
      said = "left alone: done or running elsewhere";
    } else if (code != 0) {
      ++failed;
      said = "failed: " + (noted ? entry.message : "no record");
    }
    progress.Clear();
    std::printf("%s: %s (%.1f s)\n", folder.c_str(), said.c_str(), took);
    std::fflush(stdout);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    progress.Update(std::to_string(finished) + "/" + std::to_string(folders.size()) + " scans, " +
                        std::to_string(static_cast<int>(finished * 3600 / seconds)) + " per hour",
                    static_cast<double>(finished) / folders.size());
  }
  progress.Clear();
  return failed;
}

// The stale scans (and the failed ones, when they are to be tried again).
std::vector<PlannedScan> ToDo(const std::vector<PlannedScan>& plan,
                              const collection::RunSettings& run) {
  std::vector<PlannedScan> todo;
  for (const PlannedScan& p : plan) {
    if (p.state == State::kStale || (p.state == State::kFailed && run.retry_failed)) {
      todo.push_back(p);
    }
  }
  return todo;
}

// The end of a run: the views rebuilt, the counts said; the exit status.
int Finish(const std::string& root, const Flags& flags, const collection::RunSettings& run,
           bool failures) {
  std::vector<PlannedScan> plan;
  const Status s = collection::Plan(root, run.options, false, &plan);
  if (!s.ok()) throw std::runtime_error(s.message());
  const bool views = RebuildViews(root, flags, plan);
  PrintCounts(plan);
  return failures || !views ? 1 : 0;
}

int RunLocal(const std::string& root, const Flags& flags) {
  collection::CleanUp(root);
  const collection::RunSettings run = Settings(flags);
  std::vector<PlannedScan> plan;
  const Status s = collection::Plan(root, run.options, false, &plan);
  if (!s.ok()) throw std::runtime_error(s.message());
  std::vector<std::string> todo;
  for (const PlannedScan& p : ToDo(plan, run)) todo.push_back(p.folder);
  int jobs = flags.GetInt("jobs", 0, 256);
  if (jobs == 0) jobs = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  std::printf("%zu scan(s) to process, %d at a time\n", todo.size(), jobs);
  std::fflush(stdout);
  const int failed = RunPool(root, todo, jobs, run);
  return Finish(root, flags, run, failed > 0);
}

// A task of a Slurm array: its chunk of the list, one scan after the other.
int RunTask(const std::string& root, const Flags& flags) {
  const std::string list = flags.Require("list");
  std::ifstream in(list);
  if (!in) throw std::runtime_error(list + ": cannot read");
  std::vector<std::string> all;
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) all.push_back(line);
  }
  const int chunk = flags.GetInt("chunk", 1, 1 << 20);
  const int index = flags.GetInt("index", 0, 1 << 20);
  const size_t from = static_cast<size_t>(index) * chunk;
  if (from >= all.size()) throw UsageError("--index " + std::to_string(index) + " is past " + list);
  const size_t to = std::min(all.size(), from + chunk);
  const std::vector<std::string> mine(all.begin() + from, all.begin() + to);
  std::printf("%s: scans %zu to %zu of %zu\n", flags.Get("job").c_str(), from + 1, to, all.size());
  std::fflush(stdout);
  const auto start = std::chrono::steady_clock::now();
  const collection::RunSettings run = Settings(flags);
  // Each scan claimed first (collection::ClaimForArray): a task that already took it keeps it.
  const std::string claims = (fs::path(list).parent_path() / "claims").string();
  int failed = 0;
  auto take = [&](const std::string& folder) {
    if (collection::ClaimForArray(claims, folder)) failed += RunPool(root, {folder}, 1, run);
  };
  for (const std::string& folder : mine) take(folder);
  // Then, for --steal-for seconds from its start, the scans of the tasks not yet begun, from the
  // list's end: the array ends when its work does, not when its slowest chunk does. A scan another
  // task of the array claimed is left to it; one done meanwhile by another run is left alone by
  // the worker (ProcessScan plans it again under its lock).
  const double steal_for = flags.GetDouble("steal-for", 0, 1e9);
  for (size_t i = all.size(); i-- > 0 && steal_for > 0;) {
    if (i >= from && i < to) continue;
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >
        steal_for) {
      break;
    }
    take(all[i]);
  }
  return failed > 0 ? 1 : 0;
}

// This program's path, for the tasks to run: the same on every node of the cluster.
std::string SelfPath() {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  return ec ? std::string("vellum") : self.string();
}

// How many of `todo` the ledger says were processed (done or failed) since `since`.
int FinishedSince(const std::string& root, const std::vector<PlannedScan>& todo,
                  const std::string& since) {
  int n = 0;
  for (const PlannedScan& p : todo) {
    collection::LedgerEntry e;
    n += collection::NotedSince(root, p.folder, since, &e);
  }
  return n;
}

// Follows the jobs until none of their tasks is queued, or every scan of `todo` was processed
// since `since` (its tasks are then ending): the progress meanwhile, from the ledger.
void Follow(const std::string& root, const std::vector<std::string>& jobs,
            const std::vector<PlannedScan>& todo, const std::string& since) {
  Progress progress;
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  // The ledger is read 20 times a second for a small collection, less often for a large one (each
  // look reads every scan's note); squeue, which asks the controller and costs the nodes' cores a
  // little each time, once a second at most: it is only needed to see tasks that ended early.
  const auto look = std::chrono::milliseconds(todo.size() > 1000  ? 2000
                                              : todo.size() > 100 ? 500
                                                                  : 50);
  const auto ask = std::max<Clock::duration>(look, std::chrono::seconds(1));
  std::vector<std::string> queued;
  Clock::time_point asked;
  for (bool first = true;; first = false) {
    const int done = todo.empty() ? 0 : FinishedSince(root, todo, since);
    if (!todo.empty() && done == static_cast<int>(todo.size())) {
      // Every scan processed: the tasks not yet begun would find nothing to do.
      for (const std::string& job : jobs) static_cast<void>(collection::CancelPending(job));
      break;
    }
    if (first || Clock::now() - asked >= ask) {
      const Status s = collection::Queued(jobs, &queued);
      if (!s.ok()) throw std::runtime_error(s.message());
      asked = Clock::now();
      if (queued.empty()) break;  // The caller reads what became of each scan from the ledger.
    }
    int running = 0;
    for (const std::string& task : queued) running += task.find("RUNNING") != std::string::npos;
    const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
    progress.Update(std::to_string(done) + "/" + std::to_string(todo.size()) + " scans, " +
                        std::to_string(running) + " task(s) running, " +
                        std::to_string(static_cast<int>(done * 3600 / std::max(1.0, seconds))) +
                        " per hour",
                    static_cast<double>(done) / std::max<size_t>(1, todo.size()));
    std::this_thread::sleep_for(look);
  }
  progress.Clear();
}

collection::SlurmSettings SlurmSettingsOf(const Flags& flags) {
  collection::SlurmSettings slurm;
  slurm.partition = flags.Get("partition");
  slurm.account = flags.Get("account");
  slurm.chunk = flags.GetInt("chunk", 1, 1 << 20);
  slurm.cpus_per_task = flags.GetInt("cpus-per-task", 1, 1024);
  slurm.vellum = SelfPath();
  const std::string steal = flags.Get("steal");
  if (steal != "yes" && steal != "no") throw UsageError("--steal must be yes or no");
  slurm.steal = steal == "yes";
  std::string extra = flags.Get("sbatch");
  for (size_t at = 0; at < extra.size();) {
    const size_t end = std::min(extra.find(';', at), extra.size());
    if (end > at) slurm.extra.push_back(extra.substr(at, end - at));
    at = end + 1;
  }
  return slurm;
}

// Writes and submits one array over `todo`; its job id.
std::string SubmitArray(const std::string& root, const std::vector<PlannedScan>& todo,
                        const collection::SlurmSettings& slurm,
                        const collection::RunSettings& run) {
  const collection::SlurmArray array = collection::MakeArray(todo, slurm.chunk);
  const std::string dir = root + "/" + collection::kLedgerFolder + "/slurm/array-" +
                          std::to_string(collection::SubmittedJobs(root).size() + 1);
  std::error_code ec;
  fs::create_directories(dir, ec);
  std::ofstream list(dir + "/scans.txt");
  for (const std::string& f : array.folders) list << f << "\n";
  list.close();
  const std::string script = dir + "/job.sh";
  Status s = WriteTextFile(
      script,
      collection::BatchScript(root, dir + "/scans.txt", dir + "/task-%a.log", array, slurm, run));
  std::string job;
  if (s.ok()) s = collection::Submit(script, &job);
  if (s.ok()) s = collection::NoteSubmitted(root, job);
  if (!s.ok()) throw std::runtime_error(s.message());
  std::printf("submitted job %s: %zu scan(s) in %d task(s) of %d, %lld MB and %d min each (%s)\n",
              job.c_str(), todo.size(), array.tasks, array.chunk,
              static_cast<long long>(array.memory_mb), array.minutes, script.c_str());
  std::fflush(stdout);
  return job;
}

int RunSlurm(const std::string& root, const Flags& flags) {
  const collection::RunSettings run = Settings(flags);
  const collection::SlurmSettings slurm = SlurmSettingsOf(flags);
  // An earlier run's array still at work (its follower killed): followed first, never doubled.
  std::vector<std::string> earlier = collection::SubmittedJobs(root), queued;
  Status s = collection::Queued(earlier, &queued);
  if (!s.ok()) throw std::runtime_error(s.message());
  if (!queued.empty()) {
    std::printf("following %zu task(s) submitted earlier\n", queued.size());
    Follow(root, earlier, {}, "");
  }
  collection::CleanUp(root);
  std::vector<PlannedScan> plan;
  s = collection::Plan(root, run.options, false, &plan);
  if (!s.ok()) throw std::runtime_error(s.message());
  std::vector<PlannedScan> todo = ToDo(plan, run);
  std::printf("%zu scan(s) to process on Slurm\n", todo.size());
  // Tasks that fail or are cancelled leave their scans stale: submitted again (--resubmit times),
  // then reported.
  const int rounds = 1 + flags.GetInt("resubmit", 0, 10);
  bool failed = false;
  for (int round = 0; round < rounds && !todo.empty(); ++round) {
    const std::string since = collection::LedgerTime();
    const std::string job = SubmitArray(root, todo, slurm, run);
    Follow(root, {job}, todo, since);
    // What became of each scan: the ledger's note since the submission, else (a task cancelled
    // or killed on it, or a scan another run did) the scan planned again.
    std::vector<PlannedScan> left;
    for (const PlannedScan& p : todo) {
      collection::LedgerEntry entry;
      const bool noted = collection::NotedSince(root, p.folder, since, &entry);
      State state = noted && entry.state == "done" ? State::kDone : State::kFailed;
      if (!noted) state = collection::PlanScan(root, p.folder, run.options, false).state;
      if (state == State::kFailed) {
        std::printf("%s: failed: %s\n", p.folder.c_str(), entry.message.c_str());
        failed = true;
      }
      if (state == State::kStale) left.push_back(p);
    }
    if (!left.empty()) {
      std::printf(
          "%zu scan(s) not processed: their task failed or was cancelled (logs in %s/%s/"
          "slurm)%s\n",
          left.size(), root.c_str(), collection::kLedgerFolder,
          round + 1 < rounds ? "; submitting them again" : "");
    }
    todo = left;
  }
  collection::CleanUp(root);
  return Finish(root, flags, run, failed || !todo.empty());
}

}  // namespace

int RunCollection(const std::vector<std::string>& args) {
  Flags flags("vellum collection plan|run|status|one --root DIR [processing flags]", kSummary,
              Specs());
  std::vector<std::string> positional, rest;
  SplitPositional(args, &positional, &rest, {"--verify", "--retry-failed", "--all", "--slurm"});
  if (!flags.Parse(rest)) return 0;
  if (positional.size() != 1) {
    throw UsageError("give one of plan, run, status, one (see --help)");
  }
  const std::string& what = positional[0];
  const std::string root = flags.Require("root");
  // A bad processing flag is said now, naming the flag, not by every scan's worker.
  static_cast<void>(collection::PipelineOptionsOf(collection::OptionsOf(flags)));
  if (what == "plan") return RunPlan(root, flags);
  if (what == "status") return RunStatus(root, flags);
  if (what == "run") return flags.Has("slurm") ? RunSlurm(root, flags) : RunLocal(root, flags);
  if (what == "one") return RunOne(root, flags);
  if (what == "task") return RunTask(root, flags);
  throw UsageError("unknown subcommand '" + what + "': plan, run, status, one or task");
}

}  // namespace vellum
