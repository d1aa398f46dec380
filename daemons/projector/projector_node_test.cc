// The projector's node on an in-process bus with its real SDL screen (SDL's dummy video
// driver): a scan request publishes the calibration and runs the whole sequence, one pattern per
// CAPTURE, each pattern on screen with the mirror's flip before PATTERN_SHOWN; bad requests and a
// capture that never comes are reported, and the projector takes the next scan.
#include "daemons/projector/projector_node.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <opencv2/imgproc.hpp>

#include "daemons/projector/sdl_projector.h"
#include "station/daemon.h"
#include "station/messages.h"
#include "station/testing.h"
#include "vellum/calibration_t.hpp"
#include "vellum/light_t.hpp"
#include "vellum/pattern_shown_t.hpp"
#include "vellum/scan_started_t.hpp"
#include "vellum/status_t.hpp"

namespace vellum::station {
namespace {

using testing::MemqBus;

// The projector's screen, as a projector with a mirror would show it: remembers what was on
// screen (read back from SDL) when each pattern was shown.
class WatchedProjector : public Projector {
 public:
  explicit WatchedProjector(const SdlProjectorOptions& options) : sdl_(options) {}
  cv::Size size() const override { return sdl_.size(); }
  void Show(const cv::Mat& gray) override {
    sdl_.Show(gray);
    shown.push_back(gray.clone());
    screens.push_back(sdl_.Screen());
  }
  bool Poll() override { return sdl_.Poll(); }
  std::vector<cv::Mat> shown, screens;

 private:
  SdlProjector sdl_;
};

class ProjectorNodeTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { setenv("SDL_VIDEODRIVER", "dummy", 1); }
  ProjectorNodeTest() {
    screen_.size = QuickRig().projector.size;
    screen_.fullscreen = false;
    screen_.flip = display::Flip::kHorizontal;
    options_.patterns.projector_size = screen_.size;
    options_.calibration = QuickRig();
    options_.calibration_source = "small rig";
    options_.settle = std::chrono::milliseconds(0);
  }
  void Request(int64_t id) {
    scan_request_t r{};
    r.scan_id = id;
    bus_.probe().Publish(channel::kScanRequest, &r);
  }
  // Answers every PATTERN_SHOWN with its CAPTURE (a frame-less ack) until the scan's end.
  void AnswerEveryPattern(const std::shared_ptr<std::vector<pattern_shown_t>>& shown,
                          size_t* answered) {
    while (*answered < shown->size()) {
      const pattern_shown_t& m = (*shown)[(*answered)++];
      capture_t c{};
      c.scan_id = m.scan_id;
      c.session = m.session;
      c.pattern_index = m.pattern_index;
      c.pattern_count = m.pattern_count;
      bus_.probe().Publish(channel::kCapture, &c);
    }
  }

