// The station on one in-process bus, for unit tests of the daemons' nodes: LCM's memq://
// provider, nodes that share it (station::Node over a shared handle), a probe that records what
// they publish, a clock the test steps (its nodes' timeouts), and a pump that handles messages
// until a condition holds.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <lcm/lcm-cpp.hpp>
#include <map>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "core/patterns/scan.h"
#include "core/sim/evaluate.h"
#include "pipeline/pipeline.h"
#include "pipeline/stages.h"
#include "station/node.h"
#include "station/scan_log.h"
#include "vellum/status_t.hpp"

namespace vellum::station::testing {

// Whether two images are the same bit for bit (NaNs too, which cv::norm cannot compare).
inline bool SameBits(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  for (int y = 0; y < a.rows; ++y) {
    if (std::memcmp(a.ptr(y), b.ptr(y), a.cols * a.elemSize()) != 0) return false;
  }
  return true;
}

class MemqBus {
 public:
  MemqBus() : lcm_("memq://"), probe_("vellum-test", &lcm_) {}

  lcm::LCM& lcm() { return lcm_; }
  // The time the test's nodes go by, when made as Node(process, &bus.lcm(), &bus.clock()): it
  // stands still unless the test moves it (StepUntil), so that a timeout fires when the test
  // says and never because a loaded machine was slow.
  SteppedClock& clock() { return clock_; }
  // The test's own node: publishes as "vellum-test".
  Node& probe() { return probe_; }

  // Called between messages, as a daemon's Run calls its node's Tick.
  void AddTick(std::function<void()> tick) { ticks_.push_back(std::move(tick)); }

  // Handles messages (the nodes' workers run meanwhile) and calls the ticks until `done` holds;
  // false after `timeout_s`.
  bool RunUntil(const std::function<bool()>& done, double timeout_s = 60) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    while (!done()) {
      if (std::chrono::steady_clock::now() > end) return false;
      lcm_.handleTimeout(5);
      for (const auto& tick : ticks_) tick();
    }
    return true;
  }

  // As RunUntil, and the clock moves `step_s` whenever no message came for 5 ms (what was sent
  // has been handled), `most_s` in all; after that `done` is awaited with the clock still (a
  // slow worker finishing what the last step set off). False if `done` does not hold within 60 s
  // of real time.
  bool StepUntil(const std::function<bool()>& done, double step_s, double most_s) {
    const Clock::time_point end = clock_.Now() + Seconds(most_s);
    const auto real_end = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (!done()) {
      if (std::chrono::steady_clock::now() > real_end) return false;
      const bool quiet = lcm_.handleTimeout(5) == 0;
      for (const auto& tick : ticks_) tick();
      if (quiet && clock_.Now() < end) clock_.Advance(step_s);
    }
    return true;
  }
  // Lets `seconds` pass on the clock, handling messages and ticking, as StepUntil does.
  void StepFor(double seconds, double step_s = 0.1) {
    const Clock::time_point end = clock_.Now() + Seconds(seconds);
    StepUntil([&] { return clock_.Now() >= end; }, step_s, seconds + step_s);
  }

  // Records every message of `channel` (decoded as Msg) from now on.
  template <class Msg>
  std::shared_ptr<std::vector<Msg>> Record(const std::string& channel) {
    auto seen = std::make_shared<std::vector<Msg>>();
    probe_.Subscribe<Msg>(channel, [seen](const Msg& m) { seen->push_back(m); });
    return seen;
  }

  // Follows the status of `process` ("vellum-decoder") from now on.
  void Watch(const std::string& process) {
    auto& last = statuses_[process];
    probe_.Subscribe<status_t>(StatusChannel(process), [&last](const status_t& m) { last = m; });
  }
  const status_t& Status(const std::string& process) { return statuses_[process]; }
  // A counter of the last status of a watched process (0 if absent).
  int64_t Counter(const std::string& process, const std::string& name) {
    const status_t& s = statuses_[process];
    for (int k = 0; k < s.ncounters; ++k) {
      if (s.counter_names[k] == name) return s.counter_values[k];
    }
    return 0;
  }
  // Waits until the watched process reports an error containing `text`.
  bool WaitForError(const std::string& process, const std::string& text, double timeout_s = 30) {
    return RunUntil([&] { return statuses_[process].last_error.find(text) != std::string::npos; },
                    timeout_s);
  }

 private:
  SteppedClock clock_;
  lcm::LCM lcm_;
  Node probe_;
  std::vector<std::function<void()>> ticks_;
  std::map<std::string, status_t> statuses_;
};

