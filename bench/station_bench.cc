// What the operator waits for: from the last frame captured to the restored page on the
// viewer's screen. A scan log is played into the real processing daemons (vellum-decoder,
// -triangulator, -flattener, -restorer) and vellum-viewer (drawing offscreen), started afresh
// for each repetition on a private udpm bus, at its recording's own pace, twice: the same
// captures first under another scan id (a station's first scan, its daemons just started), then
// as recorded (a scan in a session, the wait an operator has on every scan but the first; the
// benchmark's time). Each is measured on the bus, by this program's clock:
//  - capture: the first CAPTURE to the last (the scan's own time at the gantry: the baseline);
//  - the wait: the last CAPTURE to RESTORED, and to the viewer's status naming the scan as drawn;
//  - each stage's part of the wait, from SCAN_PROGRESS (when each daemon handed the scan on).
// The benchmark's time is the wait to RESTORED; the table after it gives medians and spreads,
// the wait as a fraction of the capture time in the same run, and each stage's share.
//
// Cases: the recorded demo leaf (tests/data/demo_leaf.lcmlog, 1440 x 1080, as it was recorded),
// and the virtual gantry's curled leaf on the default rig (1600 x 1200) and on the 24 MP rig
// (config/hires_rig.yaml), written as logs at the demo recording's pace or the camera link's
// (SimulatedLog). The program runs
// itself inside scripts/netns-run.sh: the bus never leaves a private loopback.
//
//   ./build/bench/station_bench [--paces=MB/S,...] [--builds=DIR,...] [--repeats=N] [--keep]
//                               [--benchmark_filter=...]
//
// --keep leaves the work folder (each case's last station: its scan folders, the daemons' logs)
// for a look at what the station wrote, and names it. --builds runs each case with the daemons
// of each build folder named (another commit's: a change measured beside what it changed, in the
// same run); --repeats=N repeats each case N times rather than five.
#include <benchmark/benchmark.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <lcm/lcm-cpp.hpp>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "bench/ratio_reporter.h"
#include "core/sim/evaluate.h"
#include "io/calibration_io.h"
#include "station/chain.h"
#include "station/messages.h"
#include "station/node.h"
#include "station/scan_log.h"
#include "vellum/restored_t.hpp"
#include "vellum/scan_progress_t.hpp"
#include "vellum/status_t.hpp"

