// The camera's node on an in-process bus with the virtual gantry as its camera: a
// PATTERN_SHOWN is answered by a CAPTURE holding exactly the frame the gantry renders (patterns
// in gray, exposed after the pattern was shown) and a small copy on PREVIEW; a malformed pattern
// and a projector of another size are reported, and the node goes on.
#include "daemons/camera/camera_node.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "daemons/camera/sim_camera.h"
#include "station/daemon.h"
#include "station/messages.h"
#include "station/testing.h"
#include "vellum/capture_t.hpp"

namespace vellum::station {
namespace {

using testing::MemqBus;

class CameraNodeTest : public ::testing::Test {
 protected:
  CameraNodeTest() {
    sim_.rig = QuickRig();
    sim_.seed = 3;
    sequence_ = MakePatternSequence(PatternOptions{sim_.rig.projector.size});
  }
  pattern_shown_t Shown(int64_t scan, int index) {
    pattern_shown_t m{};
    m.scan_id = scan;
    m.pattern_index = index;
    m.pattern_count = static_cast<int32_t>(sequence_.patterns.size());
    m.projector_width = sim_.rig.projector.size.width;
    m.projector_height = sim_.rig.projector.size.height;
    PatternSpec black;
    black.kind = PatternKind::kBlack;
    m.pattern = ToMessage(index < 0 ? black : sequence_.patterns[index]);
    return m;
  }

