// The station as operators run it: real daemon processes on a real LCM udpm bus (inside this
// test's private network namespace), the virtual gantry as camera and SDL2's offscreen/dummy
// video driver for the projector. Checks the scan handshake, recording, playback of a recorded
// log, and that a scan through the daemons gives exactly what `vellum process` gives.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <tuple>

#include "core/sim/gantry.h"
#include "io/calibration_io.h"
#include "io/scan_io.h"
#include "io/xmp.h"
#include "station/node.h"
#include "station/scan_log.h"
#include "station/scan_store.h"
#include "tests/report_keys.h"
#include "tests/station_harness.h"
#include "tests/xwd.h"
#include "vellum/calibration_t.hpp"
#include "vellum/capture_t.hpp"
#include "vellum/correspondence_t.hpp"
#include "vellum/pattern_shown_t.hpp"
#include "vellum/restored_t.hpp"
#include "vellum/scan_progress_t.hpp"
#include "vellum/scan_request_t.hpp"
#include "vellum/scan_started_t.hpp"
#include "vellum/status_t.hpp"

namespace vellum {
namespace {

using testing::HandleUntil;
using testing::Listener;
using testing::Process;
using testing::ReadText;
namespace fs = std::filesystem;

const std::string kBuild = VELLUM_BUILD_DIR;
const std::string kSource = VELLUM_SOURCE_DIR;
const std::string kRig = kSource + "/config/small_rig.yaml";
const std::string kLog = kBuild + "/tests/data/curl_scan.lcmlog";
const std::string kDemoLog = kBuild + "/tests/data/demo_leaf.lcmlog";  // What the demo plays.

std::string Daemon(const std::string& name) { return kBuild + "/daemons/" + name; }

std::string Tool() { return kBuild + "/cli/vellum"; }

// How long the projector waits for each CAPTURE from the sim camera: the camera renders every
// frame, which takes seconds under the sanitizers on a loaded machine (the default is 5 s).
constexpr char kSimCaptureTimeout[] = "30";

const std::vector<std::string> kProcessingStatus = {"STATUS_DECODER", "STATUS_TRIANGULATOR",
                                                    "STATUS_FLATTENER", "STATUS_RESTORER"};

class StationTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = (fs::temp_directory_path() /
            ("vellum_station_" + std::string(info->name()) + "_" + std::to_string(getpid())))
               .string();
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    // Each test its own port (and each its own network namespace, so its own loopback).
    const std::string name = info->name();
    url_ = testing::TestUrl(7900 + static_cast<int>(std::hash<std::string>()(name) % 1000));
    lcm_ = std::make_unique<lcm::LCM>(url_);
    ASSERT_TRUE(lcm_->good()) << "LCM cannot open " << url_ << " (run inside scripts/netns-run.sh)";
  }
  void TearDown() override {
    for (auto& p : processes_) {
      if (p->killed()) continue;
      const int code = StopCleanly(p.get());
      EXPECT_EQ(code, 0) << p->name() << " did not stop cleanly on SIGTERM:\n" << p->Output();
    }
    processes_.clear();
    std::error_code ec;
    if (!HasFailure()) fs::remove_all(dir_, ec);
  }

  // Stops `p` (SIGTERM) and returns its exit status, but 0 when the sanitizer build's leak
  // check could not run at exit (LeakSanitizer's own tracer crashing as it stops the process's
  // threads: "LeakSanitizer has encountered a fatal error", with no leak and no ASan report).
  // That is the tool failing, not the daemon; it is said, and a real leak still fails.
  static int StopCleanly(Process* p) {
    const int code = p->Stop();
    if (code == 0) return 0;
    const std::string out = p->Output();
    if (out.find("LeakSanitizer has encountered a fatal error") != std::string::npos &&
        out.find("detected memory leaks") == std::string::npos &&
        out.find("ERROR: AddressSanitizer") == std::string::npos &&
        out.find("runtime error") == std::string::npos) {
      std::printf(
          "[lsan] %s: the leak check could not run at exit (its tracer failed); not "
          "counted\n",
          p->name().c_str());
      return 0;
    }
    return code;
  }

  Process* Start(const std::string& binary, std::vector<std::string> args,
                 const std::vector<std::string>& env = {}) {
    args.insert(args.begin(), binary);
    args.push_back("--url");
    args.push_back(url_);
    // The sanitizer build's receivers drain their sockets several times slower: it paces the
    // processing daemons' chunked products to match (scripts/sanitize.sh).
    const char* pace = std::getenv("VELLUM_TEST_PACE");
    if (pace && binary.find("vellum-") != std::string::npos &&
        binary.find("camera") == std::string::npos &&
        binary.find("projector") == std::string::npos &&
        binary.find("lights") == std::string::npos && binary.find("viewer") == std::string::npos) {
      args.push_back("--pace");
      args.push_back(pace);
    }
    const std::string log = dir_ + "/" + fs::path(binary).filename().string() + "_" +
                            std::to_string(processes_.size()) + ".log";
    processes_.push_back(std::make_unique<Process>(args, log, env));
    return processes_.back().get();
  }
  // The four processing daemons; the restorer also given `restorer_flags`.
  void StartProcessing(const std::vector<std::string>& restorer_flags = {}) {
    for (const char* name :
         {"vellum-decoder", "vellum-triangulator", "vellum-flattener", "vellum-restorer"}) {
      std::vector<std::string> flags = {"--data", dir_ + "/scans"};
      if (std::string(name) == "vellum-restorer") {
        flags.insert(flags.end(), restorer_flags.begin(), restorer_flags.end());
      }
      Start(Daemon(name), flags);
    }
  }
  // Runs a tool to completion; returns its exit code and output.
  int RunTool(std::vector<std::string> args, std::string* output, double timeout_s = 300) {
    args.insert(args.begin(), Tool());
    Process p(args, dir_ + "/tool.log");
    const int code = p.Wait(timeout_s);
    *output = p.Output();
    return code;
  }
  // Every daemon has published a heartbeat (it is subscribed and running).
  void WaitForHeartbeats(const std::vector<std::string>& channels) {
    std::set<std::string> seen;
    std::vector<std::unique_ptr<Listener<status_t>>> listeners;
    for (const std::string& c : channels) {
      listeners.push_back(std::make_unique<Listener<status_t>>(
          *lcm_, c, [&seen, c](const status_t&) { seen.insert(c); }));
    }
    ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] { return seen.size() == channels.size(); }))
        << "only " << seen.size() << " of " << channels.size() << " daemons sent a heartbeat";
  }
  // The same scan through `vellum process` (into dir_/<out>): the products must be identical.
  // `flags`: more of vellum process's flags, as the daemons were given them.
  void ExpectSameAsProcess(const std::string& scan_dir, const std::string& results,
                           const std::string& out_name = "process",
                           const std::vector<std::string>& flags = {}) {
    std::string out;
    const std::string processed = dir_ + "/" + out_name;
    std::vector<std::string> args = {
        "process", "--scan", scan_dir, "--calibration", scan_dir + "/calibration.yaml",
        "--out",   processed};
    args.insert(args.end(), flags.begin(), flags.end());
    ASSERT_EQ(RunTool(args, &out), 0) << out;
    for (const char* file : {"restored.tif", "restored_mask.png", "flat.ply", "mesh.ply",
                             "points.ply", "restored.json", "depth.png"}) {
      EXPECT_EQ(ReadText(results + "/" + file), ReadText(processed + "/" + file))
          << file << " differs between the daemons and vellum process";
    }
    // The restorer's report has every picture, the depth map from the bus's POINT_CLOUD too.
    for (const char* picture : {"texture.png", "outline.png", "valid.png", "depth.png", "grid.png",
                                "strain.png", "before_after.png"}) {
      EXPECT_TRUE(fs::exists(results + "/report/" + picture)) << picture;
    }
    EXPECT_TRUE(fs::exists(results + "/report.html"));
    // report.json: the same keys, and the same options and figures (not the times or paths).
    const nlohmann::json station = nlohmann::json::parse(ReadText(results + "/report.json"));
    const nlohmann::json process = nlohmann::json::parse(ReadText(processed + "/report.json"));
    // A section absent from both (identity, for a scan without one) compares equal.
    auto section_of = [](const nlohmann::json& j, const char* key) {
      return j.contains(key) ? j[key] : nlohmann::json();
    };
    const std::set<std::string> station_keys = ComparableReportKeys(station);
    EXPECT_EQ(station_keys, ComparableReportKeys(process));
    for (const char* section :
         {"identity", "options", "sizes", "pixels", "sheet", "flattening", "outputs"}) {
      EXPECT_EQ(section_of(station, section), section_of(process, section)) << section;
    }
    EXPECT_GE(station_keys.count("options/max_epipolar_error_px"), 1u);
    const cv::Mat a = cv::imread(results + "/restored.tif", cv::IMREAD_UNCHANGED);
    const cv::Mat b = cv::imread(processed + "/restored.tif", cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(a.empty());
    ASSERT_EQ(a.size(), b.size());
    EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0.0);
  }

  void RunFullScan(const std::string& rig, int patterns);

  // An X server (Xvfb, 1280x720) for the viewer, its screen readable as an xwd file at
  // *screen; returns the display.
  std::string StartXvfb(std::string* screen) {
    const std::string display = ":" + std::to_string(200 + std::hash<std::string>()(dir_) % 300);
    fs::create_directories(dir_ + "/fb");
    xvfb_ = std::make_unique<Process>(
        std::vector<std::string>{"/usr/bin/Xvfb", display, "-screen", "0", "1280x720x24", "-fbdir",
                                 dir_ + "/fb", "-nolisten", "tcp"},
        dir_ + "/xvfb.log");
    *screen = dir_ + "/fb/Xvfb_screen0";
    for (int k = 0; k < 100 && !fs::exists(*screen); ++k) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    EXPECT_TRUE(fs::exists(*screen)) << xvfb_->Output();
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    return display;
  }
  // The whole station with the viewer on an X server (StartXvfb): the viewer, the sim camera
  // on `rig` (with `camera_flags` more), the projector (its capture timeout `capture_timeout`),
  // the decoder (with `decoder_flags` more) and the three other processing daemons; waits for
  // every heartbeat.
  struct ViewedStation {
    std::string display, screen;
    Process* viewer = nullptr;
    Process* camera = nullptr;
  };
  ViewedStation StartViewedStation(const std::string& rig,
                                   const std::vector<std::string>& camera_flags = {},
                                   const std::string& capture_timeout = kSimCaptureTimeout,
                                   const std::vector<std::string>& decoder_flags = {}) {
    ViewedStation v;
    v.display = StartXvfb(&v.screen);
    v.viewer = Start(Daemon("vellum-viewer"), {"--data", dir_ + "/scans"},
                     {"DISPLAY=" + v.display, "SDL_VIDEODRIVER=x11"});
    std::vector<std::string> camera = {"--backend", "sim", "--rig", rig, "--page", "curl"};
    camera.insert(camera.end(), camera_flags.begin(), camera_flags.end());
    v.camera = Start(Daemon("vellum-camera"), camera);
    Start(Daemon("vellum-projector"),
          {"--calibration", rig, "--fullscreen", "false", "--capture-timeout", capture_timeout},
          {"SDL_VIDEODRIVER=offscreen"});
    std::vector<std::string> decoder = {"--data", dir_ + "/scans"};
    decoder.insert(decoder.end(), decoder_flags.begin(), decoder_flags.end());
    Start(Daemon("vellum-decoder"), decoder);
    for (const char* name : {"vellum-triangulator", "vellum-flattener", "vellum-restorer"}) {
      Start(Daemon(name), {"--data", dir_ + "/scans"});
    }
    std::vector<std::string> all = kProcessingStatus;
    all.push_back("STATUS_VIEWER");
    all.push_back("STATUS_CAMERA");
    all.push_back("STATUS_PROJECTOR");
    WaitForHeartbeats(all);
    return v;
  }
  // Runs xdotool on `display` (keys and text as an operator types them); true when it worked.
  bool Xdotool(const std::string& display, std::vector<std::string> args) {
    args.insert(args.begin(), "/usr/bin/xdotool");
    Process p(args, dir_ + "/xdotool.log", {"DISPLAY=" + display});
    const int code = p.Wait(30);
    EXPECT_EQ(code, 0) << p.Output();
    return code == 0;
  }

  std::string dir_, url_;
  std::unique_ptr<lcm::LCM> lcm_;
  std::vector<std::unique_ptr<Process>> processes_;
  std::unique_ptr<Process> xvfb_;  // Stopped after the daemons (TearDown), as the fixture goes.
};

// The last status of each of some daemons, from their heartbeats, and their counters.
class StatusBoard {
 public:
  StatusBoard(lcm::LCM& lcm, const std::vector<std::string>& channels) {
    for (const std::string& c : channels) {
      listeners_.push_back(
          std::make_unique<Listener<status_t>>(lcm, c, [this, c](const status_t& m) {
            if (!m.last_error.empty() &&
                (errors_[c].empty() || errors_[c].back() != m.last_error)) {
              errors_[c].push_back(m.last_error);
            }
            last_[c] = m;
          }));
    }
  }
  // The error (of every one reported on `channel` so far) that holds `text`; "" if none.
  std::string Error(const std::string& channel, const std::string& text) {
    for (const std::string& e : errors_[channel]) {
      if (e.find(text) != std::string::npos) return e;
    }
    return "";
  }
  std::string LastError(const std::string& channel) { return last_[channel].last_error; }
  // A counter of the last status on `channel` (0 if absent).
  int64_t Counter(const std::string& channel, const std::string& name) {
    const status_t& st = last_[channel];
    for (int k = 0; k < st.ncounters; ++k) {
      if (st.counter_names[k] == name) return st.counter_values[k];
    }
    return 0;
  }

 private:
  std::map<std::string, status_t> last_;
  std::map<std::string, std::vector<std::string>> errors_;
  std::vector<std::unique_ptr<Listener<status_t>>> listeners_;
};