namespace {

namespace fs = std::filesystem;
using namespace vellum;
using Clock = std::chrono::steady_clock;

constexpr const char* kUrl = station::kDefaultUrl;
constexpr char kViewer[] = "vellum-viewer";
// The stages of the wait, in order: the processing chain's daemons, each ending when it hands
// the scan on, and the viewer, when it says the page is drawn.
const std::vector<std::string> kStages = [] {
  std::vector<std::string> stages;
  for (const station::ChainLink& link : station::kChain) stages.push_back(link.process);
  stages.push_back(kViewer);
  return stages;
}();

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

const fs::path& WorkDir() {
  static const fs::path dir = [] {
    const fs::path d =
        fs::temp_directory_path() / ("vellum_station_bench_" + std::to_string(getpid()));
    fs::create_directories(d);
    return d;
  }();
  return dir;
}

// The CAPTUREs of a log: how many, and the median time between them.
struct Pace {
  int captures = 0;
  int64_t interval_us = 0;
};

Pace LogPace(const std::string& path) {
  lcm::LogFile log(path, "r");
  Pace pace;
  if (!log.good()) return pace;
  std::vector<int64_t> times;
  for (const lcm::LogEvent* e = log.readNextEvent(); e; e = log.readNextEvent()) {
    if (e->channel == station::channel::kCapture) times.push_back(e->timestamp);
  }
  pace.captures = static_cast<int>(times.size());
  std::vector<int64_t> gaps;
  for (size_t k = 1; k < times.size(); ++k) gaps.push_back(times[k] - times[k - 1]);
  if (!gaps.empty()) {
    std::nth_element(gaps.begin(), gaps.begin() + gaps.size() / 2, gaps.end());
    pace.interval_us = gaps[gaps.size() / 2];
  }
  return pace;
}

// A camera link's bytes per second: GigE Vision's gigabit, less its framing (a 24 MP 8-bit
// frame takes 0.2 s; USB3 cameras are faster, but few 24 MP ones).
constexpr double kLinkBytesPerSecond = 119e6;

// A log of the virtual gantry's curled leaf on `rig` (made once), at the demo recording's pace,
// or as fast as the camera's link carries its frames if that is slower.
std::string SimulatedLog(const std::string& name, const Calibration& rig) {
  const std::string path = (WorkDir() / (name + ".lcmlog")).string();
  if (fs::exists(path)) return path;
  const double frame_bytes = static_cast<double>(rig.camera.size.area());
  const int64_t interval =
      std::max<int64_t>(LogPace(VELLUM_DEMO_LOG).interval_us,
                        static_cast<int64_t>(1e6 * frame_bytes / kLinkBytesPerSecond));
  calibration_t calibration{};
  station::ToMessage(rig, &calibration);
  const Status s = station::WriteScanLog(path, AsScan(SimulateScan(rig, PageShape::kCurl, 5)),
                                         1000 + name.size(), "vellum", &calibration, interval);
  if (!s.ok()) {
    std::fprintf(stderr, "station_bench: %s\n", s.message().c_str());
    std::exit(1);
  }
  return path;
}

// A daemon of the build, its output in `log`; SIGTERM and a wait when it goes. Everything the
// child needs is made before fork (this process has threads: the child may only open, dup2 and
// exec).
class Daemon {
 public:
  // `build`: the build folder whose daemons run (empty: this program's).
  Daemon(const std::string& name, const std::vector<std::string>& flags, const std::string& log,
         const std::string& build) {
    const std::string path =
        (build.empty() ? std::string(VELLUM_BUILD_DIR) : build) + "/daemons/" + name;
    std::vector<std::string> args = {path, "--url", kUrl};
    args.insert(args.end(), flags.begin(), flags.end());
    std::vector<std::string> env = {"SDL_VIDEODRIVER=offscreen"};
    for (char** e = environ; *e != nullptr; ++e) {
      if (std::string(*e).rfind("SDL_VIDEODRIVER=", 0) != 0) env.push_back(*e);
    }
    std::vector<char*> argv, envp;
    for (std::string& a : args) argv.push_back(a.data());
    for (std::string& e : env) envp.push_back(e.data());
    argv.push_back(nullptr);
    envp.push_back(nullptr);
    pid_ = fork();
    if (pid_ != 0) return;
    const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      dup2(fd, 1);
      dup2(fd, 2);
    }
    execve(path.c_str(), argv.data(), envp.data());
    _exit(127);
  }
  ~Daemon() {
    if (pid_ <= 0) return;
    kill(pid_, SIGTERM);
    waitpid(pid_, nullptr, 0);
  }
  Daemon(const Daemon&) = delete;
  Daemon& operator=(const Daemon&) = delete;

 private:
  pid_t pid_ = -1;
};

// What this program hears on the bus, by its clock.
class Ear {
 public:
  Ear() : lcm_(kUrl) {
    for (const std::string& p : kStages) {
      lcm_.subscribe(station::StatusChannel(p), &Ear::OnStatus, this);
    }
    lcm_.subscribe(station::channel::kScanProgress, &Ear::OnProgress, this);
    lcm_.subscribe(station::channel::kRestored, &Ear::OnRestored, this);
    thread_ = std::thread([this] {
      while (!stop_) lcm_.handleTimeout(20);
    });
  }
  ~Ear() {
    stop_ = true;
    thread_.join();
  }
  bool good() { return lcm_.good(); }
  lcm::LCM& lcm() { return lcm_; }