// Publishes `scan` from `probe` as scan `id`, as the station's projector and camera would:
// SCAN_STARTED with a new session, then the texture and every frame on CAPTURE (of that
// session), except pattern `skip`. Returns the session.
inline int64_t PublishScan(Node& probe, const Scan& scan, int64_t id, int skip = -2) {
  const int64_t session = NewSession();
  scan_started_t started = MakeScanStarted(scan, id, session);
  probe.Publish(channel::kScanStarted, &started);
  for (int k = -1; k < static_cast<int>(scan.frames.size()); ++k) {
    if (k == skip) continue;
    capture_t c = MakeCapture(scan, id, k, NowUtime());
    c.session = session;
    probe.Publish(channel::kCapture, &c);
  }
  return session;
}

// The temporary folders a test process made, removed when it exits (kept, to look into, when
// VELLUM_KEEP_TEST_DIRS is set).
inline void RemoveAtExit(const std::string& dir) {
  struct Folders {
    std::vector<std::string> paths;
    ~Folders() {
      if (std::getenv("VELLUM_KEEP_TEST_DIRS")) return;
      std::error_code ignored;
      for (const std::string& p : paths) std::filesystem::remove_all(p, ignored);
    }
  };
  static Folders folders;
  folders.paths.push_back(dir);
}

// A fresh folder for one test's files, named after the test: <tmp>/vellum_<what>_<pid>_<test>,
// removed when the process exits.
inline std::string TestDir(const std::string& what) {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = info ? info->name() : "x";
  std::replace(name.begin(), name.end(), '/', '_');  // A parameterised test's "Name/param".
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() /
      ("vellum_" + what + "_" + std::to_string(::getpid()) + "_" + name);
  std::filesystem::remove_all(dir);
  RemoveAtExit(dir.string());
  return dir.string();
}

// A file's bytes ("" if it cannot be read).
inline std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// A curled page scanned on the quick rig (QuickRig) by the virtual gantry (rendered once per
// process).
inline const Scan& SmallScan() {
  static const Scan scan = AsScan(SimulateScan(QuickRig(), PageShape::kCurl, 7));
  return scan;
}

// SmallScan()'s context, measured with the quick rig: what travels with its products.
inline ScanContext SmallScanContext() { return ScanContext::For(SmallScan(), QuickRig()); }

// SmallScan() through each stage with the default options (computed once per process, its
// files in a temporary folder): the inputs the daemons after the decoder take, and what their
// products must equal.
struct SmallProducts {
  std::string results;  // Where the stages wrote their files.
  DecodeResult decoded;
  PointMap map;
  Outline outline;
  Mesh mesh;
  FlattenResult flat;
  RestoreResult restored;
  std::vector<StageReport> stages;  // decode, triangulate, outline, mesh, flatten, restore.
};
inline const SmallProducts& SmallScanProducts() {
  static const SmallProducts products = [] {
    SmallProducts p;
    p.results = (std::filesystem::temp_directory_path() /
                 ("vellum_small_products_" + std::to_string(::getpid())))
                    .string();
    std::filesystem::create_directories(p.results);
    RemoveAtExit(p.results);
    // The pipeline's steps from the decode to the restore, as `vellum process` runs them.
    const Pipeline pipeline{PipelineOptions()};
    ScanWork work;
    work.scan = SmallScan();
    work.calibration = QuickRig();
    work.context = SmallScanContext();
    work.results = p.results;
    Status ran = pipeline.Run(Step::kDecode, Step::kDecode, &work);
    p.decoded = work.decoded;  // The triangulation lets it go.
    if (ran.ok()) ran = pipeline.Run(Step::kTriangulate, Step::kRestore, &work);
    if (!ran.ok()) throw std::runtime_error(ran.message());
    p.stages = work.stages;
    p.map = work.map;
    p.outline = work.outline;
    p.mesh = work.pages[0].mesh;
    p.flat = work.pages[0].flat;
    p.restored = work.pages[0].restored;
    for (const StageReport& stage : p.stages) {
      if (!stage.status.ok()) throw std::runtime_error(stage.stage + ": " + stage.status.message());
    }
    return p;
  }();
  return products;
}

// The first `n` stage reports of SmallScanProducts().
inline std::vector<StageReport> FirstStages(size_t n) {
  const auto& all = SmallScanProducts().stages;
  return std::vector<StageReport>(all.begin(), all.begin() + n);
}

}  // namespace vellum::station::testing