  SimCameraOptions sim_;
  PatternSequence sequence_;
  MemqBus bus_;
};

TEST_F(CameraNodeTest, AnswersEachPatternShownWithTheFrameTheGantryRenders) {
  Node node("vellum-camera", &bus_.lcm());
  CameraNode camera(&node, std::make_unique<SimCamera>(sim_), CameraNodeOptions());
  auto captures = bus_.Record<capture_t>(channel::kCapture);
  auto previews = bus_.Record<image_t>(channel::kPreview);
  for (int index : {-1, 7}) {
    pattern_shown_t m = Shown(42, index);
    bus_.probe().Publish(channel::kPatternShown, &m);
  }
  ASSERT_TRUE(bus_.RunUntil([&] { return captures->size() == 2 && previews->size() >= 2; }));
  // The same gantry renders the same frames (the seed follows the pattern index).
  SimCamera reference(sim_);
  for (const capture_t& c : *captures) {
    EXPECT_EQ(c.scan_id, 42);
    EXPECT_GT(c.image.utime, c.shown_utime);
    cv::Mat got, expected;
    ASSERT_TRUE(FromMessage(c.image, &got).ok());
    FrameRequest request;
    request.pattern_index = c.pattern_index;
    request.projector = sim_.rig.projector.size;
    ASSERT_TRUE(FromMessage(c.pattern, &request.pattern).ok());
    int64_t exposure = 0;
    ASSERT_TRUE(reference.Capture(request, &expected, &exposure).ok());
    ASSERT_EQ(got.size(), sim_.rig.camera.size);
    if (c.pattern_index >= 0) {
      EXPECT_EQ(got.channels(), 1) << c.pattern_index;
    }
    EXPECT_EQ(cv::norm(got, expected, cv::NORM_INF), 0) << c.pattern_index;
  }
  EXPECT_LE(previews->back().width, 640);
}

// While no scan runs: the live preview, at most 640 wide, and the view's centre at the
// camera's own resolution (the viewer's 100% zoom): the same pixels as the camera's frame.
TEST_F(CameraNodeTest, TheLivePreviewComesWithTheCentreAtFullResolution) {
  Node node("vellum-camera", &bus_.lcm());
  CameraNode camera(&node, std::make_unique<SimCamera>(sim_), CameraNodeOptions());
  bus_.AddTick([&] { camera.Tick(); });
  auto previews = bus_.Record<image_t>(channel::kPreview);
  auto focus = bus_.Record<image_t>(channel::kPreviewFocus);
  ASSERT_TRUE(bus_.RunUntil([&] { return !previews->empty() && !focus->empty(); }));
  cv::Mat crop, frame;
  ASSERT_TRUE(FromMessage(focus->back(), &crop).ok());
  SimCamera reference(sim_);
  int64_t exposure = 0;
  ASSERT_TRUE(reference.Preview(&frame, &exposure).ok());
  const cv::Size size(std::min(320, frame.cols), std::min(240, frame.rows));
  ASSERT_EQ(crop.size(), size);
  const cv::Rect centre((frame.cols - size.width) / 2, (frame.rows - size.height) / 2, size.width,
                        size.height);
  EXPECT_EQ(cv::norm(crop, frame(centre), cv::NORM_INF), 0);
}

TEST_F(CameraNodeTest, BadPatternsAreReportedAndTheNodeGoesOn) {
  Node node("vellum-camera", &bus_.lcm());
  CameraNode camera(&node, std::make_unique<SimCamera>(sim_), CameraNodeOptions());
  bus_.Watch("vellum-camera");
  auto captures = bus_.Record<capture_t>(channel::kCapture);
  pattern_shown_t unknown = Shown(43, 3);
  unknown.pattern.kind = 17;
  bus_.probe().Publish(channel::kPatternShown, &unknown);
  EXPECT_TRUE(bus_.WaitForError("vellum-camera", "pattern kind 17 is not known"))
      << bus_.Status("vellum-camera").last_error;
  pattern_shown_t other = Shown(43, 4);
  other.projector_width = 1024;
  other.projector_height = 768;
  bus_.probe().Publish(channel::kPatternShown, &other);
  EXPECT_TRUE(bus_.WaitForError("vellum-camera", "the projector shows 1024x768 images"))
      << bus_.Status("vellum-camera").last_error;
  pattern_shown_t beyond = Shown(43, 0);
  beyond.pattern_index = beyond.pattern_count;
  bus_.probe().Publish(channel::kPatternShown, &beyond);
  EXPECT_TRUE(bus_.WaitForError("vellum-camera", "pattern_index outside"))
      << bus_.Status("vellum-camera").last_error;
  EXPECT_TRUE(captures->empty());
  pattern_shown_t good = Shown(44, 0);
  bus_.probe().Publish(channel::kPatternShown, &good);
  EXPECT_TRUE(bus_.RunUntil([&] { return captures->size() == 1; }));
}

// What the daemon's flags or config may leave nonsensical is refused by name (the daemon exits 2
// with it, by RequireValid), not run.
// The virtual gantry's display shows each pattern two refreshes (33.3 ms at 60 Hz) after
// vsync, and its camera exposes 10 ms per frame, 30 frames a second. Each PATTERN_SHOWN comes
// `wait_ms` after the handover, as a projector waiting that long would send it.
class DisplayLag : public CameraNodeTest {
 protected:
  DisplayLag() {
    sim_.timing.display_lag_refreshes = 2;
    sim_.timing.frame_ms = 1000.0 / 30;
    sim_.timing.exposure_ms = 10;
  }
  void Show(int64_t scan, int index, double wait_ms) {
    pattern_shown_t m = Shown(scan, index);
    m.handed_utime = handed_;
    m.utime = handed_ + static_cast<int64_t>(1000 * wait_ms);
    handed_ += 200000;  // The next pattern 200 ms later.
    bus_.probe().Publish(channel::kPatternShown, &m);
  }
  // The frame the fault-free gantry gives for a capture.
  cv::Mat FaultFree(const capture_t& c) {
    SimCameraOptions plain = sim_;
    plain.timing = SimTiming();
    SimCamera reference(plain);
    FrameRequest request;
    request.pattern_index = c.pattern_index;
    request.projector = sim_.rig.projector.size;
    EXPECT_TRUE(FromMessage(c.pattern, &request.pattern).ok());
    cv::Mat frame;
    int64_t exposure = 0;
    EXPECT_TRUE(reference.Capture(request, &frame, &exposure).ok());
    if (c.pattern_index >= 0 && frame.channels() == 3)
      cv::cvtColor(frame, frame, cv::COLOR_BGR2GRAY);
    return frame;
  }
  int64_t handed_ = NowUtime();
};

// The projector waits 30 ms, short of the lag: every first frame straddles the change (two
// thirds this pattern, a third the one before). White and black are each taken again from the
// camera's next frame, named, and sent as the fault-free gantry gives them; the first Gray-code
// pattern, which has no check of its own, goes out mixed, and its inverse finds it: the scan
// fails naming it. Nothing mixed is decoded.
TEST_F(DisplayLag, AFrameThatMixesTwoPatternsIsNamedAndNeverSent) {
  Node node("vellum-camera", &bus_.lcm());
  CameraNode camera(&node, std::make_unique<SimCamera>(sim_), CameraNodeOptions());
  bus_.Watch("vellum-camera");
  auto captures = bus_.Record<capture_t>(channel::kCapture);
  for (int index : {-1, 0, 1, 2, 3}) Show(71, index, 30);
  ASSERT_TRUE(bus_.WaitForError("vellum-camera", "pattern 2 (") && bus_.RunUntil([&] {
    return captures->size() == 4;
  })) << bus_.Status("vellum-camera").last_error;
  const std::string error = bus_.Status("vellum-camera").last_error;
  EXPECT_NE(error.find("scan 71, pattern 3: pattern 2 (gray column bit 0) was taken mixing two "
                       "patterns"),
            std::string::npos)
      << error;
  EXPECT_NE(error.find("vellum calibrate latency"), std::string::npos) << error;
  for (int k = 0; k < 3; ++k) {  // The texture, white and black.
    cv::Mat got;
    ASSERT_TRUE(FromMessage((*captures)[k].image, &got).ok());
    EXPECT_EQ(cv::norm(got, FaultFree((*captures)[k]), cv::NORM_INF), 0) << k - 1;
  }
  // White, black, and the inverse three times (the last time steady, still not adding up).
  EXPECT_EQ(node.Counter("frames mixing two patterns"), 4);
}

// The projector waits the measured lag (34 ms): every frame is the fault-free one, even on a
// camera that loses every third frame.
TEST_F(DisplayLag, WithTheLagWaitedForEveryFrameIsTheFaultFreeOne) {
  sim_.timing.drop_every = 3;
  Node node("vellum-camera", &bus_.lcm());
  CameraNode camera(&node, std::make_unique<SimCamera>(sim_), CameraNodeOptions());
  auto captures = bus_.Record<capture_t>(channel::kCapture);
  for (int index : {-1, 0, 1, 2, 3, 4, 5}) Show(72, index, 34);
  ASSERT_TRUE(bus_.RunUntil([&] { return captures->size() == 7; }));
  for (const capture_t& c : *captures) {
    cv::Mat got;
    ASSERT_TRUE(FromMessage(c.image, &got).ok());
    EXPECT_EQ(cv::norm(got, FaultFree(c), cv::NORM_INF), 0) << c.pattern_index;
    EXPECT_GT(c.image.utime, c.shown_utime);
  }
  EXPECT_EQ(node.Counter("frames mixing two patterns"), 0);
  EXPECT_GE(node.Counter("frames the camera dropped"), 2);
}

TEST(CameraNodeOptions, NonsenseIsRefusedByName) {
  CameraNodeOptions o;
  std::string why;
  EXPECT_TRUE(o.Check(&why)) << why;
  o.preview_hz = 0;
  EXPECT_FALSE(o.Check(&why));
  EXPECT_NE(why.find("preview_hz"), std::string::npos) << why;
  EXPECT_THROW(RequireValid(o), UsageError);
  SimCameraOptions sim;
  EXPECT_TRUE(sim.Check(&why)) << why;
  sim.light.noise_dn = -1;
  EXPECT_FALSE(sim.Check(&why));
  EXPECT_NE(why.find("noise_dn"), std::string::npos) << why;
}

}  // namespace
}  // namespace vellum::station