// A scan through all six daemons with the sim camera on `rig`; checks the raw captures, the
// handshake's timing, what lcm-spy decodes, and the products against `vellum process`.
void StationTest::RunFullScan(const std::string& rig, int patterns) {
  Start(Daemon("vellum-camera"), {"--backend", "sim", "--rig", rig, "--page", "curl"});
  Start(Daemon("vellum-projector"),
        {"--calibration", rig, "--fullscreen", "false", "--flip", "horizontal", "--capture-timeout",
         kSimCaptureTimeout},
        {"SDL_VIDEODRIVER=offscreen"});
  StartProcessing();
  std::vector<std::string> all = kProcessingStatus;
  all.push_back("STATUS_CAMERA");
  all.push_back("STATUS_PROJECTOR");
  WaitForHeartbeats(all);
  // The whole bus recorded, to check below that every message decodes as lcm-spy decodes it.
  Process logger({"/usr/bin/lcm-logger", "--lcm-url=" + url_, "-f", dir_ + "/bus.lcmlog"},
                 dir_ + "/logger.log");

  std::string out;
  ASSERT_EQ(
      RunTool({"scan", "--url", url_, "--label", "test leaf", "--shelfmark", "MS 12", "--folio",
               "3", "--side", "recto", "--operator", "A. Scribe", "--timeout", "300"},
              &out),
      0)
      << out;
  // "scan N restored: WxH at D dpi -> DIR/scans/scan-N/results"
  const size_t arrow = out.find("-> ");
  ASSERT_NE(arrow, std::string::npos) << out;
  std::string results = out.substr(arrow + 3);
  results = results.substr(0, results.find('\n'));
  ASSERT_TRUE(fs::exists(results + "/restored.tif")) << out;
  const std::string raw = fs::path(results).parent_path().string() + "/raw";
  // The scan's folder is named after the folio: scan-<id>-MS-12_3_recto.
  EXPECT_NE(results.find("-MS-12_3_recto/results"), std::string::npos) << results;
  // And its report is headed with the folio, not a scan number.
  EXPECT_NE(ReadText(results + "/report.html").find("<h1>vellum: MS 12, 3 recto ("),
            std::string::npos);

  // Nothing lost: the texture, every frame, the scan's log and its calibration are on disk.
  EXPECT_TRUE(fs::exists(raw + "/texture.png"));
  for (int k = 0; k < patterns; ++k) EXPECT_TRUE(fs::exists(raw + "/" + FrameName(k))) << k;
  EXPECT_TRUE(fs::exists(raw + "/scan.yaml"));
  EXPECT_TRUE(fs::exists(raw + "/calibration.yaml"));
  lcm::LogFile log(raw + "/captures.lcmlog", "r");
  ASSERT_TRUE(log.good());
  int captures = 0, calibrations = 0;
  for (const lcm::LogEvent* e = log.readNextEvent(); e; e = log.readNextEvent()) {
    captures += e->channel == "CAPTURE";
    calibrations += e->channel == "CALIBRATION";
    if (e->channel != "CAPTURE") continue;
    // The handshake: each frame's exposure starts after its pattern was shown, and the
    // captures come in pattern order, texture first.
    capture_t c;
    ASSERT_TRUE(station::SafeDecode(e->data, e->datalen, &c));
    EXPECT_GT(c.image.utime, c.shown_utime) << "pattern " << c.pattern_index;
    EXPECT_EQ(c.pattern_index, captures - 2);
    EXPECT_EQ(c.image.pattern_index, c.pattern_index);
  }
  EXPECT_EQ(captures, patterns + 1);
  EXPECT_EQ(calibrations, 1);
  // The catalogue identity given to `vellum scan` is in the scan's scan.yaml and its report.
  Scan recorded;
  ASSERT_TRUE(ReadScan(raw, &recorded).ok());
  EXPECT_EQ(recorded.identity.shelfmark, "MS 12");
  EXPECT_EQ(recorded.identity.side, "recto");
  const nlohmann::json report = nlohmann::json::parse(ReadText(results + "/report.json"));
  EXPECT_EQ(report["identity"]["shelfmark"], "MS 12") << report.dump();
  EXPECT_EQ(report["identity"]["folio"], "3");
  EXPECT_EQ(report["identity"]["operator"], "A. Scribe");
  EXPECT_EQ(report["identity"]["label"], "test leaf");

  ExpectSameAsProcess(raw, results);

#ifdef VELLUM_SPY_CLASSPATH
  EXPECT_EQ(logger.Stop(), 0);
  Process spy(
      {"/usr/bin/java", "-cp", VELLUM_SPY_CLASSPATH, "SpyDecodeCheck", dir_ + "/bus.lcmlog"},
      dir_ + "/spy.log");
  EXPECT_EQ(spy.Wait(120), 0) << spy.Output();
  const std::string decoded = spy.Output();
  for (const char* line :
       {"CALIBRATION vellum.calibration_t", "CAPTURE vellum.capture_t",
        "CORRESPONDENCE vellum.correspondence_t", "FLAT_MESH vellum.mesh_t",
        "PATTERN_SHOWN vellum.pattern_shown_t", "POINT_CLOUD vellum.point_cloud_t",
        "RESTORED vellum.restored_t", "SCAN_REQUEST vellum.scan_request_t",
        "SCAN_STARTED vellum.scan_started_t", "STATUS_CAMERA vellum.status_t",
        "STATUS_RESTORER vellum.status_t"}) {
    EXPECT_NE(decoded.find(line), std::string::npos) << line << " not decoded:\n" << decoded;
  }
#endif
}

TEST_F(StationTest, FullScanThroughAllSixDaemonsEqualsVellumProcess) { RunFullScan(kRig, 54); }

// The virtual gantry's faults (issue: the real gantry): its display shows each image two
// refreshes after vsync (33.3 ms at 60 Hz), its camera exposes 10 ms of each 33.3 ms frame,
// starting as early as it may (so a first frame straddles the change), and loses every
// twentieth frame.
const std::vector<std::string> kLaggingGantry = {
    "--sim-display-lag", "2",  "--sim-frame-ms",   "33.333",
    "--sim-exposure-ms", "10", "--sim-drop-every", "20"};

// With the lag waited for (--display-lag-ms 34: two refreshes and the rounding up), a scan on
// the faulty gantry is the fault-free one: every frame byte for byte, the restored page pixel
// for pixel (its master's metadata holds the scan's own times), no frame found mixed.
TEST_F(StationTest, WithTheDisplayLagWaitedForAFaultyGantryScansAsAFaultFreeOne) {
  Process* camera =
      Start(Daemon("vellum-camera"), {"--backend", "sim", "--rig", kRig, "--page", "curl"});
  Start(Daemon("vellum-projector"),
        {"--calibration", kRig, "--fullscreen", "false", "--display-lag-ms", "34",
         "--capture-timeout", kSimCaptureTimeout},
        {"SDL_VIDEODRIVER=offscreen"});
  StartProcessing();
  std::vector<std::string> all = kProcessingStatus;
  all.push_back("STATUS_CAMERA");
  all.push_back("STATUS_PROJECTOR");
  WaitForHeartbeats(all);
  auto scan = [&](const std::string& folio) {
    std::string out;
    EXPECT_EQ(RunTool({"scan", "--url", url_, "--folio", folio, "--timeout", "300"}, &out), 0)
        << out;
    const size_t arrow = out.find("-> ");
    EXPECT_NE(arrow, std::string::npos) << out;
    if (arrow == std::string::npos) return std::string();
    const std::string results = out.substr(arrow + 3);
    return fs::path(results.substr(0, results.find('\n'))).parent_path().string();
  };
  const std::string fault_free = scan("1");
  ASSERT_FALSE(fault_free.empty());
  camera->Kill();
  camera->Wait(30);
  Start(Daemon("vellum-camera"), [] {
    std::vector<std::string> flags = {"--backend", "sim", "--rig", kRig, "--page", "curl"};
    flags.insert(flags.end(), kLaggingGantry.begin(), kLaggingGantry.end());
    return flags;
  }());
  status_t camera_status{};
  Listener<status_t> on_status(*lcm_, "STATUS_CAMERA",
                               [&](const status_t& m) { camera_status = m; });
  WaitForHeartbeats({"STATUS_CAMERA"});
  const std::string faulty = scan("2");
  ASSERT_FALSE(faulty.empty());
  Scan a, b;
  ASSERT_TRUE(ReadScan(fault_free + "/raw", &a).ok());
  ASSERT_TRUE(ReadScan(faulty + "/raw", &b).ok());
  ASSERT_EQ(a.frames.size(), b.frames.size());
  for (size_t k = 0; k < a.frames.size(); ++k) {
    EXPECT_EQ(cv::norm(a.frames[k], b.frames[k], cv::NORM_INF), 0) << "frame " << k;
  }
  EXPECT_EQ(cv::norm(a.texture, b.texture, cv::NORM_INF), 0);
  const cv::Mat page_a = cv::imread(fault_free + "/results/restored.tif", cv::IMREAD_UNCHANGED);
  const cv::Mat page_b = cv::imread(faulty + "/results/restored.tif", cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(page_a.empty());
  ASSERT_EQ(page_a.size(), page_b.size());
  EXPECT_EQ(cv::norm(page_a, page_b, cv::NORM_INF), 0);
  ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] {
    return station::StatusCounter(camera_status, "frames the camera dropped") > 0;
  }));
  EXPECT_EQ(station::StatusCounter(camera_status, "frames mixing two patterns"), 0);
}

// The display's lag measured as the virtual gantry has it, 3 refreshes and then 1 at 60 Hz
// (50 and 16.7 ms; frames of 10 ms every 33.3): by the projector at start-up, which then waits
// it (a scan on the lagging gantry finds no mixed frame and restores, where the settle's 30 ms
// alone would not do), and by `vellum calibrate latency`, whose measurement the projector then
// waits.
TEST_F(StationTest, TheDisplayLagIsMeasuredAsTheGantryHasItAndTheHandshakeWaitsIt) {
  auto start_camera = [&](int refreshes) {
    std::vector<std::string> flags = {"--backend",
                                      "sim",
                                      "--rig",
                                      kRig,
                                      "--page",
                                      "curl",
                                      "--sim-display-lag",
                                      std::to_string(refreshes),
                                      "--sim-frame-ms",
                                      "33.333",
                                      "--sim-exposure-ms",
                                      "10"};
    return Start(Daemon("vellum-camera"), flags);
  };
  Process* camera = start_camera(3);
  Process* projector =
      Start(Daemon("vellum-projector"),
            {"--calibration", kRig, "--fullscreen", "false", "--measure-lag", "true",
             "--refresh-hz", "60", "--capture-timeout", kSimCaptureTimeout},
            {"SDL_VIDEODRIVER=offscreen"});
  StartProcessing();
  std::vector<std::string> all = kProcessingStatus;
  all.push_back("STATUS_CAMERA");
  all.push_back("STATUS_PROJECTOR");
  WaitForHeartbeats(all);
  ASSERT_TRUE(HandleUntil(*lcm_, 60, [&] {
    return projector->Output().find("display lag") != std::string::npos;
  })) << projector->Output();
  const std::string log = projector->Output();
  const size_t line = log.find("display lag");
  std::printf("[latency] at start-up: %s\n", log.substr(line, log.find('\n', line) - line).c_str());
  std::fflush(stdout);  // Before the next process forks with it buffered.
  EXPECT_NE(log.find("display lag 50.0 ms (3.00 refreshes at 60 Hz): median of"), std::string::npos)
      << log;
  std::string out;
  ASSERT_EQ(RunTool({"scan", "--url", url_, "--timeout", "300"}, &out), 0) << out;
  EXPECT_NE(out.find("-> "), std::string::npos) << out;
  EXPECT_EQ(camera->Output().find("mixes two patterns"), std::string::npos) << camera->Output();

  camera->Kill();
  camera->Wait(30);
  camera = start_camera(1);
  WaitForHeartbeats({"STATUS_CAMERA"});
  ASSERT_EQ(RunTool({"calibrate", "latency", "--url", url_}, &out), 0) << out;
  std::printf("[latency] %s", out.c_str());
  std::fflush(stdout);
  EXPECT_NE(out.find("display lag 16.7 ms (1.00 refreshes at 60 Hz): median of"), std::string::npos)
      << out;
  EXPECT_NE(out.find("display-lag-ms: 17.7"), std::string::npos) << out;
  ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] {
    return projector->Output().find("display lag 16.7 ms") != std::string::npos;
  })) << projector->Output();
}

// Without it (and no settle time: the projector sends PATTERN_SHOWN at vsync, 33.3 ms before
// the display changes; a loaded machine oversleeping a 30 ms settle by a few ms made some
// frames clean and the test flaky), the first frame of each pattern shows the pattern before or
// straddles the change: the camera names each such frame and takes white and black again, and
// when the first Gray-code pair shows its pattern was sent mixed, the scan fails saying so.
// Nothing is restored from it.
TEST_F(StationTest, WithoutTheDisplayLagMixedFramesAreNamedAndTheScanFailsRestoringNothing) {
  std::vector<std::string> camera = {"--backend", "sim", "--rig", kRig, "--page", "curl"};
  camera.insert(camera.end(), kLaggingGantry.begin(), kLaggingGantry.end());
  Process* camera_process = Start(Daemon("vellum-camera"), camera);
  Start(Daemon("vellum-projector"),
        {"--calibration", kRig, "--fullscreen", "false", "--settle-ms", "0", "--capture-timeout",
         "5"},
        {"SDL_VIDEODRIVER=offscreen"});
  StartProcessing();
  std::vector<std::string> all = kProcessingStatus;
  all.push_back("STATUS_CAMERA");
  all.push_back("STATUS_PROJECTOR");
  WaitForHeartbeats(all);
  std::string out;
  EXPECT_NE(RunTool({"scan", "--url", url_, "--timeout", "120"}, &out), 0) << out;
  // The first pair: pattern 2 (its pattern, sent) and 3 (its inverse, taken again).
  EXPECT_NE(out.find("pattern 3: pattern 2 (gray column bit 0) was taken mixing two patterns"),
            std::string::npos)
      << out;
  const std::string log = camera_process->Output();
  EXPECT_NE(log.find("pattern 0: the frame changed before the next"), std::string::npos) << log;
  EXPECT_NE(log.find("pattern 1: the frame changed before the next"), std::string::npos) << log;
  EXPECT_NE(log.find("pattern 3: the frame does not add up with its pattern"), std::string::npos)
      << log;
  EXPECT_EQ(out.find("-> "), std::string::npos) << out;
  for (const auto& entry : fs::recursive_directory_iterator(dir_ + "/scans")) {
    EXPECT_NE(entry.path().filename(), "restored.tif") << entry.path();
  }
}

// A station with extra lights (three raking lamps and a UV lamp, switched by
// vellum-lights' sim backend): after the patterns the projector asks for each light and the
// camera takes its frame; the scan's folder holds them (light_<name>.png, named in scan.yaml
// with their directions), and the restorer restores each through the page's own warp, with the
// photometric normals of the three directed ones, file for file as `vellum process` of the
// recorded scan does. Given the projector's flat field and the lamps' studio field, it writes
// the page's albedo and reflectance as `vellum process` with the same files does, byte for byte.
// The camera gives more than 8 bits (the sim's texture and lights at 16): the texture and the
// lights cross the bus and reach the scan's folder at 16 bits, the structured-light frames at 8,
// and the masters (restored.tif, archival.tif, each light's) are 16-bit, as `vellum process`'s.
TEST_F(StationTest, ADeepCamerasExtraLightsAreCapturedAndRestoredAtSixteenBitsAsVellumProcessDoes) {
  // Fields as `vellum calibrate flatfield` and `vellum calibrate studio` write them, even (the
  // files must only be the same for both).
  Calibration rig;
  ASSERT_TRUE(ReadCalibration(kRig, &rig).ok());
  FlatField flat;
  flat.projector_size = rig.projector.size;
  flat.reference_mm = cv::norm(rig.projector.Center());
  flat.gain = cv::Mat((rig.projector.size.height + 7) / 8, (rig.projector.size.width + 7) / 8,
                      CV_32F, cv::Scalar(110.0));
  StudioField studio;
  studio.camera_size = rig.camera.size;
  studio.gain = cv::Mat((rig.camera.size.height + 7) / 8, (rig.camera.size.width + 7) / 8, CV_32F,
                        cv::Scalar(250.0));  // The sim camera's texture is gray.
  studio.lamps = {cv::Vec3d(-450, -250, 500), cv::Vec3d(450, -250, 500)};
  const std::string flat_file = dir_ + "/flatfield.yaml", studio_file = dir_ + "/studio.yaml";
  ASSERT_TRUE(WriteFlatField(flat_file, flat).ok());
  ASSERT_TRUE(WriteStudioField(studio_file, studio).ok());
  const std::vector<std::string> fields = {"--flatfield", flat_file, "--studio-field", studio_file};
  const std::string lights_file = dir_ + "/lights.yaml";
  {
    std::ofstream out(lights_file);
    out << "%YAML:1.0\n---\nstudio_channel: 0\nlights:\n";
    int channel = 1;
    for (const SceneLight& l : RakingLights(3)) {
      out << "  - { name: " << l.name << ", direction: [ " << l.direction[0] << ", "
          << l.direction[1] << ", " << l.direction[2] << " ], channel: " << channel++ << " }\n";
    }
    out << "  - { name: uv, channel: " << channel << " }\n";
  }
  Start(Daemon("vellum-camera"),
        {"--backend", "sim", "--rig", kRig, "--page", "curl", "--texture-bits", "16"});
  Start(Daemon("vellum-projector"),
        {"--calibration", kRig, "--fullscreen", "false", "--capture-timeout", kSimCaptureTimeout,
         "--lights", lights_file},
        {"SDL_VIDEODRIVER=offscreen"});
  Start(Daemon("vellum-lights"), {"--backend", "sim", "--lights", lights_file, "--settle-ms", "0"});
  StartProcessing(fields);
  std::vector<std::string> all = kProcessingStatus;
  for (const char* s : {"STATUS_CAMERA", "STATUS_PROJECTOR", "STATUS_LIGHTS"}) all.push_back(s);
  WaitForHeartbeats(all);
  std::string out;
  ASSERT_EQ(RunTool({"scan", "--url", url_, "--folio", "9", "--timeout", "300"}, &out), 0) << out;
  const size_t arrow = out.find("-> ");
  ASSERT_NE(arrow, std::string::npos) << out;
  std::string results = out.substr(arrow + 3);
  results = results.substr(0, results.find('\n'));
  const std::string raw = fs::path(results).parent_path().string() + "/raw";
  Scan recorded;
  ASSERT_TRUE(ReadScan(raw, &recorded).ok());
  ASSERT_EQ(recorded.lights.size(), 4u);
  const std::vector<SceneLight> raking = RakingLights(3);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(recorded.lights[k].name, raking[k].name);
    EXPECT_LT(cv::norm(recorded.lights[k].direction - raking[k].direction), 1e-6) << k;
  }
  EXPECT_EQ(recorded.lights[3].name, "uv");
  EXPECT_FALSE(recorded.lights[3].directed());
  EXPECT_EQ(recorded.texture.depth(), CV_16U);
  for (const ScanLight& light : recorded.lights)
    EXPECT_EQ(light.image.depth(), CV_16U) << light.name;
  for (const cv::Mat& frame : recorded.frames) ASSERT_EQ(frame.depth(), CV_8U);
  // 16 bits that are the camera's, not 8 bits shifted up: most samples are not multiples of 257.
  cv::Mat rest;
  cv::Mat(recorded.texture.reshape(1)).convertTo(rest, CV_32S);
  int fine = 0;
  for (auto it = rest.begin<int>(); it != rest.end<int>(); ++it) fine += *it % 257 != 0;
  EXPECT_GT(fine, static_cast<int>(rest.total() / 2));
  // Each light's frame is its own: lit from its side, not the texture or another light's.
  for (int k = 0; k < 4; ++k) {
    const cv::Mat& image = recorded.lights[k].image;
    ASSERT_EQ(image.size(), recorded.texture.size()) << k;
    for (int j = 0; j < k; ++j) {
      EXPECT_GT(cv::norm(image, recorded.lights[j].image, cv::NORM_L1) / image.total(), 1.0)
          << recorded.lights[k].name << " is " << recorded.lights[j].name << "'s frame";
    }
  }
  ExpectSameAsProcess(raw, results, "process", fields);
  const std::string processed = dir_ + "/process";
  for (const char* file : {"restored_albedo.tif", "restored_reflectance.tif"}) {
    ASSERT_TRUE(fs::exists(results + "/" + file)) << file;
    EXPECT_EQ(ReadText(results + "/" + file), ReadText(processed + "/" + file)) << file;
  }
  for (const ScanLight& light : recorded.lights) {
    const std::string file = "lights/" + light.name + ".tif";
    ASSERT_TRUE(fs::exists(results + "/" + file)) << file;
    EXPECT_EQ(ReadText(results + "/" + file), ReadText(processed + "/" + file)) << file;
  }
  EXPECT_EQ(ReadText(results + "/normals.tif"), ReadText(processed + "/normals.tif"));
  EXPECT_TRUE(fs::exists(results + "/report/relief.png"));
  std::vector<std::string> masters = {"restored.tif", "archival.tif"};
  for (const ScanLight& light : recorded.lights) masters.push_back("lights/" + light.name + ".tif");
  for (const std::string& master : masters) {
    EXPECT_EQ(cv::imread(results + "/" + master, cv::IMREAD_UNCHANGED).depth(), CV_16U) << master;
  }
  EXPECT_EQ(ReadText(results + "/archival.tif").size(),
            ReadText(processed + "/archival.tif").size());
}