  // Waits until `done` holds (under the lock) or `timeout_s` passes.
  template <class F>
  bool Await(F done, double timeout_s) {
    const auto end = Clock::now() + std::chrono::duration<double>(timeout_s);
    for (;;) {
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (done()) return true;
      }
      if (Clock::now() >= end) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  }
  // From now on, hears only scan `id`'s progress, RESTORED and drawing (each scan of a session
  // is timed on its own).
  void Expect(int64_t id) {
    std::lock_guard<std::mutex> lock(mutex_);
    id_ = id;
    done_.clear();
    restored_ = Clock::time_point();
  }
  bool Heard(const std::string& process) { return heard_.count(process) > 0; }
  // When `stage` was done with the scan (zero time: not yet).
  Clock::time_point Done(const std::string& stage) { return done_[stage]; }
  Clock::time_point restored() { return restored_; }
  const std::string& error() { return error_; }  // The first a daemon reported.
  // Chunks and whole products the daemons asked again (the bus lost them), as their statuses
  // last said.
  int64_t AskedAgain() {
    int64_t n = 0;
    for (const auto& [process, asked] : asked_) n += asked;
    return n;
  }
  std::mutex& mutex() { return mutex_; }

 private:
  void OnStatus(const lcm::ReceiveBuffer*, const std::string&, const status_t* m) {
    std::lock_guard<std::mutex> lock(mutex_);
    heard_.insert(m->process);
    int64_t& asked = asked_[m->process];
    asked = std::max(asked, station::StatusCounter(*m, station::counter::kChunksAskedAgain) +
                                station::StatusCounter(*m, station::counter::kProductsAskedAgain));
    if (m->errors > 0 && error_.empty()) error_ = m->process + ": " + m->last_error;
    if (m->process == kViewer && m->scan_id == id_ && done_[kViewer] == Clock::time_point()) {
      done_[kViewer] = Clock::now();
    }
  }
  void OnProgress(const lcm::ReceiveBuffer*, const std::string&, const scan_progress_t* m) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (m->scan_id != id_) return;
    if (done_[m->process] == Clock::time_point()) done_[m->process] = Clock::now();
  }
  void OnRestored(const lcm::ReceiveBuffer*, const std::string&, const restored_t* m) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (m->scan_id != id_) return;
    if (restored_ == Clock::time_point()) restored_ = Clock::now();
  }

  lcm::LCM lcm_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::mutex mutex_;
  int64_t id_ = -1;  // The scan timed.
  std::set<std::string> heard_;
  std::map<std::string, Clock::time_point> done_;
  Clock::time_point restored_;
  std::string error_;
  std::map<std::string, int64_t> asked_;
};

// One scan's figures, seconds.
struct Sample {
  double capture = 0, restored = 0, shown = 0;
  int64_t asked_again = 0;  // Chunks or products the bus lost and the daemons asked again.
  std::map<std::string, double> stage;  // Each stage's part of the wait.
};
// By case: each repetition's scan in session (the operator's wait on every scan but a
// station's first), and its first scan (the daemons just started).
std::map<std::string, std::vector<Sample>>& Samples() {
  static std::map<std::string, std::vector<Sample>> samples;
  return samples;
}
std::map<std::string, std::vector<Sample>>& FirstSamples() {
  static std::map<std::string, std::vector<Sample>> samples;
  return samples;
}
std::map<std::string, Pace>& Paces() {  // Each case's log.
  static std::map<std::string, Pace> paces;
  return paces;
}

// A case's scans: the log timed, and the one played before it into the same daemons (the same
// captures, written again under another scan id, at the log's pace).
struct Session {
  std::string first, timed;
  int64_t first_id = 0, timed_id = 0;
};

Session MakeSession(const std::string& log) {
  Session session;
  session.timed = log;
  Scan scan;
  bool has_calibration = false;
  calibration_t calibration{};
  Status s = station::ReadScanLog(log, 0, &scan, &has_calibration, &calibration, &session.timed_id);
  session.first_id = session.timed_id - 1;
  session.first = (WorkDir() / ("first_of_" + fs::path(log).filename().string())).string();
  if (s.ok()) {
    s = station::WriteScanLog(session.first, scan, session.first_id, "vellum",
                              has_calibration ? &calibration : nullptr, LogPace(log).interval_us);
  }
  if (!s.ok()) {
    std::fprintf(stderr, "station_bench: %s\n", s.message().c_str());
    std::exit(1);
  }
  return session;
}