  SdlProjectorOptions screen_;
  ProjectorNodeOptions options_;
  MemqBus bus_;
};

TEST_F(ProjectorNodeTest, RunsTheWholeSequenceOnePatternPerCaptureWithTheMirrorFlipOnScreen) {
  Node node("vellum-projector", &bus_.lcm(), &bus_.clock());
  auto projector = std::make_unique<WatchedProjector>(screen_);
  WatchedProjector* screen = projector.get();
  ProjectorNode conductor(&node, std::move(projector), options_);
  bus_.AddTick([&] { conductor.Tick(); });
  auto calibrations = bus_.Record<calibration_t>(channel::kCalibration);
  auto started = bus_.Record<scan_started_t>(channel::kScanStarted);
  auto shown = bus_.Record<pattern_shown_t>(channel::kPatternShown);
  size_t answered = 0;
  bus_.AddTick([&] { AnswerEveryPattern(shown, &answered); });
  Request(77);
  const PatternSequence sequence = MakePatternSequence(options_.patterns);
  const size_t total = sequence.patterns.size() + 1;
  ASSERT_TRUE(bus_.RunUntil([&] { return shown->size() == total && conductor.scan_id() == 0; }));
  ASSERT_EQ(calibrations->size(), 1u);
  EXPECT_EQ(calibrations->front().scan_id, 77);
  EXPECT_EQ(calibrations->front().source, "small rig");
  // One session for the whole scan, announced first.
  ASSERT_EQ(started->size(), 1u);
  EXPECT_GT(started->front().session, 0);
  EXPECT_EQ(calibrations->front().session, started->front().session);
  for (const pattern_shown_t& m : *shown) EXPECT_EQ(m.session, started->front().session);
  for (size_t k = 0; k < total; ++k) EXPECT_EQ((*shown)[k].pattern_index, int(k) - 1);
  EXPECT_EQ(node.Counter("scans captured"), 1);
  // Pattern k was on screen, mirrored left to right, when PATTERN_SHOWN(k) went out. (Shows:
  // black at start, black for the texture, the patterns, black at the end.)
  ASSERT_EQ(screen->shown.size(), total + 2);
  int asymmetric = 0;  // Patterns that a mirror changes: the flip shows on them.
  for (size_t p = 0; p < sequence.patterns.size(); ++p) {
    const PatternSpec& spec = sequence.patterns[p];
    const cv::Mat expected = RenderPattern(spec, sequence.projector_size);
    EXPECT_EQ(cv::norm(screen->shown[p + 2], expected, cv::NORM_INF), 0) << p;
    cv::Mat on_screen, mirrored;
    cv::cvtColor(screen->screens[p + 2], on_screen, cv::COLOR_BGR2GRAY);
    cv::flip(expected, mirrored, 1);
    ASSERT_EQ(on_screen.size(), mirrored.size());
    EXPECT_EQ(cv::norm(on_screen, mirrored, cv::NORM_INF), 0) << "pattern " << p;
    if (cv::norm(mirrored, expected, cv::NORM_INF) > 0) ++asymmetric;
  }
  EXPECT_GT(asymmetric, 5);
}

TEST_F(ProjectorNodeTest, BadRequestsAndAMissingCaptureAreReportedAndTheNextScanRuns) {
  Node node("vellum-projector", &bus_.lcm(), &bus_.clock());
  ProjectorNode conductor(&node, std::make_unique<SdlProjector>(screen_), options_);
  bus_.AddTick([&] { conductor.Tick(); });
  bus_.Watch("vellum-projector");
  Request(0);
  EXPECT_TRUE(bus_.WaitForError("vellum-projector", "SCAN_REQUEST with scan_id 0 refused"));
  Request(5);
  Request(6);
  EXPECT_TRUE(bus_.WaitForError("vellum-projector", "scan 6 refused: scan 5 is in progress"));
  // No capture comes: the scan waits out its capture timeout (5 s) on the node's clock, then
  // fails.
  bus_.StepFor(4.9);
  EXPECT_EQ(conductor.scan_id(), 5);
  EXPECT_TRUE(bus_.StepUntil(
      [&] {
        return bus_.Status("vellum-projector")
                   .last_error.find("scan 5 failed: no CAPTURE of the texture within 5000 ms") !=
               std::string::npos;
      },
      0.1, 1))
      << bus_.Status("vellum-projector").last_error;
  EXPECT_EQ(conductor.scan_id(), 0);
  auto shown = bus_.Record<pattern_shown_t>(channel::kPatternShown);
  size_t answered = 0;
  bus_.AddTick([&] { AnswerEveryPattern(shown, &answered); });
  Request(7);
  EXPECT_TRUE(bus_.RunUntil([&] { return node.Counter("scans captured") == 1; }));
  EXPECT_EQ(node.Counter("scans failed"), 1);
}

// A scan the decoder fails while it is being captured (its status: "scans failed" rose with an
// error naming the scan) is stopped at once: black on screen, no more patterns, and the next
// request is taken. An error of the decoder about another scan, or with no failure counted,
// does not stop it.
TEST_F(ProjectorNodeTest, AScanTheDecoderFailsStopsAtOnceAndTheNextRequestIsTaken) {
  Node node("vellum-projector", &bus_.lcm(), &bus_.clock());
  auto projector = std::make_unique<WatchedProjector>(screen_);
  WatchedProjector* screen = projector.get();
  ProjectorNode conductor(&node, std::move(projector), options_);
  bus_.AddTick([&] { conductor.Tick(); });
  auto shown = bus_.Record<pattern_shown_t>(channel::kPatternShown);
  auto decoder = [&](int64_t failed, int64_t error_scan) {
    status_t m{};
    m.process = "vellum-decoder";
    m.pid = 1;
    m.state = "busy";
    m.counter_names = {counter::kScansFailed};
    m.counter_values = {failed};
    m.ncounters = 1;
    m.last_error_scan_id = error_scan;
    m.last_error = "scan " + std::to_string(error_scan) + " failed: recording failed: disk full";
    bus_.probe().Publish(StatusChannel("vellum-decoder"), &m);
  };
  decoder(0, 0);
  Request(31);
  ASSERT_TRUE(bus_.RunUntil([&] { return !shown->empty(); }));
  decoder(0, 31);  // An error about the scan, not a failure: it goes on.
  decoder(1, 30);  // A failure of another scan: it goes on.
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("received STATUS_DECODER") == 3; }));
  EXPECT_EQ(conductor.scan_id(), 31);
  decoder(2, 31);  // The decoder failed scan 31.
  ASSERT_TRUE(bus_.RunUntil([&] { return conductor.scan_id() == 0; }));
  EXPECT_EQ(node.Counter("scans stopped"), 1);
  EXPECT_EQ(node.Counter(counter::kScansFailed), 0) << "the decoder's failure, not the projector's";
  EXPECT_EQ(cv::countNonZero(screen->shown.back()), 0) << "not black after the stop";
  const size_t patterns_then = shown->size();
  size_t answered = patterns_then;  // The stopped scan's last pattern is never answered.
  bus_.AddTick([&] { AnswerEveryPattern(shown, &answered); });
  Request(32);
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("scans captured") == 1; }));
  for (size_t k = patterns_then; k < shown->size(); ++k) EXPECT_EQ((*shown)[k].scan_id, 32);
}