// The default rig: 1600x1200 frames, a 17-chunk correspondence map and a 23-chunk point cloud
// on the bus, paced so that no receiver's buffer overflows.
TEST_F(StationTest, FullResolutionScanCrossesTheBusInChunks) {
  RunFullScan(kSource + "/config/default_calibration.yaml", 58);
}

// A station whose collection is scanned to 300 ppi (the restorer's --target-ppi, as its config
// would set it) on the small rig, whose pages are truly sampled at about 41 ppi: every scan is
// restored, and FAILs on "sampling", named with what the target asks, in `vellum scan`'s output
// and exit status and in report.json. Two scans: the target holds for each, not the first.
TEST_F(StationTest, AStationTargetOf300PpiFailsEverySmallRigScanOnSampling) {
  Start(Daemon("vellum-camera"), {"--backend", "sim", "--rig", kRig, "--page", "curl"});
  Start(Daemon("vellum-projector"),
        {"--calibration", kRig, "--fullscreen", "false", "--capture-timeout", kSimCaptureTimeout},
        {"SDL_VIDEODRIVER=offscreen"});
  StartProcessing({"--target-ppi", "300"});
  std::vector<std::string> all = kProcessingStatus;
  all.push_back("STATUS_CAMERA");
  all.push_back("STATUS_PROJECTOR");
  WaitForHeartbeats(all);
  for (int scan = 0; scan < 2; ++scan) {
    SCOPED_TRACE("scan " + std::to_string(scan + 1));
    std::string out;
    EXPECT_EQ(RunTool({"scan", "--url", url_, "--timeout", "300"}, &out), 3) << out;
    EXPECT_NE(out.find("quality: fail"), std::string::npos) << out;
    EXPECT_NE(out.find("warning sampling: "), std::string::npos) << out;
    EXPECT_NE(out.find("the target (300 ppi) asks 300"), std::string::npos) << out;
    const size_t arrow = out.find("-> ");
    ASSERT_NE(arrow, std::string::npos) << out;
    const std::string results = out.substr(arrow + 3, out.find('\n', arrow) - arrow - 3);
    const nlohmann::json report = nlohmann::json::parse(ReadText(results + "/report.json"));
    EXPECT_EQ(report["qc"]["verdict"], "fail");
    EXPECT_EQ(report["qc"]["target"], "300 ppi");
    std::string sampling;
    for (const auto& check : report["qc"]["checks"]) {
      if (check["name"] == "sampling" && check["verdict"] == "fail") sampling = check["detail"];
    }
    EXPECT_NE(sampling.find("asks 300"), std::string::npos) << report["qc"].dump();
  }
}

TEST_F(StationTest, PlaybackOfTheRecordedLogDrivesTheProcessingDaemons) {
  ASSERT_TRUE(fs::exists(kDemoLog)) << kDemoLog << " (made from tests/data at build time)";
  std::vector<restored_t> restored;
  Listener<restored_t> on_restored(*lcm_, "RESTORED",
                                   [&](const restored_t& m) { restored.push_back(m); });
  // As the demo plays it: `vellum watch --play` starts the player once every processing
  // daemon's heartbeat is heard (the daemons are started after it, so it must wait).
  Process player(
      {Tool(), "watch", "--url", url_, "--count", "1", "--timeout", "300", "--play", kDemoLog},
      dir_ + "/watch.log");
  StartProcessing();
  ASSERT_TRUE(HandleUntil(*lcm_, 300, [&] { return !restored.empty(); }))
      << "no RESTORED; watch: " << player.Output();
  EXPECT_EQ(player.Wait(60), 0) << player.Output();
  EXPECT_NE(player.Output().find("restored: "), std::string::npos) << player.Output();
  const restored_t& r = restored[0];
  EXPECT_EQ(r.view, "orthographic");
  // The demo's leaf as a library would judge it: at least 300 ppi, the camera's own
  // true sampling at its finest on the curled leaf (326 ppi; the rig samples the table
  // at 343), a clean verdict, its identity in the folder name.
  EXPECT_GE(r.dpi, 300);
  EXPECT_EQ(r.qc, "pass");
  EXPECT_NE(r.results.find("Demo-MS-1_7_recto"), std::string::npos) << r.results;
  EXPECT_GT(r.preview.width, 100);
  EXPECT_LE(static_cast<size_t>(r.preview.size), size_t{3} << 20);
  // Cropped to the leaf (56 x 70 mm) plus its margin, upright: the red initial at the top
  // left of the text, as on the page drawn, in colour.
  const cv::Mat page = cv::imread(r.results + "/restored.tif", cv::IMREAD_UNCHANGED);
  ASSERT_EQ(page.type(), CV_8UC3);
  const double mm = 25.4 / r.dpi;
  EXPECT_NEAR(page.cols * mm, 56, 8) << page.cols << " px";
  EXPECT_NEAR(page.rows * mm, 70, 8) << page.rows << " px";
  std::vector<cv::Mat> bgr;
  cv::split(page, bgr);
  cv::Mat redder;
  cv::subtract(bgr[2], bgr[1], redder, cv::noArray(), CV_16S);
  const cv::Mat red = redder > 60;  // Parchment's red exceeds its green by about 25 DN.
  ASSERT_GT(cv::countNonZero(red), 200);
  const cv::Rect initial = cv::boundingRect(red);
  EXPECT_LT(initial.x + initial.width, page.cols / 3) << initial;
  EXPECT_LT(initial.y + initial.height, page.rows / 3) << initial;

  // The same scan exported from the log and processed by `vellum process`.
  std::string out;
  ASSERT_EQ(RunTool({"export", kDemoLog, dir_ + "/exported"}, &out), 0) << out;
  ExpectSameAsProcess(dir_ + "/exported", r.results);
  EXPECT_TRUE(fs::exists(fs::path(r.results).parent_path() / "raw" / "captures.lcmlog"));
  // The scan's folder holds its SHA-256 manifest, and every file checks against it.
  ASSERT_EQ(RunTool({"manifest", "check", fs::path(r.results).parent_path().string()}, &out), 0)
      << out;
}