// How a case's station is run: its daemons' pace (`--pace`, MB/s; empty: their default) and the
// build they come from (empty: this program's).
struct Variant {
  std::string pace, build;
};

// A station's processing daemons and viewer on a fresh data folder `dir`, once each has said it
// is there.
class Station {
 public:
  Station(Ear* ear, const Variant& variant, const std::string& dir) : ear_(ear), dir_(dir) {
    const std::string& pace = variant.pace;
    fs::remove_all(dir);
    fs::create_directories(dir);
    for (const station::ChainLink& link : station::kChain) {
      const std::string p = link.process;
      std::vector<std::string> flags = {"--data", dir};
      if (!pace.empty()) flags.insert(flags.end(), {"--pace", pace});
      daemons_.push_back(std::make_unique<Daemon>(p, flags, dir + "/" + p + ".log", variant.build));
    }
    daemons_.push_back(std::make_unique<Daemon>(kViewer, std::vector<std::string>{"--data", dir},
                                                dir + "/" + kViewer + ".log", variant.build));
  }
  bool Ready(std::string* why) {
    if (ear_->Await(
            [&] {
              return std::all_of(kStages.begin(), kStages.end(),
                                 [&](const std::string& p) { return ear_->Heard(p); });
            },
            60)) {
      return true;
    }
    *why = "the daemons did not answer within 60 s (logs in " + dir_ + ")";
    return false;
  }
  // Plays scan `id`'s `log` at its own pace and times it; false (with `why`) when its page
  // does not come.
  bool Play(const std::string& log, int64_t id, Sample* out, std::string* why);

 private:
  Ear* ear_;
  std::string dir_;
  std::vector<std::unique_ptr<Daemon>> daemons_;
};

bool Station::Play(const std::string& log, int64_t id, Sample* out, std::string* why) {
  Ear& ear = *ear_;
  ear.Expect(id);
  lcm::LogFile file(log, "r");
  if (!file.good()) {
    *why = "cannot read " + log;
    return false;
  }
  Clock::time_point start, first, last;
  int64_t t0 = -1;
  for (const lcm::LogEvent* e = file.readNextEvent(); e; e = file.readNextEvent()) {
    if (t0 < 0) {
      t0 = e->timestamp;
      start = Clock::now();
    }
    std::this_thread::sleep_until(start + std::chrono::microseconds(e->timestamp - t0));
    if (!ear.Await([&] { return ear.error().empty(); }, 0)) break;  // Failed already.
    ear.lcm().publish(e->channel, e->data, static_cast<unsigned>(e->datalen));
    if (e->channel == station::channel::kCapture) {
      last = Clock::now();
      if (first == Clock::time_point()) first = last;
    }
  }
  if (!ear.Await([&] { return ear.Done(kViewer) != Clock::time_point() || !ear.error().empty(); },
                 600)) {
    *why = "no restored page drawn within 600 s (logs in " + dir_ + ")";
    return false;
  }
  std::lock_guard<std::mutex> lock(ear.mutex());
  if (!ear.error().empty()) {
    *why = ear.error();
    return false;
  }
  out->capture = Seconds(last - first);
  out->restored = Seconds(ear.restored() - last);
  out->shown = Seconds(ear.Done(kViewer) - last);
  out->asked_again = ear.AskedAgain();
  Clock::time_point before = last;
  for (const std::string& stage : kStages) {
    const Clock::time_point done = ear.Done(stage);
    out->stage[stage] = Seconds(done - before);
    before = done;
  }
  return true;
}

// A case's log, made on its first repetition (the 24 MP one takes a minute and 1.4 GB).
using LogMaker = std::function<std::string()>;