// A capture of another session (a stale one, another projector's) does not advance
// the scan; a station calibration (scan_id 0) published mid-scan applies from the next scan.
TEST_F(ProjectorNodeTest, OnlyItsSessionsCapturesAdvanceItAndANewCalibrationWaitsForTheNextScan) {
  Node node("vellum-projector", &bus_.lcm(), &bus_.clock());
  ProjectorNode conductor(&node, std::make_unique<SdlProjector>(screen_), options_);
  bus_.AddTick([&] { conductor.Tick(); });
  auto calibrations = bus_.Record<calibration_t>(channel::kCalibration);
  auto shown = bus_.Record<pattern_shown_t>(channel::kPatternShown);
  Request(80);
  ASSERT_TRUE(bus_.RunUntil([&] { return shown->size() == 1; }));
  capture_t stray{};
  stray.scan_id = 80;
  stray.session = shown->front().session + 1;
  stray.pattern_index = -1;
  stray.pattern_count = shown->front().pattern_count;
  bus_.probe().Publish(channel::kCapture, &stray);
  calibration_t update{};
  update.source = "recalibrated";
  Calibration moved = QuickRig();
  moved.camera.matrix(0, 0) *= 1.01;
  ToMessage(moved, &update);
  bus_.probe().Publish(channel::kCalibration, &update);
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("calibrations taken") == 1; }));
  EXPECT_EQ(shown->size(), 1u) << "a capture of another session advanced the scan";
  size_t answered = 0;
  bus_.AddTick([&] { AnswerEveryPattern(shown, &answered); });
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("scans captured") == 1; }));
  Request(81);
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("scans captured") == 2; }));
  std::vector<std::string> sources;
  for (const calibration_t& c : *calibrations) {
    if (c.scan_id != 0) sources.push_back(c.source);
  }
  EXPECT_EQ(sources, (std::vector<std::string>{"small rig", "recalibrated"}));
}