// Two gantries on one network, on the same multicast group and port, told apart by
// their station ids. Both scans run at once under the same scan id; each station restores its
// own page (a curl on one, a fold on the other), equal to `vellum process` of its own
// recording, and counts the other station's traffic instead of using it.
TEST_F(StationTest, TwoGantriesOnOneBusEachRestoreTheirOwnPage) {
  const std::vector<std::pair<std::string, std::string>> stations = {{"gantry-a", "curl"},
                                                                     {"gantry-b", "fold"}};
  for (const auto& [station, page] : stations) {
    Start(Daemon("vellum-camera"),
          {"--station", station, "--backend", "sim", "--rig", kRig, "--page", page});
    Start(Daemon("vellum-projector"),
          {"--station", station, "--calibration", kRig, "--fullscreen", "false",
           "--capture-timeout", kSimCaptureTimeout},
          {"SDL_VIDEODRIVER=offscreen"});
    for (const char* name :
         {"vellum-decoder", "vellum-triangulator", "vellum-flattener", "vellum-restorer"}) {
      Start(Daemon(name), {"--station", station, "--data", dir_ + "/" + station});
    }
  }
  std::vector<std::string> channels = kProcessingStatus;
  channels.push_back("STATUS_CAMERA");
  channels.push_back("STATUS_PROJECTOR");
  std::set<std::string> heard;
  std::vector<std::unique_ptr<Listener<status_t>>> listeners;
  for (const std::string& c : channels) {
    listeners.push_back(std::make_unique<Listener<status_t>>(
        *lcm_, c, [&heard, c](const status_t& m) { heard.insert(m.station + " " + c); }));
  }
  ASSERT_TRUE(HandleUntil(*lcm_, 60, [&] { return heard.size() == 2 * channels.size(); }))
      << heard.size() << " of " << 2 * channels.size() << " daemons heard";
  listeners.clear();
  const std::string id = "7000000001";
  Process a(
      {Tool(), "scan", "--url", url_, "--station", "gantry-a", "--scan-id", id, "--timeout", "300"},
      dir_ + "/scan_a.log");
  Process b(
      {Tool(), "scan", "--url", url_, "--station", "gantry-b", "--scan-id", id, "--timeout", "300"},
      dir_ + "/scan_b.log");
  ASSERT_EQ(a.Wait(400), 0) << a.Output();
  ASSERT_EQ(b.Wait(400), 0) << b.Output();
  cv::Mat restored[2];
  for (size_t k = 0; k < stations.size(); ++k) {
    const std::string folder = dir_ + "/" + stations[k].first + "/scan-" + id;
    ExpectSameAsProcess(folder + "/raw", folder + "/results", "process_" + stations[k].first);
    restored[k] = cv::imread(folder + "/results/restored.tif", cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(restored[k].empty());
    // The station's own page: its log holds one session, its own station's.
    lcm::LogFile log(folder + "/raw/captures.lcmlog", "r");
    ASSERT_TRUE(log.good());
    std::set<int64_t> sessions;
    int captures = 0;
    for (const lcm::LogEvent* e = log.readNextEvent(); e; e = log.readNextEvent()) {
      capture_t c;
      if (e->channel != "CAPTURE" || !station::SafeDecode(e->data, e->datalen, &c)) continue;
      ++captures;
      sessions.insert(c.session);
      EXPECT_EQ(c.station, stations[k].first);
    }
    EXPECT_EQ(captures, 55);
    EXPECT_EQ(sessions.size(), 1u);
  }
  // A curl and a fold restore to different pages: neither station took the other's frames.
  EXPECT_TRUE(restored[0].size() != restored[1].size() ||
              cv::norm(restored[0], restored[1], cv::NORM_L1) > 0);
}

// A scan played again after it was restored (a stale replay of its captures), a
// flood of captures for scans never started, and a second decoder on the same data folder:
// the archive stays byte for byte as it was, no folder is made, the second decoder refuses.
TEST_F(StationTest, StaleAndUnknownCapturesAreRefusedAndTheArchiveIsUnchanged) {
  StartProcessing();
  WaitForHeartbeats(kProcessingStatus);
  StatusBoard board(*lcm_, {"STATUS_DECODER"});
  std::vector<restored_t> restored;
  Listener<restored_t> on_restored(*lcm_, "RESTORED",
                                   [&](const restored_t& m) { restored.push_back(m); });
  {
    Process player({"/usr/bin/lcm-logplayer", "--lcm-url=" + url_, kLog}, dir_ + "/player.log");
    ASSERT_TRUE(HandleUntil(*lcm_, 300, [&] { return !restored.empty(); }));
    EXPECT_EQ(player.Wait(60), 0) << player.Output();
  }
  const std::string root = fs::path(restored[0].results).parent_path().string();
  std::map<std::string, std::string> archived;
  for (const auto& e : fs::recursive_directory_iterator(root + "/raw")) {
    if (e.is_regular_file()) archived[e.path().string()] = ReadText(e.path().string());
  }
  // The same recording again: its SCAN_STARTED is refused, and all 55 captures.
  {
    Process player({"/usr/bin/lcm-logplayer", "--lcm-url=" + url_, kLog}, dir_ + "/player2.log");
    EXPECT_EQ(player.Wait(120), 0) << player.Output();
  }
  // 300 captures of scans nobody started (the log's texture capture with new ids, its image cut
  // to 8 x 8 so that the burst fits the loopback's buffers).
  capture_t texture;
  {
    lcm::LogFile log(kLog, "r");
    for (const lcm::LogEvent* e = log.readNextEvent(); e; e = log.readNextEvent()) {
      if (e->channel == "CAPTURE" && station::SafeDecode(e->data, e->datalen, &texture)) break;
    }
  }
  texture.image.width = texture.image.height = texture.image.row_stride = 8;
  texture.image.pixelformat = image_t::PIXEL_FORMAT_GRAY;
  texture.image.size = 64;
  texture.image.data.assign(64, 0);
  // In bursts of 25, each once the decoder has counted the last (a socket buffer holds about
  // 90 datagrams by default: a burst of 300 would be lost on the bus, not refused).
  for (int k = 0; k < 300; ++k) {
    texture.scan_id = 9000 + k;
    texture.seq = k;
    lcm_->publish("CAPTURE", &texture);
    if (k % 25 == 24) {
      ASSERT_TRUE(HandleUntil(*lcm_, 60,
                              [&] {
                                return board.Counter("STATUS_DECODER",
                                                     "captures refused (unknown scan)") == k + 1;
                              }))
          << board.Counter("STATUS_DECODER", "captures refused (unknown scan)") << " of " << k + 1;
    }
  }
  ASSERT_TRUE(HandleUntil(
      *lcm_, 60,
      [&] {
        return board.Counter("STATUS_DECODER", "scans refused") == 1 &&
               board.Counter("STATUS_DECODER", "captures refused (scan over)") == 55 &&
               board.Counter("STATUS_DECODER", "captures refused (unknown scan)") == 300;
      }))
      << "scans refused " << board.Counter("STATUS_DECODER", "scans refused") << ", scan over "
      << board.Counter("STATUS_DECODER", "captures refused (scan over)") << ", unknown "
      << board.Counter("STATUS_DECODER", "captures refused (unknown scan)");
  std::map<std::string, std::string> now;
  for (const auto& e : fs::recursive_directory_iterator(root + "/raw")) {
    if (e.is_regular_file()) now[e.path().string()] = ReadText(e.path().string());
  }
  EXPECT_TRUE(now == archived) << "the archived scan changed";
  int folders = 0;
  for (const auto& e : fs::directory_iterator(dir_ + "/scans")) folders += e.is_directory();
  EXPECT_EQ(folders, 1);
  EXPECT_EQ(restored.size(), 1u);
  // A second decoder on the same folder (a second station set up by mistake) refuses to start.
  Process second({Daemon("vellum-decoder"), "--url", url_, "--data", dir_ + "/scans"},
                 dir_ + "/second_decoder.log");
  EXPECT_EQ(second.Wait(30), 1);
  EXPECT_NE(second.Output().find("is being recorded into by another vellum-decoder"),
            std::string::npos)
      << second.Output();
}

// Poisoned input. A scan whose scan.yaml claims a projector 2^31 pixels wide, left
// pending from before a restart, and a CAPTURE claiming a projector 2^30 pixels wide: each ends
// in a clear error within 5 s (our bar; before, both hung the decoder for good). The
// poisoned pending scan is parked, the scan of the poisoned capture fails at once (each marked
// in raw/failed.txt; the capture is never recorded); a restarted decoder takes neither up again.
// Then a capture with a pattern index beyond the count, and a CALIBRATION of another rig, each
// in the midst of a scan played through the real daemons (below).
TEST_F(StationTest, PoisonedAndMidScanMessagesFailClearlyOrAreRefusedAndNothingIsLost) {
  std::string out;
  ASSERT_EQ(RunTool({"export", kLog, dir_ + "/exported"}, &out), 0) << out;
  const std::string poisoned = dir_ + "/scans/scan-500";
  fs::create_directories(poisoned);
  fs::copy(dir_ + "/exported", poisoned + "/raw", fs::copy_options::recursive);
  {
    std::string yaml = ReadText(poisoned + "/raw/scan.yaml");
    const std::string size = "projector_size: [ 512, 384 ]";
    ASSERT_NE(yaml.find(size), std::string::npos) << yaml.substr(0, 200);
    yaml.replace(yaml.find(size), size.size(), "projector_size: [ 2147483647, 384 ]");
    std::ofstream(poisoned + "/raw/scan.yaml", std::ios::trunc) << yaml;
    std::ofstream(poisoned + "/pending") << "1\n";  // Recorded, not yet restored.
  }
  StatusBoard board(*lcm_, kProcessingStatus);
  using Clock = std::chrono::steady_clock;
  auto seconds_since = [](Clock::time_point t) {
    return std::chrono::duration<double>(Clock::now() - t).count();
  };
  Clock::time_point t0 = Clock::now();
  StartProcessing();
  WaitForHeartbeats(kProcessingStatus);
  ASSERT_TRUE(HandleUntil(*lcm_, 60, [&] {
    return !board.Error("STATUS_DECODER", "scan 500 failed and is parked").empty();
  })) << board.LastError("STATUS_DECODER");
  std::printf("[poison] scan.yaml: parked %.3f s after the daemons were started\n",
              seconds_since(t0));
  EXPECT_LE(seconds_since(t0), 5.0);
  const std::string parked = board.Error("STATUS_DECODER", "scan 500 failed and is parked");
  EXPECT_NE(parked.find("projector"), std::string::npos) << parked;
  EXPECT_NE(parked.find(poisoned + "/raw"), std::string::npos) << parked;
  EXPECT_FALSE(fs::exists(poisoned + "/pending"));
  EXPECT_EQ(ReadText(poisoned + "/raw/failed.txt").rfind("parked: ", 0), 0u);

  // A scan started as its projector starts one, whose first CAPTURE is poisoned.
  scan_started_t started;
  capture_t capture;
  {
    lcm::LogFile log(kLog, "r");
    bool have_start = false, have_capture = false;
    for (const lcm::LogEvent* e = log.readNextEvent(); e && !(have_start && have_capture);
         e = log.readNextEvent()) {
      if (e->channel == "SCAN_STARTED")
        have_start = station::SafeDecode(e->data, e->datalen, &started);
      if (e->channel == "CAPTURE" && !have_capture) {
        have_capture = station::SafeDecode(e->data, e->datalen, &capture);
      }
    }
    ASSERT_TRUE(have_start && have_capture);
  }
  started.scan_id = capture.scan_id = 600;
  started.session = capture.session = 6006;
  capture.projector_width = 1 << 30;
  lcm_->publish("SCAN_STARTED", &started);
  t0 = Clock::now();
  lcm_->publish("CAPTURE", &capture);
  ASSERT_TRUE(HandleUntil(*lcm_, 60, [&] {
    return !board.Error("STATUS_DECODER", "projector size 1073741824x").empty();
  })) << board.LastError("STATUS_DECODER");
  std::printf("[poison] CAPTURE: error %.3f s after it was sent\n", seconds_since(t0));
  std::fflush(stdout);
  EXPECT_LE(seconds_since(t0), 5.0);
  // The scan in progress fails at once, marked so on disk; the capture is not in its log.
  EXPECT_NE(board.Error("STATUS_DECODER", "projector size 1073741824x").find("scan 600 failed"),
            std::string::npos);
  const std::string raw600 = dir_ + "/scans/scan-600/raw";
  EXPECT_TRUE(fs::exists(raw600 + "/failed.txt"));
  {
    lcm::LogFile log(raw600 + "/captures.lcmlog", "r");
    ASSERT_TRUE(log.good());
    for (const lcm::LogEvent* e = log.readNextEvent(); e; e = log.readNextEvent()) {
      EXPECT_NE(e->channel, "CAPTURE") << "the poisoned capture was recorded";
    }
  }

  // The decoder is restarted (as systemd would restart a hung one): neither scan is taken up
  // again.
  Process* decoder = processes_[0].get();
  ASSERT_NE(decoder->name().find("vellum-decoder"), std::string::npos);
  decoder->Kill();
  StatusBoard after(*lcm_, {"STATUS_DECODER"});
  Start(Daemon("vellum-decoder"), {"--data", dir_ + "/scans"});
  ASSERT_TRUE(HandleUntil(*lcm_, 60, [&] {
    return after.Counter("STATUS_DECODER", "processing daemons heard") == 3;
  })) << after.LastError("STATUS_DECODER");
  EXPECT_EQ(after.Counter("STATUS_DECODER", "scans sent again"), 0);
  EXPECT_EQ(after.Counter("STATUS_DECODER", "scans failed"), 0);
  EXPECT_TRUE(after.Error("STATUS_DECODER", "scan 600").empty());

  // Bad messages in the midst of a scan, each after the scan's third capture. Each
  // scan is the recorded one imported under a new id, its log rewritten with the bad message
  // `bad_message` makes from that capture (its channel and bytes).
  using Injected = std::pair<std::string, std::vector<uint8_t>>;
  auto tampered = [&](int64_t id,
                      const std::function<Injected(const lcm::LogEvent&)>& bad_message) {
    const std::string clean = dir_ + "/scan" + std::to_string(id) + ".lcmlog";
    const std::string bad = dir_ + "/scan" + std::to_string(id) + "_bad.lcmlog";
    std::string out;
    EXPECT_EQ(RunTool({"import", dir_ + "/exported", clean, "--scan-id", std::to_string(id)}, &out),
              0)
        << out;
    lcm::LogFile in(clean, "r"), log(bad, "w");
    int captures = 0;
    int64_t eventnum = 0;
    for (const lcm::LogEvent* e = in.readNextEvent(); e; e = in.readNextEvent()) {
      lcm::LogEvent copy = *e;
      copy.eventnum = eventnum++;
      log.writeEvent(&copy);
      if (e->channel == "CAPTURE" && ++captures == 3) {
        const auto [channel, bytes] = bad_message(*e);
        copy.eventnum = eventnum++;
        copy.channel = channel;
        copy.data = const_cast<uint8_t*>(bytes.data());
        copy.datalen = static_cast<int32_t>(bytes.size());
        log.writeEvent(&copy);
      }
    }
    return bad;
  };
  // A scan's recorded log exports to the files of the scan as recorded.
  auto exports_as_recorded = [&](const std::string& raw, const std::string& to) {
    std::string out;
    ASSERT_EQ(RunTool({"export", raw + "/captures.lcmlog", to}, &out), 0) << out;
    for (const char* file : {"scan.yaml", "texture.png", "frame_000.png", "frame_053.png"}) {
      EXPECT_EQ(ReadText(to + "/" + file), ReadText(dir_ + "/exported/" + file)) << file;
    }
  };
  auto play = [&](const std::string& log) {
    Process player({"/usr/bin/lcm-logplayer", "--lcm-url=" + url_, log}, dir_ + "/player.log");
    EXPECT_EQ(player.Wait(120), 0) << player.Output();
  };
  // A CAPTURE with a pattern index beyond the count: not one of the scan's captures (no
  // projector takes it for one), so it is refused before the scan's log and the scan goes on:
  // restored, and its log exports to the scan as recorded.
  std::vector<restored_t> restored;
  Listener<restored_t> on_restored(*lcm_, "RESTORED",
                                   [&](const restored_t& m) { restored.push_back(m); });
  const std::string beyond_log = tampered(700, [&](const lcm::LogEvent& capture) {
    capture_t beyond;
    EXPECT_TRUE(station::SafeDecode(capture.data, capture.datalen, &beyond));
    beyond.pattern_index = beyond.pattern_count + 5;
    beyond.image.pattern_index = beyond.pattern_index;
    return Injected{"CAPTURE", station::Encode(beyond)};
  });
  play(beyond_log);
  ASSERT_TRUE(HandleUntil(*lcm_, 300, [&] { return !restored.empty(); }))
      << after.LastError("STATUS_DECODER");
  EXPECT_EQ(restored[0].scan_id, 700);
  EXPECT_NE(after.Error("STATUS_DECODER", "scan 700, pattern 59: pattern_index outside"), "")
      << after.LastError("STATUS_DECODER");
  const std::string raw700 = dir_ + "/scans/scan-700/raw";
  EXPECT_FALSE(fs::exists(raw700 + "/failed.txt"));
  exports_as_recorded(raw700, dir_ + "/exported700");
  restored.clear();
  // A CALIBRATION of another rig: refused at the decoder and the processing daemons; the scan
  // keeps the calibration it started with (its raw/calibration.yaml, and a result equal to
  // `vellum process` of the scan as recorded); its log exports whole.
  StatusBoard processing(*lcm_, kProcessingStatus);
  const std::string other_log = tampered(701, [&](const lcm::LogEvent&) {
    calibration_t other;
    lcm::LogFile again(dir_ + "/scan701.lcmlog", "r");
    for (const lcm::LogEvent* c = again.readNextEvent(); c; c = again.readNextEvent()) {
      if (c->channel == "CALIBRATION") {
        EXPECT_TRUE(station::SafeDecode(c->data, c->datalen, &other));
      }
    }
    other.camera.matrix[0] *= 1.1;  // Another camera's focal length.
    other.source = "another rig";
    return Injected{"CALIBRATION", station::Encode(other)};
  });
  play(other_log);
  ASSERT_TRUE(HandleUntil(*lcm_, 300, [&] { return !restored.empty(); }))
      << after.LastError("STATUS_DECODER");
  EXPECT_EQ(restored[0].scan_id, 701);
  ExpectSameAsProcess(dir_ + "/exported", restored[0].results);
  EXPECT_EQ(after.Counter("STATUS_DECODER", "scans sent again"), 0);
  ASSERT_TRUE(HandleUntil(*lcm_, 10,
                          [&] {
                            return after.Counter("STATUS_DECODER", "calibrations refused") == 1 &&
                                   processing.Counter("STATUS_TRIANGULATOR",
                                                      "calibrations refused") == 1;
                          }))
      << "decoder " << after.Counter("STATUS_DECODER", "calibrations refused") << ", triangulator "
      << processing.Counter("STATUS_TRIANGULATOR", "calibrations refused");
  const std::string raw701 = dir_ + "/scans/scan-701/raw";
  EXPECT_EQ(ReadText(raw701 + "/calibration.yaml"), ReadText(dir_ + "/exported/calibration.yaml"));
  exports_as_recorded(raw701, dir_ + "/exported701");
}

// Sends `msg` on `channel` as one LCM datagram ("LC02", a sequence number, the channel, the
// message) unicast to 127.0.0.1:port, as any host that can reach the station could.
template <class Msg>
void SendUnicast(int port, const std::string& channel, const Msg& msg) {
  std::vector<uint8_t> datagram = {'L', 'C', '0', '2', 0, 0, 0, 0};
  datagram.insert(datagram.end(), channel.begin(), channel.end());
  datagram.push_back(0);
  const std::vector<uint8_t> bytes = station::Encode(msg);
  datagram.insert(datagram.end(), bytes.begin(), bytes.end());
  const int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  ASSERT_GE(fd, 0);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(static_cast<uint16_t>(port));
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  EXPECT_EQ(
      sendto(fd, datagram.data(), datagram.size(), 0, reinterpret_cast<sockaddr*>(&to), sizeof(to)),
      static_cast<ssize_t>(datagram.size()));
  close(fd);
}

// LCM's udpm takes any datagram that reaches the bus port. Without the station's
// firewall rules a unicast SCAN_REQUEST starts a scan; with systemd/vellum-bus.nft loaded (in
// this test's own network namespace) the same datagram is dropped and counted, while the bus's
// multicast traffic still flows.
TEST_F(StationTest, TheFirewallDropsAUnicastDatagramToTheBusPort) {
  // Rules go only into this test's own network namespace (main() below).
  ASSERT_STREQ(std::getenv("VELLUM_IN_NETNS"), "1");
  const int port = std::stoi(url_.substr(url_.rfind(':') + 1));
  Start(Daemon("vellum-projector"),
        {"--calibration", kRig, "--fullscreen", "false", "--capture-timeout", "600"},
        {"SDL_VIDEODRIVER=dummy"});
  WaitForHeartbeats({"STATUS_PROJECTOR"});
  std::vector<pattern_shown_t> shown;
  Listener<pattern_shown_t> on_shown(*lcm_, "PATTERN_SHOWN",
                                     [&](const pattern_shown_t& m) { shown.push_back(m); });
  auto request = [](int64_t id) {
    scan_request_t r{};
    r.station = "vellum";
    r.scan_id = id;
    return r;
  };
  auto started = [&](int64_t id) {
    return std::any_of(shown.begin(), shown.end(),
                       [&](const pattern_shown_t& m) { return m.scan_id == id; });
  };
  // The control: without the rules, a unicast datagram starts a scan.
  SendUnicast(port, "SCAN_REQUEST", request(101));
  ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] { return started(101); }))
      << "a unicast datagram did not reach the projector even without the firewall";
  // The station's rules, for this test's port.
  std::string rules = ReadText(kSource + "/systemd/vellum-bus.nft");
  const std::string define = "define vellum_port = 7667";
  ASSERT_NE(rules.find(define), std::string::npos);
  rules.replace(rules.find(define), define.size(), "define vellum_port = " + std::to_string(port));
  std::ofstream(dir_ + "/bus.nft") << rules;
  Process nft({"/usr/sbin/nft", "-f", dir_ + "/bus.nft"}, dir_ + "/nft.log");
  ASSERT_EQ(nft.Wait(30), 0) << nft.Output();
  // The projector is in scan 101 (no camera answers): a request that reaches it now is refused
  // with an error naming it. The unicast one (102) must not reach it; the bus's own multicast
  // (103) still does.
  std::vector<status_t> statuses;
  Listener<status_t> on_status(*lcm_, "STATUS_PROJECTOR",
                               [&](const status_t& m) { statuses.push_back(m); });
  SendUnicast(port, "SCAN_REQUEST", request(102));
  scan_request_t r = request(103);
  lcm_->publish("SCAN_REQUEST", &r);
  ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] {
    return std::any_of(statuses.begin(), statuses.end(), [](const status_t& m) {
      return m.last_error.find("scan 103 refused: scan 101 is in progress") != std::string::npos;
    });
  })) << "the bus's own multicast was dropped too";
  for (const status_t& m : statuses) {
    EXPECT_EQ(m.last_error.find("scan 102"), std::string::npos) << m.last_error;
  }
  Process list({"/usr/sbin/nft", "list", "table", "inet", "vellum_bus"}, dir_ + "/nft_list.log");
  ASSERT_EQ(list.Wait(30), 0);
  EXPECT_NE(list.Output().find("counter packets 1 "), std::string::npos) << list.Output();
}