// Each repetition starts a station afresh and plays it two scans, one after the other as an
// operator would: its first, then the one timed.
void BM_Station_LastFrameToRestored(benchmark::State& state, const std::string& name,
                                    const std::string& scan, const LogMaker& make,
                                    const Variant& variant) {
  static std::map<std::string, Session> sessions;
  if (sessions.count(scan) == 0) {
    sessions[scan] = MakeSession(make());
    Paces()[scan] = LogPace(sessions[scan].timed);
  }
  const Session& session = sessions[scan];
  for (auto _ : state) {
    Sample first, timed;
    std::string why;
    Ear ear;
    bool ok = ear.good();
    if (!ok) why = "cannot open the bus";
    Station station(&ear, variant, (WorkDir() / ("station_" + name)).string());
    ok = ok && station.Ready(&why) && station.Play(session.first, session.first_id, &first, &why) &&
         station.Play(session.timed, session.timed_id, &timed, &why);
    if (!ok) {
      // Said at once: libbenchmark 1.7.1 crashes computing a case's statistics when its first
      // repetition is the one that failed (google/benchmark #1406), and the reason with it.
      std::fprintf(stderr, "station_bench: %s, repetition failed: %s\n", name.c_str(), why.c_str());
      state.SkipWithError(why.c_str());
      break;
    }
    state.SetIterationTime(timed.restored);
    state.counters["capture_s"] = timed.capture;
    state.counters["to_shown_s"] = timed.shown;
    state.counters["first_scan_s"] = first.restored;
    state.counters["asked_again"] = static_cast<double>(timed.asked_again);
    Samples()[name].push_back(timed);
    FirstSamples()[name].push_back(first);
  }
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

// The kernel's cap on a socket's receive buffer, bytes (0 if unknown).
long RmemMax() {
  long bytes = 0;
  if (FILE* f = std::fopen("/proc/sys/net/core/rmem_max", "r")) {
    if (std::fscanf(f, "%ld", &bytes) != 1) bytes = 0;
    std::fclose(f);
  }
  return bytes;
}

// One line of the summary: case `name`'s samples, labelled `label`.
void PrintRow(const std::string& name, const std::string& label,
              const std::vector<Sample>& samples) {
  if (samples.empty()) return;
  std::vector<double> capture, restored, shown;
  std::map<std::string, std::vector<double>> share;
  int64_t asked = 0;  // Over every repetition.
  for (const Sample& s : samples) {
    asked += s.asked_again;
    capture.push_back(s.capture);
    restored.push_back(s.restored);
    shown.push_back(s.shown);
    for (const auto& [stage, t] : s.stage) share[stage].push_back(t / s.shown);
  }
  auto spread = [](const std::vector<double>& v) {
    return *std::max_element(v.begin(), v.end()) / *std::min_element(v.begin(), v.end());
  };
  const Pace& pace = Paces()[name.substr(0, name.find('@'))];
  std::printf("%-19s %3d, %4.0f ms/f %8.2fs %10.3fs %6.2fx %9.0f%% %6.3fs %8.2fx %6lld  ",
              label.c_str(), pace.captures, pace.interval_us / 1e3, Median(capture),
              Median(restored), spread(restored), 100 * Median(restored) / Median(capture),
              Median(shown), spread(shown), static_cast<long long>(asked));
  for (const std::string& stage : kStages) {
    std::printf(" %s %.0f%%", stage.substr(7).c_str(), 100 * Median(share[stage]));
  }
  std::printf("\n");
}

void PrintSummary() {
  std::printf(
      "\nnet.core.rmem_max: %.1f MB (an installed station sets 16 MB, systemd/60-vellum.conf: "
      "below that, udpm loses the 24 MP rig's frames)\n",
      RmemMax() / 1048576.0);
  std::printf(
      "\nThe operator's wait (medians over the repetitions; spread = slowest / fastest; asked: "
      "chunks and products the bus lost and the daemons asked again, all repetitions):\n");
  std::printf("%-19s %14s %9s %11s %7s %10s %7s %9s %6s   %s\n", "scan", "captures", "capture",
              "->RESTORED", "spread", "of capture", "->drawn", "spread", "asked",
              "shares of the wait to drawn");
  for (const auto& [name, samples] : Samples()) {
    PrintRow(name, name, samples);
    PrintRow(name, name + ", 1st", FirstSamples()[name]);
  }
  std::printf(
      "(1st: a station's first scan, its daemons just started; the other: the scan after it, as "
      "every scan of a session but the first)\n");
}

}  // namespace

