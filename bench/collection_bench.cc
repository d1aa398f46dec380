// Throughput of `vellum collection run` on the test collection of tests/slurm_collection_test.sh
// (18 leaves of the virtual gantry at the station's size, seeds 1 to 18, and the two recorded
// scans, the demo leaf and the curl scan):
// the local pool (one worker per core) against a real one-node Slurm cluster on this machine
// (tests/slurm/cluster.sh: munged, slurmctld, slurmd from Debian), in the same run, their
// repetitions interleaved. Each repetition processes the whole collection from its state before
// any run (a fresh copy, made outside the timing). Reported: each case's time, its scans per hour,
// and Slurm's overhead (its time over the local pool's, less one). The program runs itself inside
// scripts/netns-run.sh: the cluster talks over a private loopback.
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "bench/ratio_reporter.h"

namespace vellum {
namespace {
namespace fs = std::filesystem;

constexpr int kScans = 20;
const std::string kVellum = VELLUM_COMMAND;
const std::string kSource = VELLUM_SOURCE_DIR;

fs::path Work() {
  return fs::temp_directory_path() / ("vellum_collection_bench_" + std::to_string(getpid()));
}

// The controller's scheduling wait of each Slurm repetition (SchedulerWait), in seconds.
std::vector<double> g_waits;

bool Run(const std::string& command) { return std::system(command.c_str()) == 0; }

// Seconds since midnight of a slurmctld log line's stamp "[2026-12-07T09:48:50.504] ...".
double StampSeconds(const std::string& line) {
  const size_t t = line.find('T');
  if (line.size() < 24 || line[0] != '[' || t == std::string::npos) return -1;
  return std::stoi(line.substr(t + 1, 2)) * 3600.0 + std::stoi(line.substr(t + 4, 2)) * 60.0 +
         std::stod(line.substr(t + 7, 6));
}

// The controller's wait for the newest job in its log: from its submission to its first task's
// allocation, in seconds (slurmctld schedules what was submitted at its next pass, once a second);
// -1 when the log does not say.
double SchedulerWait(const fs::path& log) {
  std::ifstream in(log);
  double submitted = -1, allocated = -1;
  std::string job;
  for (std::string line; std::getline(in, line);) {
    size_t at = line.find("_slurm_rpc_submit_batch_job: JobId=");
    if (at != std::string::npos) {
      at += 35;
      job = line.substr(at, line.find(' ', at) - at);
      submitted = StampSeconds(line);
      allocated = -1;
    } else if (allocated < 0 && !job.empty() &&
               line.find("sched: Allocate JobId=" + job + "_") != std::string::npos) {
      allocated = StampSeconds(line);
    }
  }
  return submitted >= 0 && allocated >= submitted ? allocated - submitted : -1;
}

// The collection before any run, made once.
bool MakePristine(const fs::path& pristine) {
  const std::string rig = kSource + "/config/default_calibration.yaml";
  for (int i = 1; i <= kScans - 2; ++i) {
    const fs::path raw = pristine / ("scan-" + std::to_string(1000 + i)) / "raw";
    if (!Run(kVellum + " render --out " + raw.string() + " --calibration " + rig + " --seed " +
             std::to_string(i) + " --truth false > /dev/null 2>&1")) {
      return false;
    }
  }
  return Run(kVellum + " export " + VELLUM_DEMO_LOG + " " +
             (pristine / "scan-2000-demo/raw").string() + " > /dev/null") &&
         Run(kVellum + " export " + VELLUM_CURL_LOG + " " +
             (pristine / "scan-2001-curl/raw").string() + " > /dev/null");
}

// One case: `flags` given to `vellum collection run` over a fresh copy of the collection.
void BM_CollectionRun(benchmark::State& state, const std::string& flags) {
  const fs::path pristine = Work() / "pristine", root = Work() / "collection";
  double seconds = 0;
  for (auto _ : state) {
    state.PauseTiming();
    // Each repetition starts on an idle cluster: the last array's tasks have left it (the run
    // returns once every scan is processed, while its tasks are still ending).
    while (!Run("test -z \"$(squeue -h 2>/dev/null)\"")) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    fs::remove_all(root);
    fs::copy(pristine, root, fs::copy_options::recursive);
    state.ResumeTiming();
    const auto start = std::chrono::steady_clock::now();
    if (!Run(kVellum + " collection run --root " + root.string() + " " + flags + " > " +
             (Work() / "run.log").string() + " 2>&1")) {
      state.SkipWithError(("the run failed: see " + (Work() / "run.log").string()).c_str());
      return;
    }
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  state.counters["scans_per_hour"] = kScans * 3600.0 * state.iterations() / seconds;
  if (flags.find("--slurm") != std::string::npos) {
    const double wait = SchedulerWait(Work() / "cluster" / "slurmctld.log");
    state.counters["scheduler_wait_s"] = wait;
    if (wait >= 0) g_waits.push_back(wait);
  }
}

}  // namespace
}  // namespace vellum

int main(int argc, char** argv) {
  using namespace vellum;
  const char* in_netns = std::getenv("VELLUM_IN_NETNS");
  if (in_netns == nullptr || std::string(in_netns) != "1") {
    std::string script = kSource + "/scripts/netns-run.sh";
    std::vector<char*> args = {script.data()};
    for (int k = 0; k < argc; ++k) args.push_back(argv[k]);
    args.push_back(nullptr);
    execv(script.c_str(), args.data());
    std::perror("collection_bench: scripts/netns-run.sh");
    return 1;
  }
  const fs::path work = Work();
  fs::create_directories(work);
  std::printf("collection_bench: making the collection (%d scans) and starting the cluster\n",
              kScans);
  const std::string conf = (work / "cluster" / "slurm.conf").string();
  if (!MakePristine(work / "pristine") || !Run(kSource + "/tests/slurm/cluster.sh start " +
                                               (work / "cluster").string() + " > /dev/null")) {
    std::fprintf(stderr, "collection_bench: cannot make the collection or start the cluster\n");
    return 1;
  }
  setenv("SLURM_CONF", conf.c_str(), 1);
  benchmark::RegisterBenchmark("BM_Collection/local", BM_CollectionRun, "--jobs 2")
      ->Apply(Repeated)
      ->Iterations(1)
      ->UseRealTime()
      ->Unit(benchmark::kMillisecond);
  // Two tasks of one core at once, as the local pool's two workers; five scans a task.
  benchmark::RegisterBenchmark("BM_Collection/slurm", BM_CollectionRun,
                               "--slurm --chunk 5 --cpus-per-task 1")
      ->Apply(Repeated)
      ->Iterations(1)
      ->UseRealTime()
      ->Unit(benchmark::kMillisecond);
  InitializeInterleaved(&argc, &argv);
  RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  const double local = reporter.Time("BM_Collection/local");
  const double slurm = reporter.Time("BM_Collection/slurm");
  if (local > 0 && slurm > 0) {
    std::printf(
        "local pool %.2f s (spread %.2fx, %.0f scans/h) vs Slurm %.2f s (spread %.2fx, %.0f "
        "scans/h): Slurm's overhead %.1f%% (medians; bar: 15%%)\n",
        local / 1e3, reporter.Spread("BM_Collection/local"), kScans * 3600e3 / local, slurm / 1e3,
        reporter.Spread("BM_Collection/slurm"), kScans * 3600e3 / slurm, 100 * (slurm / local - 1));
  }
  if (!g_waits.empty()) {
    std::sort(g_waits.begin(), g_waits.end());
    const double wait = g_waits[g_waits.size() / 2];
    std::printf(
        "of which slurmctld's wait from submission to the first task's start (its scheduling "
        "pass, once a second): median %.2f s (%.2f to %.2f s); the rest of the overhead %.1f%%\n",
        wait, g_waits.front(), g_waits.back(), 100 * ((slurm - wait * 1e3) / local - 1));
  }
  Run(kSource + "/tests/slurm/cluster.sh stop " + (work / "cluster").string());
  fs::remove_all(work);
  return 0;
}