TEST_F(StationTest, WithoutACameraTheScanFailsWithAClearStatusAndTheStationStaysReady) {
  {  // No station at all: vellum scan says so at once, naming the daemons it did not hear.
    std::string out;
    EXPECT_EQ(RunTool({"scan", "--url", url_, "--wait", "1"}, &out), 1) << out;
    EXPECT_NE(out.find("no heartbeat within 1 s from vellum-projector, vellum-camera"),
              std::string::npos)
        << out;
  }
  Process* projector =
      Start(Daemon("vellum-projector"),
            {"--calibration", kRig, "--fullscreen", "false", "--capture-timeout", "1"},
            {"SDL_VIDEODRIVER=dummy"});
  WaitForHeartbeats({"STATUS_PROJECTOR"});
  for (int attempt = 0; attempt < 2; ++attempt) {
    std::string out;
    EXPECT_EQ(RunTool({"scan", "--url", url_, "--timeout", "60", "--wait", "1"}, &out), 1) << out;
    // vellum scan names the silent camera first, asks anyway, and the projector's failure
    // follows.
    EXPECT_NE(out.find("not heard within 1 s: vellum-camera"), std::string::npos) << out;
    EXPECT_NE(out.find("no CAPTURE of the texture within 1000 ms"), std::string::npos) << out;
    EXPECT_NE(out.find("failed"), std::string::npos) << out;
  }
  EXPECT_TRUE(projector->running());
}

TEST_F(StationTest, CorruptAndWrongTypeMessagesAreReportedAndTheDaemonKeepsRunning) {
  Process* decoder = Start(Daemon("vellum-decoder"), {"--data", dir_ + "/scans"});
  WaitForHeartbeats({"STATUS_DECODER"});
  std::vector<status_t> statuses;
  Listener<status_t> on_status(*lcm_, "STATUS_DECODER",
                               [&](const status_t& m) { statuses.push_back(m); });
  auto wait_error = [&](const std::string& text) {
    return HandleUntil(*lcm_, 10, [&] {
      return !statuses.empty() && statuses.back().last_error.find(text) != std::string::npos;
    });
  };
  // Garbage bytes.
  const std::vector<uint8_t> junk(1000, 0x5a);
  lcm_->publish("CAPTURE", junk.data(), static_cast<unsigned>(junk.size()));
  EXPECT_TRUE(wait_error("1000 bytes does not decode as vellum.capture_t"))
      << (statuses.empty() ? "" : statuses.back().last_error);
  // A message of another type.
  status_t other{};
  other.process = "impostor";
  lcm_->publish("CAPTURE", &other);
  EXPECT_TRUE(wait_error("does not decode as vellum.capture_t"));
  // A well-formed capture of a scan in progress, with an image whose data is too short.
  scan_started_t started{};
  started.station = "vellum";
  started.scan_id = 42;
  started.session = 5;
  started.pattern_count = 4;
  started.projector_width = 512;
  started.projector_height = 384;
  lcm_->publish("SCAN_STARTED", &started);
  capture_t c{};
  c.station = "vellum";
  c.session = 5;
  c.scan_id = 42;
  c.pattern_index = 0;
  c.pattern_count = 4;
  c.projector_width = 512;
  c.projector_height = 384;
  c.pattern.kind = pattern_spec_t::KIND_WHITE;
  c.image.width = 640;
  c.image.height = 480;
  c.image.row_stride = 640;
  c.image.pixelformat = image_t::PIXEL_FORMAT_GRAY;
  c.image.size = 1000;
  c.image.data.assign(1000, 0);
  lcm_->publish("CAPTURE", &c);
  EXPECT_TRUE(wait_error("image data is 1000 bytes; 640x480 needs 307200"))
      << (statuses.empty() ? "" : statuses.back().last_error);
  EXPECT_TRUE(decoder->running());
}

TEST_F(StationTest, LostChunksAndSequenceGapsAreReportedNotSilentlyUsed) {
  Process* triangulator =
      Start(Daemon("vellum-triangulator"), {"--data", dir_ + "/scans", "--calibration", kRig});
  WaitForHeartbeats({"STATUS_TRIANGULATOR"});
  std::vector<status_t> statuses;
  Listener<status_t> on_status(*lcm_, "STATUS_TRIANGULATOR",
                               [&](const status_t& m) { statuses.push_back(m); });
  auto chunk = [](int64_t scan, int index, int64_t seq) {
    correspondence_t m{};
    m.station = "vellum";
    m.seq = seq;
    m.scan_id = scan;
    m.chunk_index = index;
    m.chunk_count = 3;
    m.width = 640;
    m.height = 480;
    m.row_begin = 160 * index;
    m.row_count = 160;
    m.projector_width = 512;
    m.projector_height = 384;
    m.has_columns = m.has_rows = true;
    m.n = 160 * 640;
    m.projector_x.assign(m.n, 100.0f);
    m.projector_y.assign(m.n, 100.0f);
    m.valid.assign(m.n, 255);
    return m;
  };
  // Scan 1: chunks 0 and 2 (chunk 1 lost, and with it seq 1), then scan 2 begins.
  for (auto [scan, index, seq] : {std::tuple{1, 0, 0}, {1, 2, 2}, {2, 0, 3}}) {
    correspondence_t m = chunk(scan, index, seq);
    lcm_->publish("CORRESPONDENCE", &m);
  }
  auto has_error = [&](const std::string& text) {
    for (const status_t& s : statuses) {
      if (s.last_error.find(text) != std::string::npos) return true;
    }
    return false;
  };
  auto counter = [&](const std::string& name) {
    int64_t most = 0;
    for (const status_t& s : statuses) {
      for (int i = 0; i < s.ncounters; ++i) {
        if (s.counter_names[i] == name) most = std::max(most, s.counter_values[i]);
      }
    }
    return most;
  };
  // The gap is counted and chunk 1 asked again as soon as the last chunk came; no one sends it
  // again, so the product is given up, an error, when scan 2 begins. The loss alone is no error
  // (asked again, it is usually recovered).
  EXPECT_TRUE(HandleUntil(*lcm_, 10, [&] {
    return counter("lost messages") == 1 && counter("chunks asked again") >= 1 &&
           has_error(
               "scan 1: CORRESPONDENCE incomplete (chunk 1 of 3 missing) when scan 2 "
               "began, asked again 1 time(s)");
  })) << (statuses.empty() ? "no status" : statuses.back().last_error);
  EXPECT_FALSE(has_error("lost on the bus"));
  EXPECT_FALSE(fs::exists(dir_ + "/scans/scan-1/results/points.ply"));
  EXPECT_TRUE(triangulator->running());
}

// The operator's window under Xvfb with the whole station: after a scan, a screenshot of the
// X server (Xvfb keeps its screen as an XWD file) shows the restored page, where OpenCV finds
// the leaf's whole checkerboard (16 x 21 inner corners), and the camera's live preview.
TEST_F(StationTest, ViewerShowsTheRestoredPageAfterAScan) {
  const ViewedStation station = StartViewedStation(kRig);
  const std::string& screen = station.screen;
  std::string out;
  ASSERT_EQ(RunTool({"scan", "--url", url_, "--timeout", "300"}, &out), 0) << out;
  // The viewer redraws ten times a second.
  cv::Mat shot;
  bool found = false;
  std::vector<cv::Point2f> corners;
  for (int attempt = 0; attempt < 30 && !found; ++attempt) {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    shot = testing::ReadXwd(screen);
    ASSERT_FALSE(shot.empty()) << "cannot read the Xvfb screen " << screen;
    cv::Mat gray;
    cv::cvtColor(shot(cv::Rect(shot.cols * 2 / 3, 0, shot.cols - shot.cols * 2 / 3, shot.rows)),
                 gray, cv::COLOR_BGR2GRAY);
    found = cv::findChessboardCorners(gray, cv::Size(16, 21), corners);
  }
  cv::imwrite(dir_ + "/screenshot.png", shot);
  EXPECT_TRUE(found) << "no 16x21 checkerboard in the restored-page region; see "
                     << dir_ + "/screenshot.png";
  // The live preview (top left) is not blank: the camera's view of the page.
  cv::Mat preview;
  cv::cvtColor(shot(cv::Rect(20, 70, shot.cols / 3 - 40, 250)), preview, cv::COLOR_BGR2GRAY);
  cv::Scalar mean, stddev;
  cv::meanStdDev(preview, mean, stddev);
  EXPECT_GT(stddev[0], 20) << "the camera preview looks empty";
  EXPECT_EQ(StopCleanly(station.viewer), 0)
      << station.viewer->Output();  // Before its X server goes.
}

// An operator at the viewer (a real X server, keys typed with xdotool) enters a
// folio's identity once in the form, and scans folios 1r, 1v and 2r; then takes the last two
// advances back (u, u) and retakes 1v. Each scan's folder is named after its folio, its
// report.json carries the identity; the retake of 1v is the folder at the top, and the first
// attempt of 1v is kept whole in retaken/.
TEST_F(StationTest, AFolioSequenceTypedInTheViewerIsNamedAndARetakeKeepsTheFirstAside) {
  const ViewedStation station = StartViewedStation(kRig);
  const std::string& display = station.display;
  std::vector<scan_request_t> requests;
  Listener<scan_request_t> on_request(*lcm_, "SCAN_REQUEST",
                                      [&](const scan_request_t& m) { requests.push_back(m); });
  std::vector<restored_t> restored;
  Listener<restored_t> on_restored(*lcm_, "RESTORED",
                                   [&](const restored_t& m) { restored.push_back(m); });
  // The viewer's window takes the keyboard (there is no window manager to give it).
  ASSERT_TRUE(Xdotool(
      display, {"search", "--sync", "--name", "vellum station", "windowfocus", "--sync", "%1"}));
  // The form opens (its state on the viewer's status), then the operator types.
  std::string viewer_state, viewer_detail;
  Listener<status_t> on_viewer(*lcm_, "STATUS_VIEWER", [&](const status_t& m) {
    viewer_state = m.state;
    viewer_detail = m.detail;
  });
  ASSERT_TRUE(Xdotool(display, {"key", "e"}));
  ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] { return viewer_state == "editing"; }));
  ASSERT_TRUE(Xdotool(display, {"type", "--delay", "30", "MS 7"}));
  ASSERT_TRUE(Xdotool(display, {"key", "Tab"}));
  ASSERT_TRUE(Xdotool(display, {"type", "--delay", "30", "1"}));
  ASSERT_TRUE(Xdotool(display, {"key", "Tab"}));
  ASSERT_TRUE(Xdotool(display, {"type", "--delay", "30", "rceto"}));  // Not typed: chosen...
  ASSERT_TRUE(Xdotool(display, {"key", "space"}));                    // ...recto.
  ASSERT_TRUE(Xdotool(display, {"key", "Tab"}));
  ASSERT_TRUE(Xdotool(display, {"type", "--delay", "30", "B. Binder"}));
  ASSERT_TRUE(Xdotool(display, {"key", "Return"}));
  ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] { return viewer_state == "idle"; }));
  // One scan from the viewer's s key: asked for with `folio` and `side`, and restored.
  auto scan = [&](const std::string& folio, const std::string& side) {
    const size_t n = requests.size();
    // The viewer takes a scan once it hears the whole station (it says so on its status).
    ASSERT_TRUE(HandleUntil(*lcm_, 60, [&] { return viewer_detail == "ready to scan"; }))
        << "the viewer: " << viewer_state << ", " << viewer_detail;
    ASSERT_TRUE(Xdotool(display, {"key", "s"}));
    ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] { return requests.size() > n; }))
        << "no SCAN_REQUEST from the viewer's s key";
    const scan_request_t& r = requests.back();
    EXPECT_EQ(r.identity.shelfmark, "MS 7");
    EXPECT_EQ(r.identity.folio, folio);
    EXPECT_EQ(r.identity.side, side);
    EXPECT_EQ(r.identity.operator_name, "B. Binder");
    ASSERT_TRUE(HandleUntil(*lcm_, 300,
                            [&] {
                              return std::any_of(
                                  restored.begin(), restored.end(),
                                  [&](const restored_t& m) { return m.scan_id == r.scan_id; });
                            }))
        << "scan " << r.scan_id << " (" << folio << " " << side << ") was not restored";
  };
  scan("1", "recto");
  scan("1", "verso");
  const int64_t first_verso = requests.back().scan_id;
  scan("2", "recto");
  ASSERT_TRUE(Xdotool(display, {"key", "u"}));  // 2r again...
  ASSERT_TRUE(Xdotool(display, {"key", "u"}));  // ...and 1v again: a retake.
  scan("1", "verso");
  const int64_t retake = requests.back().scan_id;
  // The folders: one per folio at the top, the newest attempt; the first 1v in retaken/.
  std::map<std::string, int> folios;
  for (const auto& e : fs::directory_iterator(dir_ + "/scans")) {
    const std::string name = e.path().filename().string();
    if (name.rfind("scan-", 0) != 0) continue;
    const std::string slug = name.substr(name.find('-', 5) + 1);
    ++folios[slug];
    const nlohmann::json report =
        nlohmann::json::parse(ReadText(e.path().string() + "/results/report.json"));
    EXPECT_EQ(report["identity"]["shelfmark"], "MS 7") << name;
    EXPECT_EQ(report["identity"]["operator"], "B. Binder") << name;
    EXPECT_EQ("MS-7_" + report["identity"]["folio"].get<std::string>() + "_" +
                  report["identity"]["side"].get<std::string>(),
              slug);
    EXPECT_TRUE(fs::exists(e.path().string() + "/results/restored.tif")) << name;
    // The restored file's own record of what it is.
    const nlohmann::json restored_json =
        nlohmann::json::parse(ReadText(e.path().string() + "/results/restored.json"));
    EXPECT_EQ(restored_json["identity"], report["identity"]) << name;
    std::map<std::string, std::string> xmp;
    EXPECT_TRUE(ReadXmp(e.path().string() + "/results/restored.tif", &xmp).ok()) << name;
    EXPECT_EQ(xmp["dc:identifier"], "MS 7") << name;
    EXPECT_EQ(xmp["vellum:folio"], report["identity"]["folio"]) << name;
    EXPECT_EQ(xmp["vellum:side"], report["identity"]["side"]) << name;
  }
  EXPECT_EQ(folios, (std::map<std::string, int>{
                        {"MS-7_1_recto", 1}, {"MS-7_1_verso", 1}, {"MS-7_2_recto", 1}}));
  EXPECT_TRUE(fs::exists(dir_ + "/scans/scan-" + std::to_string(retake) + "-MS-7_1_verso"));
  const std::string aside =
      dir_ + "/scans/retaken/scan-" + std::to_string(first_verso) + "-MS-7_1_verso";
  EXPECT_TRUE(fs::exists(aside + "/results/restored.tif")) << aside;
  EXPECT_TRUE(fs::exists(aside + "/raw/captures.lcmlog")) << aside;
  // The contact sheet: the three folios, then the earlier attempt of 1v.
  const std::string sheet = ReadText(dir_ + "/scans/index.html");
  const size_t first = sheet.find("MS 7, 1 recto"), earlier = sheet.find("Earlier attempts");
  EXPECT_NE(sheet.find("MS 7, 2 recto"), std::string::npos) << sheet;
  EXPECT_NE(first, std::string::npos) << sheet;
  EXPECT_NE(earlier, std::string::npos) << sheet;
  EXPECT_NE(sheet.find("retaken/scan-" + std::to_string(first_verso)), std::string::npos);
  EXPECT_LT(first, earlier);
  EXPECT_EQ(StopCleanly(station.viewer), 0)
      << station.viewer->Output();  // Before its X server goes.
}