int main(int argc, char** argv) {
  // On a private loopback: the program runs itself again inside scripts/netns-run.sh.
  const char* in_netns = std::getenv("VELLUM_IN_NETNS");
  if (in_netns == nullptr || std::string(in_netns) != "1") {
    std::string script = std::string(VELLUM_SOURCE_DIR) + "/scripts/netns-run.sh";
    std::vector<char*> args = {script.data()};
    for (int k = 0; k < argc; ++k) args.push_back(argv[k]);
    args.push_back(nullptr);
    execv(script.c_str(), args.data());
    std::perror("station_bench: scripts/netns-run.sh");
    return 1;
  }
  Calibration hires;
  if (!ReadCalibration(std::string(VELLUM_SOURCE_DIR) + "/config/hires_rig.yaml", &hires).ok()) {
    std::fprintf(stderr, "station_bench: cannot read config/hires_rig.yaml\n");
    return 1;
  }
  const std::vector<std::pair<std::string, LogMaker>> cases = {
      {"demo", [] { return std::string(VELLUM_DEMO_LOG); }},
      {"1600x1200", [] { return SimulatedLog("1600x1200", DefaultRig()); }},
      {"24MP", [hires] { return SimulatedLog("24MP", hires); }},
  };
  // --paces=MB/S,MB/S,...: each case at each of these daemon paces (`--pace`), side by side in
  // the same run; without it, at the daemons' default. --builds=DIR,DIR,...: each case with the
  // daemons of each of these build folders (another commit's, for a change measured beside
  // what it changed); without it, this program's.
  std::vector<std::string> paces = {""}, builds = {""};
  int repeats = vellum::kBenchRepetitions;  // --repeats=N: more, for a small change.
  std::vector<char*> args;
  bool keep = false;
  for (int k = 0; k < argc; ++k) {
    const std::string a = argv[k];
    std::vector<std::string>* list = a.rfind("--paces=", 0) == 0    ? &paces
                                     : a.rfind("--builds=", 0) == 0 ? &builds
                                                                    : nullptr;
    if (a == "--keep") {
      keep = true;
    } else if (a.rfind("--repeats=", 0) == 0) {
      repeats = std::max(1, std::atoi(a.c_str() + 10));
    } else if (list == nullptr) {
      args.push_back(argv[k]);
    } else {
      list->clear();
      std::stringstream items(a.substr(a.find('=') + 1));
      for (std::string item; std::getline(items, item, ',');) list->push_back(item);
    }
  }
  argc = static_cast<int>(args.size());
  args.push_back(nullptr);
  argv = args.data();
  for (const auto& [scan, make] : cases) {
    for (const std::string& pace : paces) {
      for (const std::string& build : builds) {
        std::string name = pace.empty() ? scan : scan + "@" + pace;
        std::string folder = build;
        while (folder.size() > 1 && folder.back() == '/') folder.pop_back();
        if (!folder.empty()) name += "@" + fs::path(folder).filename().string();
        benchmark::RegisterBenchmark(("BM_Station_LastFrameToRestored/" + name).c_str(),
                                     BM_Station_LastFrameToRestored, name, scan, make,
                                     Variant{pace, build})
            ->Apply(vellum::Repeated)
            ->Repetitions(repeats)
            ->Iterations(1)
            ->UseManualTime()
            ->Unit(benchmark::kMillisecond);
      }
    }
  }
  vellum::InitializeInterleaved(&argc, &argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  PrintSummary();
  if (keep) {
    std::printf("kept: %s\n", WorkDir().c_str());
  } else {
    fs::remove_all(WorkDir());
  }
  return 0;
}