// After its patterns the scan takes a frame under each extra light: LIGHT_REQUEST(k),
// and on LIGHT_ON(k) (this scan's session, the light's name) PATTERN_SHOWN(pattern_count + k)
// naming the light, the projector black; LIGHT_REQUEST(-1) at the end. A LIGHT_ON that does not
// come fails the scan with a message naming the light, and turns the lights off.
TEST_F(ProjectorNodeTest, EachExtraLightIsAskedForAndCapturedAfterThePatterns) {
  for (const char* name : {"raking-000", "uv"}) {
    ScanLight light;
    light.name = name;
    if (name[0] == 'r') light.direction = cv::Vec3d(0.8, 0, 0.6);
    options_.lights.push_back(light);
  }
  Node node("vellum-projector", &bus_.lcm(), &bus_.clock());
  auto projector = std::make_unique<WatchedProjector>(screen_);
  WatchedProjector* screen = projector.get();
  ProjectorNode conductor(&node, std::move(projector), options_);
  bus_.AddTick([&] { conductor.Tick(); });
  bus_.Watch("vellum-projector");
  auto started = bus_.Record<scan_started_t>(channel::kScanStarted);
  auto shown = bus_.Record<pattern_shown_t>(channel::kPatternShown);
  auto requests = bus_.Record<light_t>(channel::kLightRequest);
  size_t answered = 0, lit = 0;
  bool answer_lights = true;
  bus_.AddTick([&] { AnswerEveryPattern(shown, &answered); });
  bus_.AddTick([&] {
    while (answer_lights && lit < requests->size()) {
      light_t on = (*requests)[lit++];
      if (on.index < 0) continue;
      on.source = "test";
      bus_.probe().Publish(channel::kLightOn, &on);
    }
  });
  Request(90);
  const int patterns = static_cast<int>(MakePatternSequence(options_.patterns).patterns.size());
  const size_t total = patterns + 1 + 2;
  ASSERT_TRUE(bus_.RunUntil(
      [&] { return shown->size() == total && conductor.scan_id() == 0 && requests->size() == 3; }));
  ASSERT_EQ(started->size(), 1u);
  ASSERT_EQ(started->front().light_count, 2);
  EXPECT_EQ(started->front().lights[1].name, "uv");
  EXPECT_TRUE(started->front().lights[0].directed);
  for (int k = 0; k < 2; ++k) {
    const pattern_shown_t& m = (*shown)[patterns + 1 + k];
    EXPECT_EQ(m.pattern_index, patterns + k);
    EXPECT_EQ(m.light_count, 2);
    EXPECT_EQ(m.light.name, options_.lights[k].name);
    EXPECT_EQ(m.pattern.kind, int8_t{pattern_spec_t::KIND_BLACK});
  }
  for (int k = 0; k <= patterns; ++k) EXPECT_EQ((*shown)[k].light.name, "") << k;
  // Black on screen under the lights.
  for (size_t k = screen->shown.size() - 3; k < screen->shown.size(); ++k) {
    EXPECT_EQ(cv::countNonZero(screen->shown[k]), 0) << k;
  }
  ASSERT_EQ(requests->size(), 3u);
  EXPECT_EQ((*requests)[0].index, 0);
  EXPECT_EQ((*requests)[0].session, started->front().session);
  EXPECT_EQ((*requests)[1].light.name, "uv");
  EXPECT_EQ((*requests)[2].index, -1) << "the lights off at the end";
  EXPECT_EQ(node.Counter("scans captured"), 1);
  // No LIGHT_ON: the scan fails naming the light, and the lights are turned off.
  answer_lights = false;
  Request(91);
  // An operator may take a while to switch a light: the scan waits the light timeout (120 s).
  ASSERT_TRUE(bus_.RunUntil([&] { return requests->back().scan_id == 91; }));
  bus_.StepFor(119);
  EXPECT_EQ(node.Counter("scans failed"), 0) << bus_.Status("vellum-projector").last_error;
  EXPECT_TRUE(bus_.StepUntil(
      [&] {
        return bus_.Status("vellum-projector")
                   .last_error.find(
                       "scan 91 failed: no LIGHT_ON for the light 'raking-000' within "
                       "120.0 s") != std::string::npos;
      },
      0.5, 2))
      << bus_.Status("vellum-projector").last_error;
  EXPECT_TRUE(bus_.RunUntil([&] { return requests->back().index == -1; }));
  EXPECT_EQ(requests->back().scan_id, 91);
  EXPECT_EQ(node.Counter("scans failed"), 1);
}

TEST(ProjectorNodeOptions, NonsenseIsRefusedByName) {
  ProjectorNodeOptions o;
  std::string why;
  EXPECT_TRUE(o.Check(&why)) << why;
  o.capture_timeout = std::chrono::duration<double>(0);
  EXPECT_FALSE(o.Check(&why));
  EXPECT_NE(why.find("capture_timeout"), std::string::npos) << why;
  SdlProjectorOptions screen;
  EXPECT_TRUE(screen.Check(&why)) << why;
  screen.size = {0, 768};
  EXPECT_FALSE(screen.Check(&why));
  EXPECT_THROW(RequireValid(screen), UsageError);
}

}  // namespace
}  // namespace vellum::station