// Whether `shot` shows `text` as the viewer writes it: OpenCV's Hershey simplex at `scale` in
// colour `fg` on `bg`. The text rendered alone the same way is found among the screen's pixels
// near `fg` (normalised correlation of the two masks, 0.9 at least): the viewer's words checked
// on the X screen, without OCR.
bool ShowsText(const cv::Mat& shot, const std::string& text, double scale, const cv::Scalar& fg,
               const cv::Scalar& bg) {
  int baseline = 0;
  const cv::Size size = cv::getTextSize(text, cv::FONT_HERSHEY_SIMPLEX, scale, 1, &baseline);
  cv::Mat glyphs(size.height + baseline + 4, size.width + 4, CV_8UC3, bg);
  cv::putText(glyphs, text, cv::Point(2, size.height + 2), cv::FONT_HERSHEY_SIMPLEX, scale, fg, 1,
              cv::LINE_AA);
  const cv::Scalar low = fg - cv::Scalar::all(30), high = fg + cv::Scalar::all(30);
  cv::Mat want, have;
  cv::inRange(glyphs, low, high, want);
  cv::inRange(shot, low, high, have);
  if (have.cols < want.cols || have.rows < want.rows) return false;
  cv::Mat score;
  cv::matchTemplate(have, want, score, cv::TM_CCORR_NORMED);
  double best = 0;
  cv::minMaxLoc(score, nullptr, &best);
  return best >= 0.9;
}

// A flat leaf that runs off the right edge of the camera's view (its centre 115 mm right: its
// right edge 10 mm past the small rig's 200 mm half width) is restored, and fails quality
// control on "leaf in view": in report.json, on RESTORED, in `vellum scan`'s output and exit
// status, and as a red badge over the restored page in the viewer (read from the X screen).
// This scene passed every check once: the view's outer ring taught the cut the flat leaf's look
// as the table's, its outline stopped short of the edge, and nothing else said the leaf ran on
// (LookRunsOff does now; the scene family's edge test covers the rest).
TEST_F(StationTest, ALeafPartlyOutOfViewFailsQualityControlInTheReportAndTheViewer) {
  const ViewedStation station =
      StartViewedStation(kRig, {"--page", "flat", "--centre", "115,0", "--texture", "text"});
  const std::string& screen = station.screen;
  std::vector<restored_t> restored;
  Listener<restored_t> on_restored(*lcm_, "RESTORED",
                                   [&](const restored_t& m) { restored.push_back(m); });
  std::string out;
  EXPECT_EQ(RunTool({"scan", "--url", url_, "--timeout", "300"}, &out), 3) << out;
  EXPECT_NE(out.find("quality: fail"), std::string::npos) << out;
  EXPECT_NE(out.find("page_cut_off"), std::string::npos) << out;
  ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] { return !restored.empty(); }));
  EXPECT_EQ(restored[0].qc, "fail");
  const nlohmann::json report =
      nlohmann::json::parse(ReadText(restored[0].results + "/report.json"));
  EXPECT_EQ(report["qc"]["verdict"], "fail") << report["qc"].dump();
  EXPECT_EQ(report["qc"]["checks"][0]["name"], "leaf in view");
  EXPECT_EQ(report["qc"]["checks"][0]["verdict"], "fail");
  EXPECT_NE(report["qc"]["checks"][0]["detail"].get<std::string>().find("runs off the camera"),
            std::string::npos)
      << report["qc"].dump();
  // The viewer: a red badge across the top of the restored page's column.
  auto badge_red = [&] {
    const cv::Mat shot = testing::ReadXwd(screen);
    if (shot.empty()) return false;
    const cv::Rect badge(shot.cols * 2 / 3 + 10, 46, shot.cols / 3 - 30, 14);
    cv::Mat mask;
    cv::inRange(shot(badge), cv::Scalar(0, 0, 180), cv::Scalar(80, 80, 255), mask);
    return cv::countNonZero(mask) > badge.area() / 2;
  };
  EXPECT_TRUE(HandleUntil(*lcm_, 30, badge_red)) << "no red quality badge; see " << screen;
  // The warning under the page in full, wrapped to the panel's width, to its remedy's last word
  // (a line cut at the panel's edge lost the remedy once), in amber on the X screen: its first
  // line, and its last, which is some tail of its words ending in "scan again", wherever the
  // wrap put it. (Lines are matched whole: a word amid a line lies at a fraction of a pixel.)
  const std::string warning =
      "! page_cut_off: the leaf runs off the camera's view: what lies outside it is missing from "
      "the restored page; move the leaf into the view and scan again";
  auto remedy_shown = [&] {
    const cv::Mat shot = testing::ReadXwd(screen);
    const cv::Scalar amber(0, 170, 255), background(30, 30, 30);
    if (shot.empty() || !ShowsText(shot, "! page_cut_off:", 0.42, amber, background)) return false;
    for (size_t at = warning.find(' '); at != std::string::npos; at = warning.find(' ', at + 1)) {
      if (ShowsText(shot, warning.substr(at + 1), 0.42, amber, background)) return true;
    }
    return false;
  };
  EXPECT_TRUE(HandleUntil(*lcm_, 30, remedy_shown)) << "the remedy is not shown; see " << screen;
  cv::imwrite(dir_ + "/cut_off.png", testing::ReadXwd(screen));
  // Asked from the viewer, whose live outline ran off the right edge: the request says so, the
  // scan's raw/scan.yaml keeps it, and its report records it.
  std::vector<scan_request_t> requests;
  Listener<scan_request_t> on_request(*lcm_, "SCAN_REQUEST",
                                      [&](const scan_request_t& m) { requests.push_back(m); });
  std::string viewer_detail;
  Listener<status_t> on_viewer(*lcm_, "STATUS_VIEWER",
                               [&](const status_t& m) { viewer_detail = m.detail; });
  ASSERT_TRUE(HandleUntil(*lcm_, 60, [&] { return viewer_detail == "ready to scan"; }))
      << viewer_detail;
  ASSERT_TRUE(Xdotool(station.display, {"search", "--sync", "--name", "vellum station",
                                        "windowfocus", "--sync", "%1"}));
  ASSERT_TRUE(Xdotool(station.display, {"key", "s"}));
  ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] { return !requests.empty(); }));
  EXPECT_EQ(requests[0].live_off_view, "right");
  ASSERT_TRUE(HandleUntil(*lcm_, 120, [&] {
    return std::any_of(restored.begin(), restored.end(),
                       [&](const restored_t& m) { return m.scan_id == requests[0].scan_id; });
  }));
  const restored_t& asked =
      *std::find_if(restored.begin(), restored.end(),
                    [&](const restored_t& m) { return m.scan_id == requests[0].scan_id; });
  EXPECT_EQ(asked.qc, "fail");
  const std::string yaml = ReadText(asked.results + "/../raw/scan.yaml");
  EXPECT_NE(yaml.find("live_off_view: [ right ]"), std::string::npos) << yaml;
  const nlohmann::json seen = nlohmann::json::parse(ReadText(asked.results + "/report.json"));
  EXPECT_NE(seen.dump().find("\"live_off_view\":\"right\""), std::string::npos);
  EXPECT_EQ(StopCleanly(station.viewer), 0) << station.viewer->Output();
}

// The camera stops in the middle of a scan. The viewer (on a real X server) turns its
// header red with the failure within the projector's capture timeout, checked on the screen;
// the scan's folder is marked failed, with the reason.
TEST_F(StationTest, ACameraStoppedMidScanTurnsTheViewerRedAndTheScanIsMarkedFailed) {
  const double capture_timeout_s = 20;
  const ViewedStation station = StartViewedStation(
      kRig, {}, std::to_string(static_cast<int>(capture_timeout_s)), {"--scan-timeout", "5"});
  const std::string& screen = station.screen;
  int captured = 0;
  int64_t scan_id = 0;
  Listener<capture_t> on_capture(*lcm_, "CAPTURE", [&](const capture_t& c) {
    ++captured;
    scan_id = c.scan_id;
  });
  Process scan({Tool(), "scan", "--url", url_, "--timeout", "300"}, dir_ + "/scan.log");
  ASSERT_TRUE(HandleUntil(*lcm_, 120, [&] { return captured >= 5; }));
  station.camera->Kill();
  const auto stopped = std::chrono::steady_clock::now();
  // The header: red across the top of the screen.
  auto header_red = [&] {
    const cv::Mat shot = testing::ReadXwd(screen);
    if (shot.empty()) return false;
    cv::Mat mask;
    cv::inRange(shot(cv::Rect(0, 0, shot.cols, 36)), cv::Scalar(0, 0, 180), cv::Scalar(80, 80, 255),
                mask);
    return cv::countNonZero(mask) > shot.cols * 36 / 2;
  };
  EXPECT_FALSE(header_red()) << "red before the failure";
  ASSERT_TRUE(HandleUntil(*lcm_, capture_timeout_s + 30, header_red))
      << "the viewer's header never turned red; see " << screen;
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - stopped).count();
  std::printf("[viewer] header red %.1f s after the camera stopped (capture timeout %.0f s)\n",
              seconds, capture_timeout_s);
  std::fflush(stdout);
  EXPECT_LE(seconds, capture_timeout_s + 5);  // A heartbeat and a redraw after the timeout.
  cv::imwrite(dir_ + "/failed.png", testing::ReadXwd(screen));
  EXPECT_NE(scan.Wait(120), 0) << scan.Output();
  const std::string failed = dir_ + "/scans/scan-" + std::to_string(scan_id) + "/raw/failed.txt";
  ASSERT_TRUE(HandleUntil(*lcm_, 60, [&] { return fs::exists(failed); })) << failed;
  EXPECT_NE(ReadText(failed).find("captures missing"), std::string::npos) << ReadText(failed);
  EXPECT_EQ(StopCleanly(station.viewer), 0) << station.viewer->Output();
}

// The operator's sequence at the gantry (a real X server, keys typed with xdotool), through
// a camera that stops mid-scan: folio 4 verso of MS 12 is scanned and fails when the camera is
// killed. The failure box names the folio; `s` with the camera down is refused, on screen; with
// the camera back, Enter retakes 4 verso (not 5 recto), and its result is named as the second
// attempt. A viewer restarted after it resumes at 5 recto. Every folder, report and XMP carries
// its folio.
TEST_F(StationTest, AFolioWhoseScanFailedIsRetakenNextAndTheSequenceSurvivesARestart) {
  const double capture_timeout_s = 8;
  ViewedStation station = StartViewedStation(
      kRig, {}, std::to_string(static_cast<int>(capture_timeout_s)), {"--scan-timeout", "5"});
  const std::string& display = station.display;
  const std::string& screen = station.screen;
  std::vector<scan_request_t> requests;
  Listener<scan_request_t> on_request(*lcm_, "SCAN_REQUEST",
                                      [&](const scan_request_t& m) { requests.push_back(m); });
  std::vector<restored_t> restored;
  Listener<restored_t> on_restored(*lcm_, "RESTORED",
                                   [&](const restored_t& m) { restored.push_back(m); });
  int captured = 0;
  Listener<capture_t> on_capture(*lcm_, "CAPTURE", [&](const capture_t&) { ++captured; });
  std::string viewer_state, viewer_detail;
  int32_t stopped_viewer = -1;  // A stopped viewer's last heartbeats may still be on their way.
  Listener<status_t> on_viewer(*lcm_, "STATUS_VIEWER", [&](const status_t& m) {
    if (m.pid == stopped_viewer) return;
    viewer_state = m.state;
    viewer_detail = m.detail;
  });
  auto focus = [&] {
    return Xdotool(display,
                   {"search", "--sync", "--name", "vellum station", "windowfocus", "--sync", "%1"});
  };
  auto ready = [&] {
    return HandleUntil(*lcm_, 60, [&] { return viewer_detail == "ready to scan"; });
  };
  ASSERT_TRUE(focus());
  ASSERT_TRUE(Xdotool(display, {"key", "e"}));
  ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] { return viewer_state == "editing"; }));
  ASSERT_TRUE(Xdotool(display, {"type", "--delay", "30", "MS 12"}));
  ASSERT_TRUE(Xdotool(display, {"key", "Tab"}));
  ASSERT_TRUE(Xdotool(display, {"type", "--delay", "30", "4"}));
  ASSERT_TRUE(Xdotool(display, {"key", "Tab", "space", "space", "Return"}));  // verso
  ASSERT_TRUE(ready()) << viewer_state << ": " << viewer_detail;
  // 4 verso; the camera stops mid-scan.
  ASSERT_TRUE(Xdotool(display, {"key", "s"}));
  ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] { return requests.size() == 1; }));
  const int64_t first = requests.back().scan_id;
  EXPECT_EQ(requests.back().identity.folio, "4");
  EXPECT_EQ(requests.back().identity.side, "verso");
  ASSERT_TRUE(HandleUntil(*lcm_, 120, [&] { return captured >= 5; }));
  station.camera->Kill();
  // The failure box, titled with the folio (white on the box's dark red).
  const std::string title = "MS 12, 4 verso (scan " + std::to_string(first) + ") failed:";
  ASSERT_TRUE(HandleUntil(*lcm_, capture_timeout_s + 30,
                          [&] {
                            const cv::Mat shot = testing::ReadXwd(screen);
                            return !shot.empty() &&
                                   ShowsText(shot, title, 0.55, cv::Scalar(255, 255, 255),
                                             cv::Scalar(20, 20, 60));
                          }))
      << "no '" << title << "' on the screen; see " << dir_ + "/failed.png";
  cv::imwrite(dir_ + "/failed.png", testing::ReadXwd(screen));
  // s with the camera down: refused, the reason on screen in red and on the viewer's status.
  ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] {
    return viewer_detail.find("cannot scan: the camera sends nothing") != std::string::npos;
  })) << viewer_detail;
  ASSERT_TRUE(Xdotool(display, {"key", "s"}));
  HandleUntil(*lcm_, 3, [] { return false; });  // The key's time to be read (a no-show).
  EXPECT_EQ(requests.size(), 1u) << "a scan asked for with the camera down";
  {
    const cv::Mat shot = testing::ReadXwd(screen);
    cv::imwrite(dir_ + "/refused.png", shot);
    EXPECT_TRUE(ShowsText(shot, "cannot scan: the camera sends nothing", 0.42,
                          cv::Scalar(40, 40, 220), cv::Scalar(30, 30, 30)))
        << "see " << dir_ + "/refused.png";
  }
  // The camera back: Enter retakes 4 verso, the second attempt.
  station.camera =
      Start(Daemon("vellum-camera"), {"--backend", "sim", "--rig", kRig, "--page", "curl"});
  ASSERT_TRUE(ready()) << viewer_detail;
  ASSERT_TRUE(Xdotool(display, {"key", "Return"}));
  ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] { return requests.size() == 2; }));
  const int64_t retake = requests.back().scan_id;
  EXPECT_EQ(requests.back().identity.folio, "4");
  EXPECT_EQ(requests.back().identity.side, "verso") << "the next scan after a failure is a retake";
  ASSERT_TRUE(HandleUntil(*lcm_, 300, [&] {
    return std::any_of(restored.begin(), restored.end(),
                       [&](const restored_t& m) { return m.scan_id == retake; });
  })) << "the retake was not restored";
  ASSERT_TRUE(HandleUntil(*lcm_, 30,
                          [&] {
                            const cv::Mat shot = testing::ReadXwd(screen);
                            return !shot.empty() &&
                                   ShowsText(shot, "MS 12, 4 verso, attempt 2 (retake)", 0.5,
                                             cv::Scalar(230, 230, 230), cv::Scalar(30, 30, 30));
                          }))
      << "the result is not named as the retake; see " << dir_ + "/retaken.png";
  cv::imwrite(dir_ + "/retaken.png", testing::ReadXwd(screen));
  // The viewer restarted: the sequence goes on at 5 recto.
  stopped_viewer = static_cast<int32_t>(station.viewer->pid());
  ASSERT_EQ(StopCleanly(station.viewer), 0) << station.viewer->Output();
  viewer_state.clear();  // What the stopped viewer last said.
  viewer_detail.clear();
  station.viewer = Start(Daemon("vellum-viewer"), {"--data", dir_ + "/scans"},
                         {"DISPLAY=" + display, "SDL_VIDEODRIVER=x11"});
  ASSERT_TRUE(ready()) << viewer_detail;  // Its window drawn, the station heard...
  ASSERT_TRUE(focus());                   // ...then it takes the keyboard.
  ASSERT_TRUE(Xdotool(display, {"key", "Return"}));
  const bool asked = HandleUntil(*lcm_, 30, [&] { return requests.size() == 3; });
  cv::imwrite(dir_ + "/restarted.png", testing::ReadXwd(screen));
  ASSERT_TRUE(asked) << "see " << dir_ + "/restarted.png";
  EXPECT_EQ(requests.back().identity.folio, "5");
  EXPECT_EQ(requests.back().identity.side, "recto");
  const int64_t next = requests.back().scan_id;
  ASSERT_TRUE(HandleUntil(*lcm_, 300, [&] {
    return std::any_of(restored.begin(), restored.end(),
                       [&](const restored_t& m) { return m.scan_id == next; });
  }));
  // The folders: the failed first attempt set aside by the retake, each restored scan's report
  // and XMP naming its folio.
  EXPECT_TRUE(fs::exists(dir_ + "/scans/scan-" + std::to_string(retake) + "-MS-12_4_verso"));
  EXPECT_TRUE(fs::exists(dir_ + "/scans/scan-" + std::to_string(next) + "-MS-12_5_recto"));
  EXPECT_TRUE(fs::exists(dir_ + "/scans/retaken/scan-" + std::to_string(first) + "-MS-12_4_verso"));
  for (const auto& [id, folio, side] :
       {std::tuple<int64_t, std::string, std::string>{retake, "4", "verso"},
        std::tuple<int64_t, std::string, std::string>{next, "5", "recto"}}) {
    const std::string results =
        dir_ + "/scans/scan-" + std::to_string(id) + "-MS-12_" + folio + "_" + side + "/results";
    const nlohmann::json report = nlohmann::json::parse(ReadText(results + "/report.json"));
    EXPECT_EQ(report["identity"]["folio"], folio);
    EXPECT_EQ(report["identity"]["side"], side);
    std::map<std::string, std::string> xmp;
    EXPECT_TRUE(ReadXmp(results + "/restored.tif", &xmp).ok()) << results;
    EXPECT_EQ(xmp["vellum:folio"], folio);
    EXPECT_EQ(xmp["vellum:side"], side);
  }
  EXPECT_EQ(StopCleanly(station.viewer), 0) << station.viewer->Output();
}

// A small leaf off the view's centre on a support as bright as it (the default rig): asked for
// with no hint, it is found there (the support is what it lies on) and restored clean; with the
// operator's hint (`vellum scan --leaf-hint`, as the viewer's drawn box: fractions of the view)
// and word for what it is (--object leaf) both travel SCAN_REQUEST -> SCAN_STARTED ->
// raw/scan.yaml (the hint in camera pixels), the leaf is restored clean at its own size, and
// `vellum process` on the raw folder gives the same.
TEST_F(StationTest, TheOperatorsLeafHintAndObjectReachTheScanAndALeafOffTheCentreIsFound) {
  const std::string rig = kSource + "/config/default_calibration.yaml";
  Start(Daemon("vellum-camera"),
        {"--backend", "sim", "--rig", rig, "--page", "curl", "--scene", "support", "--page-size",
         "100x130", "--centre", "100,60", "--texture", "text"});
  Start(Daemon("vellum-projector"),
        {"--calibration", rig, "--fullscreen", "false", "--capture-timeout", kSimCaptureTimeout},
        {"SDL_VIDEODRIVER=offscreen"});
  StartProcessing();
  std::vector<std::string> all = kProcessingStatus;
  for (const char* s : {"STATUS_CAMERA", "STATUS_PROJECTOR"}) all.push_back(s);
  WaitForHeartbeats(all);
  auto results_of = [](const std::string& out) {
    const size_t arrow = out.find("-> ");
    if (arrow == std::string::npos) return std::string();
    const std::string rest = out.substr(arrow + 3);
    return rest.substr(0, rest.find('\n'));
  };
  std::string out;
  EXPECT_EQ(RunTool({"scan", "--url", url_, "--timeout", "300"}, &out), 0) << out;
  EXPECT_NE(out.find("quality: pass"), std::string::npos) << out;
  // The leaf lies 100 mm right and 60 mm up of the view's centre on the default rig (0.25 mm
  // pixels, y down): camera pixels about 1000..1400 across and 100..620 down. A box in its
  // middle, as fractions of the 1600 x 1200 view.
  ASSERT_EQ(RunTool({"scan", "--url", url_, "--timeout", "300", "--leaf-hint",
                     "0.6875,0.1666667,0.125,0.25", "--object", "leaf"},
                    &out),
            0)
      << out;
  EXPECT_NE(out.find("quality: pass"), std::string::npos) << out;
  const std::string results = results_of(out);
  ASSERT_FALSE(results.empty()) << out;
  const std::string raw = fs::path(results).parent_path().string() + "/raw";
  Scan recorded;
  ASSERT_TRUE(ReadScanHeader(raw, &recorded).ok());
  EXPECT_EQ(recorded.leaf_hint, cv::Rect(1100, 200, 200, 300));
  EXPECT_EQ(recorded.object, ObjectKind::kLeaf);
  const nlohmann::json report = nlohmann::json::parse(ReadText(results + "/report.json"));
  EXPECT_EQ(report["outline"]["object"], "leaf") << report["outline"].dump();
  EXPECT_EQ(report["outline"]["hint_from"], "scan") << report["outline"].dump();
  EXPECT_EQ(report["outline"]["hint"], "1100,200,200,300") << report["outline"].dump();
  EXPECT_TRUE(report["warnings"].empty()) << report["warnings"].dump();
  // The restored leaf at its own size: 100 x 130 mm plus the 3 mm margin each side.
  const nlohmann::json restored = nlohmann::json::parse(ReadText(results + "/restored.json"));
  const double mm = 25.4 / restored["dpi"].get<double>();
  cv::Mat page = cv::imread(results + "/restored.tif", cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(page.empty());
  EXPECT_NEAR(page.cols * mm, 106, 4) << page.cols << " px at " << mm << " mm";
  EXPECT_NEAR(page.rows * mm, 136, 4) << page.rows << " px at " << mm << " mm";
  ExpectSameAsProcess(raw, results);
}

// The recorder crashes in the middle of a scan and systemd starts it again. What the decoder
// had received is on disk (each capture is appended to the scan's log the moment it arrives;
// the new decoder continues that log, never truncates it, and takes its captures up). A
// capture still in flight at the crash is lost with the process: then the scan fails with a
// status naming it; else the scan is processed. Either way the station takes the next scan.
TEST_F(StationTest, DecoderKilledMidScanKeepsEveryReceivedCaptureAndTheStationGoesOn) {
  Start(Daemon("vellum-camera"), {"--backend", "sim", "--rig", kRig, "--page", "curl"});
  // 300 ms per pattern: time for a restart between two captures.
  Start(Daemon("vellum-projector"),
        {"--calibration", kRig, "--fullscreen", "false", "--settle-ms", "300", "--capture-timeout",
         kSimCaptureTimeout},
        {"SDL_VIDEODRIVER=offscreen"});
  StartProcessing();
  Process* decoder = processes_[2].get();
  ASSERT_NE(decoder->name().find("vellum-decoder"), std::string::npos);
  std::vector<std::string> all = kProcessingStatus;
  all.push_back("STATUS_CAMERA");
  all.push_back("STATUS_PROJECTOR");
  WaitForHeartbeats(all);
  // The patterns in the order the bus carried them; the window in which no decoder could hear
  // them runs from the kill (less the captures the killed one may not yet have logged) to the
  // restarted decoder's first heartbeat (it subscribes before it beats).
  std::vector<int> heard;
  int64_t scan_id = 0;
  Listener<capture_t> on_capture(*lcm_, "CAPTURE", [&](const capture_t& c) {
    heard.push_back(c.pattern_index);
    scan_id = c.scan_id;
  });
  Process scan({Tool(), "scan", "--url", url_, "--timeout", "300"}, dir_ + "/scan.log");
  ASSERT_TRUE(HandleUntil(*lcm_, 60, [&] { return heard.size() >= 12; }));
  decoder->Kill();
  const size_t at_kill = heard.size();
  Process* restarted =
      Start(Daemon("vellum-decoder"), {"--data", dir_ + "/scans", "--scan-timeout", "3"});
  bool ready = false;
  Listener<status_t> on_status(*lcm_, "STATUS_DECODER", [&](const status_t& s) {
    ready = ready || s.pid == restarted->pid();
  });
  ASSERT_TRUE(HandleUntil(*lcm_, 60, [&] { return ready; })) << restarted->Output();
  const size_t at_ready = heard.size();
  const int code = scan.Wait(300);
  const std::string out = scan.Output();
  EXPECT_NE(restarted->Output().find("captures already there"), std::string::npos)
      << restarted->Output();
  // Every capture the first decoder logged plus every one after the restart is in the log.
  const std::string raw = dir_ + "/scans/scan-" + std::to_string(scan_id) + "/raw";
  lcm::LogFile log(raw + "/captures.lcmlog", "r");
  ASSERT_TRUE(log.good());
  std::set<int> patterns;
  for (const lcm::LogEvent* e = log.readNextEvent(); e; e = log.readNextEvent()) {
    capture_t c;
    if (e->channel == "CAPTURE" && station::SafeDecode(e->data, e->datalen, &c)) {
      patterns.insert(c.pattern_index);
    }
  }
  // Two captures may be in flight at the kill (sent, not yet logged); every other one before
  // it, and every one after the new decoder was listening, is kept.
  constexpr size_t kInFlight = 2;
  for (size_t k = 0; k < heard.size(); ++k) {
    if (k + kInFlight < at_kill || k >= at_ready) {
      EXPECT_TRUE(patterns.count(heard[k]))
          << "pattern " << heard[k] << " (capture " << k << " of the scan; decoder killed after "
          << at_kill << ", the new one listening after " << at_ready << ") is missing from the log";
    }
  }
  std::printf("[restart] %zu of 55 kept; %zu captures went by while no decoder listened\n",
              patterns.size(), at_ready - at_kill);
  if (code == 0) {
    EXPECT_EQ(patterns.size(), 55u);
  } else {
    EXPECT_NE(out.find("captures missing"), std::string::npos) << out;
    EXPECT_NE(out.find("kept in " + raw), std::string::npos) << out;
  }
  // The station goes on: the next scan is whole and processed.
  std::string next;
  EXPECT_EQ(RunTool({"scan", "--url", url_, "--timeout", "300"}, &next), 0) << next;
}

// A processing daemon killed while a scan is on its way to it, then restarted (as systemd
// does): the decoder sees the new pid and sends the scan again from disk, and the scan is
// restored exactly as `vellum process` restores it. The daemon is frozen (SIGSTOP) before the
// scan reaches it, so it is killed holding the scan, whatever the machine's speed. Once for each
// processing daemon after the decoder: the restarted triangulator takes the scan's calibration
// from disk, the flattener and restorer the texture too.
TEST_F(StationTest, ProcessingDaemonKilledHoldingAScanIsRestartedAndTheScanIsRestored) {
  StartProcessing();
  WaitForHeartbeats(kProcessingStatus);
  std::vector<restored_t> restored;
  Listener<restored_t> on_restored(*lcm_, "RESTORED",
                                   [&](const restored_t& m) { restored.push_back(m); });
  StatusBoard board(*lcm_, kProcessingStatus);
  auto counter = [&](const std::string& channel, const std::string& name) {
    return board.Counter(channel, name);
  };
  // The decoder must know each daemon's pid before one is frozen, or the restart looks to it
  // like a daemon's first start (its heartbeat may have gone out before the decoder listened).
  ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] {
    return counter("STATUS_DECODER", "processing daemons heard") == 3;  // Tri., flat., rest.
  })) << "the decoder did not hear every processing daemon";
  std::string out;
  ASSERT_EQ(RunTool({"export", kLog, dir_ + "/exported"}, &out), 0) << out;
  const struct {
    const char* daemon;
    const char* upstream;  // The stage before it, and its counter of scans done.
    const char* done;
  } victims[] = {{"vellum-triangulator", "STATUS_DECODER", "scans decoded"},
                 {"vellum-flattener", "STATUS_TRIANGULATOR", "scans triangulated"},
                 {"vellum-restorer", "STATUS_FLATTENER", "scans flattened"}};
  for (int round = 0; round < 3; ++round) {
    const auto& victim = victims[round];
    SCOPED_TRACE(victim.daemon);
    Process* target = nullptr;
    for (auto& p : processes_) {
      if (!p->killed() && p->name().find(victim.daemon) != std::string::npos) target = p.get();
    }
    ASSERT_NE(target, nullptr);
    ASSERT_EQ(kill(target->pid(), SIGSTOP), 0);
    const int64_t done_before = counter(victim.upstream, victim.done);  // Restarts reset it.
    const int64_t id = 100 + round;
    const std::string log = dir_ + "/scan" + std::to_string(id) + ".lcmlog";
    ASSERT_EQ(RunTool({"import", dir_ + "/exported", log, "--scan-id", std::to_string(id)}, &out),
              0)
        << out;
    Process player({"/usr/bin/lcm-logplayer", "--lcm-url=" + url_, log}, dir_ + "/player.log");
    ASSERT_TRUE(HandleUntil(*lcm_, 120,
                            [&] { return counter(victim.upstream, victim.done) > done_before; }))
        << victim.upstream << " never finished the scan";
    target->Kill();
    Start(Daemon(victim.daemon), {"--data", dir_ + "/scans"});
    ASSERT_TRUE(HandleUntil(*lcm_, 120,
                            [&] {
                              return std::any_of(
                                  restored.begin(), restored.end(),
                                  [&](const restored_t& r) { return r.scan_id == id; });
                            }))
        << "scan " << id << " was not restored after the restart";
    const restored_t& r = *std::find_if(restored.begin(), restored.end(),
                                        [&](const restored_t& m) { return m.scan_id == id; });
    ExpectSameAsProcess(dir_ + "/exported", r.results);
    // Sent again by the decoder, not taken up by the restarted daemon from an announcement:
    // the count the test waited for is published only after the announcement went out.
    EXPECT_EQ(counter("STATUS_DECODER", "scans sent again"), round + 1)
        << processes_[0]->Output() << processes_.back()->Output();
    // Restored: no longer pending, so it is not sent again at the next restart.
    const std::string pending = dir_ + "/scans/scan-" + std::to_string(id) + "/pending";
    EXPECT_TRUE(HandleUntil(*lcm_, 10, [&] { return !fs::exists(pending); })) << pending;
    player.Wait(60);
  }
  const std::string decoder_log = processes_[0]->Output();
  for (const auto& victim : victims) {
    EXPECT_NE(
        decoder_log.find(std::string(victim.daemon) + " restarted before the scan was restored"),
        std::string::npos)
        << decoder_log;
  }
}

// A loaded station loses no scan to the bus: two busy loops load both cores, and the flattener
// is paused (SIGSTOP) from the moment the decoder hands the demo's scan on until 2 s after the
// triangulator has sent its point cloud (1440 x 1080: 18 MB in 1 MB chunks), so its socket
// buffer overflows and most chunks are lost. Resumed, it asks for the chunks it lacks on RESEND,
// the triangulator sends them again, and the scan is restored, file for file as `vellum process`
// restores its recording, with the recovery counted on the status channel and nothing sent
// again from disk.
TEST_F(StationTest, APausedReceiverOnALoadedMachineAsksAgainForWhatTheBusLost) {
  std::vector<std::unique_ptr<Process>> busy;
  for (int k = 0; k < 2; ++k) {
    busy.push_back(
        std::make_unique<Process>(std::vector<std::string>{"/bin/sh", "-c", "while :; do :; done"},
                                  dir_ + "/busy" + std::to_string(k) + ".log"));
  }
  StartProcessing();
  WaitForHeartbeats(kProcessingStatus);
  StatusBoard board(*lcm_, kProcessingStatus);
  ASSERT_TRUE(HandleUntil(
      *lcm_, 60, [&] { return board.Counter("STATUS_DECODER", "processing daemons heard") == 3; }));
  Process* flattener = nullptr;
  for (auto& p : processes_) {
    if (p->name().find("vellum-flattener") != std::string::npos) flattener = p.get();
  }
  ASSERT_NE(flattener, nullptr);
  std::vector<restored_t> restored;
  Listener<restored_t> on_restored(*lcm_, "RESTORED",
                                   [&](const restored_t& m) { restored.push_back(m); });
  bool paused = false, points_sent = false;
  std::chrono::steady_clock::time_point paused_at;
  Listener<scan_progress_t> on_progress(*lcm_, "SCAN_PROGRESS", [&](const scan_progress_t& m) {
    if (m.process == "vellum-decoder" && !paused) {
      paused = kill(flattener->pid(), SIGSTOP) == 0;
      paused_at = std::chrono::steady_clock::now();
    }
    if (m.process == "vellum-triangulator") points_sent = true;
  });
  std::string out;
  ASSERT_EQ(RunTool({"export", kDemoLog, dir_ + "/exported"}, &out), 0) << out;
  Process player({"/usr/bin/lcm-logplayer", "--lcm-url=" + url_, kDemoLog}, dir_ + "/player.log");
  ASSERT_TRUE(HandleUntil(*lcm_, 300, [&] { return points_sent; }))
      << "the triangulator never sent the points";
  ASSERT_TRUE(paused);
  HandleUntil(*lcm_, 60, [&] {
    return std::chrono::steady_clock::now() - paused_at > std::chrono::seconds(2);
  });
  ASSERT_EQ(kill(flattener->pid(), SIGCONT), 0);
  ASSERT_TRUE(HandleUntil(*lcm_, 300, [&] { return !restored.empty(); }))
      << "not restored; the flattener said: " << board.LastError("STATUS_FLATTENER");
  ExpectSameAsProcess(dir_ + "/exported", restored[0].results);
  EXPECT_TRUE(HandleUntil(*lcm_, 10, [&] {
    return board.Counter("STATUS_FLATTENER", "products recovered") >= 1;
  })) << "the point cloud came whole without asking: the pause lost nothing";
  EXPECT_GE(board.Counter("STATUS_FLATTENER", "chunks asked again"), 1);
  EXPECT_GE(board.Counter("STATUS_TRIANGULATOR", "chunks sent again"), 1);
  EXPECT_EQ(board.Counter("STATUS_FLATTENER", "products lost"), 0);
  EXPECT_EQ(board.Counter("STATUS_DECODER", "scans sent again"), 0);
  player.Wait(60);
}

// The supervisor sends a scan again only to a daemon that held it. Here the chain has no
// restorer yet: a scan goes through the decoder, triangulator and flattener and waits. Then the
// triangulator and the flattener restart: the scan is past both, so it is not sent again (no
// stage processes it twice). When the restorer at last starts, the scan is sent once, and
// restored.
TEST_F(StationTest, AScanPastARestartedDaemonIsNotProcessedTwice) {
  for (const char* name : {"vellum-decoder", "vellum-triangulator", "vellum-flattener"}) {
    Start(Daemon(name), {"--data", dir_ + "/scans"});
  }
  StatusBoard board(*lcm_, kProcessingStatus);
  auto counter = [&](const std::string& channel, const std::string& name) {
    return board.Counter(channel, name);
  };
  ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] {
    return counter("STATUS_DECODER", "processing daemons heard") == 2;
  })) << "the decoder did not hear the triangulator and the flattener";
  std::string out;
  ASSERT_EQ(RunTool({"export", kLog, dir_ + "/exported"}, &out), 0) << out;
  const std::string log = dir_ + "/scan300.lcmlog";
  ASSERT_EQ(RunTool({"import", dir_ + "/exported", log, "--scan-id", "300"}, &out), 0) << out;
  Process player({"/usr/bin/lcm-logplayer", "--lcm-url=" + url_, log}, dir_ + "/player.log");
  ASSERT_TRUE(HandleUntil(*lcm_, 120, [&] {
    return counter("STATUS_FLATTENER", "scans flattened") == 1;
  })) << "the scan did not reach the flattener";
  EXPECT_EQ(player.Wait(60), 0);
  // Both daemons the scan has passed restart.
  for (const char* name : {"vellum-triangulator", "vellum-flattener"}) {
    for (auto& p : processes_) {
      if (!p->killed() && p->name().find(name) != std::string::npos) p->Kill();
    }
    Start(Daemon(name), {"--data", dir_ + "/scans"});
  }
  ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] {
    return counter("STATUS_DECODER", "restarts seen") == 2;
  })) << "the decoder did not see both restarts";
  // The restorer starts: the scan, never restored, goes down the chain once more, and only once.
  std::vector<restored_t> restored;
  Listener<restored_t> on_restored(*lcm_, "RESTORED",
                                   [&](const restored_t& m) { restored.push_back(m); });
  Start(Daemon("vellum-restorer"), {"--data", dir_ + "/scans"});
  ASSERT_TRUE(HandleUntil(*lcm_, 120, [&] { return !restored.empty(); })) << "not restored";
  EXPECT_EQ(restored[0].scan_id, 300);
  ExpectSameAsProcess(dir_ + "/exported", restored[0].results);
  const std::string pending = dir_ + "/scans/scan-300/pending";
  ASSERT_TRUE(HandleUntil(*lcm_, 10, [&] { return !fs::exists(pending); })) << pending;
  // Each stage after the restarts processed the scan once: one send after the first.
  ASSERT_TRUE(HandleUntil(*lcm_, 10,
                          [&] {
                            return counter("STATUS_DECODER", "scans decoded") == 2 &&
                                   counter("STATUS_TRIANGULATOR", "scans triangulated") == 1 &&
                                   counter("STATUS_FLATTENER", "scans flattened") == 1;
                          }))
      << "decoded " << counter("STATUS_DECODER", "scans decoded") << ", triangulated "
      << counter("STATUS_TRIANGULATOR", "scans triangulated") << ", flattened "
      << counter("STATUS_FLATTENER", "scans flattened");
  EXPECT_EQ(counter("STATUS_DECODER", "scans sent again"), 1);
  EXPECT_EQ(restored.size(), 1u);
}

// `vellum calibrate capture` records one board pose through the real camera (sim, the board
// held tilted above the table) and projector daemons as a scan directory, in which
// `vellum calibrate solve` finds every corner of the board.
TEST_F(StationTest, CalibrateCaptureRecordsABoardPoseThroughTheStation) {
  Start(Daemon("vellum-camera"),
        {"--backend", "sim", "--rig", kRig, "--page", "flat", "--pose", "18,0,4,0,0,60"});
  Start(Daemon("vellum-projector"),
        {"--calibration", kRig, "--fullscreen", "false", "--capture-timeout", kSimCaptureTimeout},
        {"SDL_VIDEODRIVER=offscreen"});
  WaitForHeartbeats({"STATUS_CAMERA", "STATUS_PROJECTOR"});
  const std::string pose = dir_ + "/pose";
  std::string out;
  ASSERT_EQ(RunTool({"calibrate", "capture", "--url", url_, "--out", pose}, &out), 0) << out;
  Scan scan;
  const Status s = ReadScan(pose, &scan);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(scan.frames.size(), scan.sequence.patterns.size());
  EXPECT_EQ(scan.texture.size(), cv::Size(640, 480));
  // One pose is too few to solve, but its board is found whole and lit.
  EXPECT_EQ(RunTool({"calibrate", "solve", "--table", pose, "--out", dir_ + "/cal.yaml"}, &out), 1);
  EXPECT_NE(out.find("336 corners"), std::string::npos) << out;
  EXPECT_NE(out.find("only 1 usable board poses of 1"), std::string::npos) << out;
}

// The disk fills up while a scan is recorded: the scan fails with a status that says so, the
// decoder keeps running, and the scan recorded before it is intact on disk.
TEST_F(StationTest, DiskFullWhileRecordingFailsTheScanAndKeepsEarlierScans) {
  const std::string small = dir_ + "/small";
  fs::create_directories(small);
  // About one and a half scans of this rig (17 MB of log and 10 MB of images each).
  if (std::system(("mount -t tmpfs -o size=40m tmpfs " + small).c_str()) != 0) {
    GTEST_SKIP() << "cannot mount a tmpfs here (needs the mount namespace of netns-run.sh)";
  }
  std::string out;
  ASSERT_EQ(RunTool({"export", kLog, dir_ + "/scan"}, &out), 0) << out;
  Process* decoder = Start(Daemon("vellum-decoder"), {"--data", small});
  WaitForHeartbeats({"STATUS_DECODER"});
  std::vector<status_t> statuses;
  Listener<status_t> on_status(*lcm_, "STATUS_DECODER",
                               [&](const status_t& m) { statuses.push_back(m); });
  auto counter = [&](const std::string& name) -> int64_t {
    if (statuses.empty()) return 0;
    const status_t& s = statuses.back();
    for (int k = 0; k < s.ncounters; ++k) {
      if (s.counter_names[k] == name) return s.counter_values[k];
    }
    return 0;
  };
  for (int id = 1; id <= 2; ++id) {
    const std::string log = dir_ + "/scan" + std::to_string(id) + ".lcmlog";
    ASSERT_EQ(RunTool({"import", dir_ + "/scan", log, "--scan-id", std::to_string(id)}, &out), 0)
        << out;
    Process player({"/usr/bin/lcm-logplayer", "--lcm-url=" + url_, log}, dir_ + "/player.log");
    if (id == 1) {
      ASSERT_TRUE(HandleUntil(*lcm_, 60, [&] { return counter("scans decoded") >= 1; }));
    } else {
      EXPECT_TRUE(HandleUntil(*lcm_, 60, [&] {
        return !statuses.empty() && statuses.back().last_error_scan_id == 2 &&
               statuses.back().last_error.find("cannot write") != std::string::npos;
      })) << (statuses.empty() ? "no status" : statuses.back().last_error);
    }
    player.Wait(60);
  }
  EXPECT_TRUE(decoder->running());
  EXPECT_EQ(counter("scans decoded"), 1);
  // Scan 1 is whole: its log reads back complete and equal to what was played.
  Scan scan, played;
  bool has_calibration = false;
  calibration_t calibration;
  int64_t id = 0;
  ASSERT_TRUE(ReadScan(dir_ + "/scan", &played).ok());
  const Status s = station::ReadScanLog(small + "/scan-1/raw/captures.lcmlog", 1, &scan,
                                        &has_calibration, &calibration, &id);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(scan.frames.size(), played.frames.size());
  for (size_t k = 0; k < scan.frames.size(); ++k) {
    EXPECT_EQ(cv::norm(scan.frames[k], played.frames[k], cv::NORM_INF), 0.0) << k;
  }
  Scan from_images;
  EXPECT_TRUE(ReadScan(small + "/scan-1/raw", &from_images).ok());
  EXPECT_EQ(decoder->Stop(), 0) << decoder->Output();  // It holds files on the tmpfs.
  std::system(("umount " + small).c_str());
}

// Peak resident memory of a process (VmHWM), MB; 0 if it is gone.
double PeakRssMb(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  }
  return 0;
}

// Scans back to back through the playback path (VELLUM_LOAD_SCANS of them, default 50): every
// one restored, each daemon's peak memory bounded (reported), and a clean exit (under the
// sanitizer build, LeakSanitizer fails the exit on a leak).
TEST_F(StationTest, ScansBackToBackKeepMemoryBounded) {
  const char* env = std::getenv("VELLUM_LOAD_SCANS");
  const int scans = env ? std::atoi(env) : 50;
  std::string out;
  ASSERT_EQ(RunTool({"export", kLog, dir_ + "/scan"}, &out), 0) << out;
  StartProcessing();
  WaitForHeartbeats(kProcessingStatus);
  std::set<int64_t> restored;
  Listener<restored_t> on_restored(*lcm_, "RESTORED",
                                   [&](const restored_t& m) { restored.insert(m.scan_id); });
  std::map<std::string, std::vector<double>> rss;
  for (int k = 1; k <= scans; ++k) {
    const std::string log = dir_ + "/scan.lcmlog";
    ASSERT_EQ(RunTool({"import", dir_ + "/scan", log, "--scan-id", std::to_string(k)}, &out), 0)
        << out;
    Process player({"/usr/bin/lcm-logplayer", "--lcm-url=" + url_, log}, dir_ + "/player.log");
    ASSERT_TRUE(HandleUntil(*lcm_, 120, [&] { return restored.count(k) > 0; }))
        << "scan " << k << " not restored";
    player.Wait(30);
    // Keep the disk in check, once the decoder has cleared the scan's pending mark on its
    // RESTORED (it deletes that file itself; removing the folder under it races).
    const std::string folder = dir_ + "/scans/scan-" + std::to_string(k);
    ASSERT_TRUE(HandleUntil(*lcm_, 30, [&] { return !fs::exists(folder + "/pending"); }))
        << "scan " << k << " still pending after its RESTORED";
    fs::remove_all(folder);
    for (auto& p : processes_) rss[p->name()].push_back(PeakRssMb(p->pid()));
  }
  for (const auto& [name, series] : rss) {
    // Peak after the first scans against the peak at the end: no growth scan after scan.
    const double early = series[std::min<size_t>(series.size() - 1, 4)], last = series.back();
    std::printf("load: %s peak RSS %.0f MB after scan %d, %.0f MB after scan %d\n",
                fs::path(name).filename().c_str(), early, std::min(5, scans), last, scans);
#ifndef __SANITIZE_ADDRESS__  // ASan's quarantine keeps freed memory: RSS says nothing there.
    EXPECT_LT(last, early * 1.25 + 20) << name << " grows with the number of scans";
#endif
  }
  EXPECT_EQ(static_cast<int>(restored.size()), scans);
}

TEST_F(StationTest, EveryDaemonHasHelpAndRejectsABadConfigFile) {
  std::ofstream(dir_ + "/bad.yaml") << "%YAML:1.0\n---\nno-such-flag: 3\n";
  for (const char* name :
       {"vellum-camera", "vellum-projector", "vellum-lights", "vellum-decoder",
        "vellum-triangulator", "vellum-flattener", "vellum-restorer", "vellum-viewer"}) {
    Process help({Daemon(name), "--help"}, dir_ + "/help.log");
    EXPECT_EQ(help.Wait(30), 0) << name;
    EXPECT_NE(help.Output().find("--url"), std::string::npos) << name;
    Process bad({Daemon(name), "--config", dir_ + "/bad.yaml"}, dir_ + "/bad.log");
    EXPECT_EQ(bad.Wait(30), 2) << name;
    EXPECT_NE(bad.Output().find("unknown key 'no-such-flag'"), std::string::npos)
        << name << ": " << bad.Output();
  }
}

}  // namespace
}  // namespace vellum

// Every run of this binary (each test, and the test discovery at build time) happens inside a
// private network namespace whose only interface is loopback (scripts/netns-run.sh): its udpm
// bus, and the firewall rules one test loads, never touch the machine's own network.
int main(int argc, char** argv) {
  if (std::getenv("VELLUM_IN_NETNS") == nullptr) {
    std::string script = std::string(VELLUM_SOURCE_DIR) + "/scripts/netns-run.sh";
    std::vector<char*> args = {script.data()};
    for (int k = 0; k < argc; ++k) args.push_back(argv[k]);
    args.push_back(nullptr);
    execv(script.c_str(), args.data());
    std::perror(("station_test: cannot run " + script).c_str());
    return 1;
  }
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
