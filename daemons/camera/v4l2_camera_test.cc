// The V4L2 camera against three recorded cameras (tests/data/v4l2/, recorded_device.h): a UVC
// webcam with YUYV and MJPEG only, an industrial monochrome camera with GREY, Y10, Y12 and Y16,
// and a Bayer RGGB sensor with 8, 10 and 12 bits. For each: the format taken, the frame turned
// into the picture the camera saw (the right way round, with its depth), the automatic controls
// switched off and read back, and what it refuses. Then faults as a driver gives them: dropped and
// flagged frames never taken, a camera unplugged mid-scan failing that scan clearly and coming
// back, in the camera and in vellum-camera's node on an in-process bus.
#include "daemons/camera/v4l2_camera.h"

#include <gtest/gtest.h>
#include <linux/videodev2.h>

#include <ctime>
#include <opencv2/imgproc.hpp>
#include <thread>

#include "core/common/depth.h"
#include "daemons/camera/camera_node.h"
#include "daemons/camera/recorded_device.h"
#include "daemons/camera/v4l2_formats.h"
#include "station/messages.h"
#include "station/testing.h"
#include "vellum/capture_t.hpp"

namespace vellum::station {
namespace {

RecordedCamera Recorded(const std::string& name) {
  RecordedCamera camera;
  const Status s = ReadRecordedCamera(
      std::string(VELLUM_SOURCE_DIR) + "/tests/data/v4l2/" + name + ".json", &camera);
  EXPECT_TRUE(s.ok()) << s.message();
  return camera;
}

// What the cameras see: a 16-bit scene that is not symmetric either way, so that a mirrored or
// upside-down frame, or red and blue swapped, cannot pass. A smooth ramp left to right (more
// than 256 levels: a deeper format keeps them), a red block at the top left and a blue block at
// the bottom right.
cv::Mat Scene() {
  cv::Mat scene(480, 640, CV_16UC3);
  for (int y = 0; y < scene.rows; ++y) {
    for (int x = 0; x < scene.cols; ++x) {
      const auto v = static_cast<uint16_t>(8000 + 40000.0 * x / (scene.cols - 1));
      scene.at<cv::Vec3w>(y, x) = cv::Vec3w(v, v, v);
    }
  }
  scene(cv::Rect(40, 40, 160, 120)).setTo(cv::Scalar(4000, 4000, 60000));
  scene(cv::Rect(440, 320, 160, 120)).setTo(cv::Scalar(60000, 4000, 4000));
  return scene;
}

// The scene at the frame's size, in the frame's depth and channels.
cv::Mat Expected(const cv::Mat& frame) {
  cv::Mat scene;
  cv::resize(Scene(), scene, frame.size(), 0, 0, cv::INTER_AREA);
  if (frame.channels() == 1) cv::cvtColor(scene, scene, cv::COLOR_BGR2GRAY);
  if (frame.depth() == CV_8U) scene = EightBit(scene);
  return scene;
}

int64_t ClockUs(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1000000 + ts.tv_nsec / 1000;
}

int64_t NowUs() { return ClockUs(CLOCK_REALTIME); }
int64_t RealtimeMinusMonotonicUs() { return ClockUs(CLOCK_REALTIME) - ClockUs(CLOCK_MONOTONIC); }

struct Opened {
  RecordedDevice* device = nullptr;  // Owned by the camera.
  std::unique_ptr<V4l2Camera> camera;
  Status status = Status::Ok();
};

Opened Open(const std::string& name, V4l2Options options,
            const std::function<void(RecordedCamera*)>& edit = nullptr) {
  RecordedCamera recorded = Recorded(name);
  if (edit) edit(&recorded);
  auto device = std::make_unique<RecordedDevice>(recorded, Scene());
  Opened o;
  o.device = device.get();
  o.camera = std::make_unique<V4l2Camera>(std::move(device));
  o.status = o.camera->Open(options);
  return o;
}

V4l2Options At(cv::Size size, const std::string& format = "auto") {
  V4l2Options o;
  o.device = "/dev/video4";
  o.size = size;
  o.format = format;
  return o;
}

FrameRequest Now() {
  FrameRequest request;
  request.shown_utime = NowUs();
  request.pattern_index = 0;
  return request;
}

struct Kind {
  const char* camera;
  cv::Size size;
  const char* format;  // What "auto" must take.
  int type;            // The frame it gives.
  // Mean absolute difference from the scene, in the frame's own levels. Y16 is exact. YUYV
  // rounds to 8 bits and halves the chroma, which blurs only the blocks' edges (0.19 measured:
  // bar 1). RG12 keeps 12 of 16 bits (steps of 16) and bilinear demosaicing smears the blocks'
  // edges over a pixel (17 measured: bar 100, a sixth of an 8-bit level).
  double mean_error;
};

class EachCamera : public ::testing::TestWithParam<Kind> {};

TEST_P(EachCamera, TakesTheFormatThatKeepsMostAndGivesTheSceneTheRightWayRound) {
  const Kind& kind = GetParam();
  Opened o = Open(kind.camera, At(kind.size));
  ASSERT_TRUE(o.status.ok()) << o.status.message();
  EXPECT_EQ(FourccText(o.camera->format()), FourccText(FourccFromText(kind.format)));
  EXPECT_NE(o.camera->Describe().find(std::string(kind.format)), std::string::npos)
      << o.camera->Describe();
  cv::Mat frame;
  int64_t exposure = 0;
  const FrameRequest request = Now();
  ASSERT_TRUE(o.camera->Capture(request, &frame, &exposure).ok());
  EXPECT_GE(exposure, request.shown_utime);
  ASSERT_EQ(frame.type(), kind.type);
  ASSERT_EQ(frame.size(), kind.size);
  const cv::Mat expected = Expected(frame);
  cv::Mat diff;
  cv::absdiff(frame, expected, diff);
  const double error = cv::mean(diff)[0];
  std::printf("[v4l2] %s: %s, mean difference from the scene %.2f of its levels\n", kind.camera,
              kind.format, error);
  EXPECT_LE(error, kind.mean_error) << kind.camera;
  // The blocks where the scene has them: red at the top left, blue at the bottom right.
  const auto at = [&](double fx, double fy) {
    cv::Mat px =
        frame(cv::Rect(static_cast<int>(fx * frame.cols), static_cast<int>(fy * frame.rows), 1, 1));
    return cv::mean(px);
  };
  const cv::Scalar top_left = at(0.19, 0.21), bottom_right = at(0.81, 0.79);
  if (frame.channels() == 3) {
    EXPECT_GT(top_left[2], 4 * top_left[0]) << "red block: " << top_left;
    EXPECT_GT(bottom_right[0], 4 * bottom_right[2]) << "blue block: " << bottom_right;
  } else {
    // In gray the red block (luma 20 745) is twice as bright as the blue one (10 383).
    EXPECT_GT(top_left[0], 1.5 * bottom_right[0]);
  }
  if (frame.depth() == CV_16U) {
    // More than 8 bits kept: the ramp's row holds far more than 256 levels.
    cv::Mat row = frame.row(frame.rows / 2).reshape(1).clone();
    std::sort(row.begin<uint16_t>(), row.end<uint16_t>());
    const auto levels =
        std::unique(row.begin<uint16_t>(), row.end<uint16_t>()) - row.begin<uint16_t>();
    EXPECT_GT(levels, 300) << kind.camera;
  }
}

INSTANTIATE_TEST_SUITE_P(
    Recorded, EachCamera,
    ::testing::Values(Kind{"uvc_webcam", {1600, 896}, "YUYV", CV_8UC3, 1.0},
                      Kind{"mono_industrial", {1600, 1200}, "Y16", CV_16UC1, 0.0},
                      Kind{"bayer_rggb", {1640, 1232}, "RG12", CV_16UC3, 100.0}),
    [](const auto& info) { return std::string(info.param.camera); });

TEST(V4l2Camera, AFormatInsistedOnIsTakenAndOneTheCameraLacksIsRefusedWithWhatItOffers) {
  Opened mjpeg = Open("uvc_webcam", At({1920, 1080}, "MJPG"));
  ASSERT_TRUE(mjpeg.status.ok()) << mjpeg.status.message();
  cv::Mat frame;
  int64_t exposure = 0;
  ASSERT_TRUE(mjpeg.camera->Capture(Now(), &frame, &exposure).ok());
  cv::Mat diff;
  cv::absdiff(frame, Expected(frame), diff);
  EXPECT_LE(cv::mean(diff)[0], 3.0);  // JPEG at quality 92: a level or two.
  // A monochrome camera asked for gray at 10 bits: 16-bit words, the low 6 bits empty.
  Opened y10 = Open("mono_industrial", At({2048, 1536}, "Y10"));
  ASSERT_TRUE(y10.status.ok()) << y10.status.message();
  ASSERT_TRUE(y10.camera->Capture(Now(), &frame, &exposure).ok());
  ASSERT_EQ(frame.type(), CV_16UC1);
  cv::Mat low;
  cv::bitwise_and(frame, cv::Scalar(63), low);
  EXPECT_EQ(cv::countNonZero(low), 0);
  cv::absdiff(frame, Expected(frame), diff);
  EXPECT_LE(cv::mean(diff)[0], 64.0);  // At most one 10-bit step.

  Opened lacking = Open("uvc_webcam", At({1600, 896}, "Y16"));
  ASSERT_FALSE(lacking.status.ok());
  EXPECT_NE(lacking.status.message().find("/dev/video4"), std::string::npos);
  EXPECT_NE(lacking.status.message().find("offers YUYV 640x480, 1600x896, 1920x1080; MJPG"),
            std::string::npos)
      << lacking.status.message();
  Opened size = Open("mono_industrial", At({1920, 1080}));
  ASSERT_FALSE(size.status.ok());
  EXPECT_NE(size.status.message().find("at 1920x1080"), std::string::npos) << size.status.message();
  Opened nonsense = Open("mono_industrial", At({1600, 1200}, "H264"));
  ASSERT_FALSE(nonsense.status.ok());
  EXPECT_NE(nonsense.status.message().find("'H264' is not one vellum takes"), std::string::npos)
      << nonsense.status.message();
}

TEST(V4l2Camera, AutomaticExposureAndGainAreSwitchedOffAndReadBack) {
  V4l2Options options = At({1600, 1200});
  options.exposure = 156;
  options.gain = 24;
  Opened o = Open("mono_industrial", options);
  ASSERT_TRUE(o.status.ok()) << o.status.message();
  EXPECT_EQ(o.device->control(V4L2_CID_EXPOSURE_AUTO).value, V4L2_EXPOSURE_MANUAL);
  EXPECT_EQ(o.device->control(V4L2_CID_AUTOGAIN).value, 0);
  EXPECT_EQ(o.device->control(V4L2_CID_EXPOSURE_ABSOLUTE).value, 156);
  EXPECT_EQ(o.device->control(V4L2_CID_GAIN).value, 24);
  EXPECT_NE(o.camera->Describe().find("exposure 156, gain 24"), std::string::npos)
      << o.camera->Describe();
  // The Bayer bridge has no automatics: exposure in lines and analogue gain instead.
  options.size = {1640, 1232};
  options.exposure = 1200;
  options.gain = 16;
  Opened bayer = Open("bayer_rggb", options);
  ASSERT_TRUE(bayer.status.ok()) << bayer.status.message();
  EXPECT_EQ(bayer.device->control(V4L2_CID_EXPOSURE).value, 1200);
  EXPECT_EQ(bayer.device->control(V4L2_CID_ANALOGUE_GAIN).value, 16);
  // Left as it is (-1), the camera's own exposure is kept, still with the automatics off.
  Opened kept = Open("uvc_webcam", At({1600, 896}));
  ASSERT_TRUE(kept.status.ok());
  EXPECT_EQ(kept.device->control(V4L2_CID_EXPOSURE_AUTO).value, V4L2_EXPOSURE_MANUAL);
  EXPECT_NE(kept.camera->Describe().find("exposure 250"), std::string::npos)
      << kept.camera->Describe();
}

// Firmware that answers "done" and keeps automatic exposure, and one that fails the request:
// the camera opens for focusing, but every scan is refused, saying why.
TEST(V4l2Camera, ACameraThatKeepsItsAutomaticExposureOrGainRefusesEveryScan) {
  for (const char* on_set : {"keeps", "refuses"}) {
    for (uint32_t control : {static_cast<uint32_t>(V4L2_CID_EXPOSURE_AUTO),
                             static_cast<uint32_t>(V4L2_CID_AUTOGAIN)}) {
      Opened o = Open("mono_industrial", At({1600, 1200}),
                      [&](RecordedCamera* c) { c->controls.at(control).on_set = on_set; });
      const std::string what = control == V4L2_CID_AUTOGAIN ? "gain" : "exposure";
      ASSERT_TRUE(o.status.ok()) << o.status.message();
      EXPECT_NE(o.camera->Describe().find("REFUSES SCANS: automatic " + what + " stays on"),
                std::string::npos)
          << o.camera->Describe();
      cv::Mat frame;
      int64_t exposure = 0;
      const Status scan = o.camera->Capture(Now(), &frame, &exposure);
      ASSERT_FALSE(scan.ok());
      EXPECT_NE(scan.message().find("camera /dev/video4 refuses to scan: automatic " + what +
                                    " stays on"),
                std::string::npos)
          << scan.message();
      EXPECT_TRUE(o.camera->Preview(&frame, &exposure).ok()) << on_set;
    }
  }
}

// Frames a driver drops never come (a gap in the sequence numbers); a frame it flags as bad
// comes and is not taken. The frame taken is the first good one whose exposure starts after
// the pattern was shown, with stamps at the start of exposure and at the end of the frame.
TEST(V4l2Camera, ADroppedOrFlaggedFrameIsNeverTakenAsACapture) {
  for (const char* name : {"uvc_webcam", "mono_industrial"}) {
    const cv::Size size =
        std::string(name) == "uvc_webcam" ? cv::Size(640, 480) : cv::Size(1600, 1200);
    Opened o = Open(name, At(size));
    ASSERT_TRUE(o.status.ok()) << o.status.message();
    o.device->DropEvery(20);  // Sequence 19, 39, ... never come.
    o.device->FlagError(40);
    const int64_t offset = RealtimeMinusMonotonicUs();
    cv::Mat frame;
    int64_t exposure = 0;
    FrameRequest request;
    request.pattern_index = 3;
    // Shown just before frame 19 starts: 19 was dropped, so frame 20 is the one.
    request.shown_utime = o.device->StartOf(19) + offset - 1000;
    ASSERT_TRUE(o.camera->Capture(request, &frame, &exposure).ok());
    EXPECT_NEAR(static_cast<double>(exposure - offset), static_cast<double>(o.device->StartOf(20)),
                500)
        << name;
    EXPECT_EQ(o.camera->dropped_frames(), 1) << name;
    // Shown just before frame 39 starts: 39 dropped, 40 flagged bad, so 41.
    request.shown_utime = o.device->StartOf(39) + offset - 1000;
    ASSERT_TRUE(o.camera->Capture(request, &frame, &exposure).ok());
    EXPECT_NEAR(static_cast<double>(exposure - offset), static_cast<double>(o.device->StartOf(41)),
                500)
        << name;
    EXPECT_EQ(o.camera->dropped_frames(), 2) << name;
    EXPECT_EQ(o.camera->bad_frames(), 1) << name;
  }
}

TEST(V4l2Camera, UnpluggedMidScanTheFrameFailsClearlyAndTheCameraComesBackWhenPluggedIn) {
  Opened o = Open("uvc_webcam", At({640, 480}));
  ASSERT_TRUE(o.status.ok()) << o.status.message();
  cv::Mat frame;
  int64_t exposure = 0;
  ASSERT_TRUE(o.camera->Capture(Now(), &frame, &exposure).ok());
  o.device->UnplugAfter(0);
  Status s = o.camera->Capture(Now(), &frame, &exposure);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("camera /dev/video4 is gone"), std::string::npos) << s.message();
  s = o.camera->Capture(Now(), &frame, &exposure);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("camera /dev/video4 is not back yet"), std::string::npos)
      << s.message();
  EXPECT_FALSE(o.camera->Preview(&frame, &exposure).ok());
  o.device->Replug();
  // A scan's frame opens it at once; the same format and controls are set again.
  const FrameRequest request = Now();
  s = o.camera->Capture(request, &frame, &exposure);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_GE(exposure, request.shown_utime);
  EXPECT_EQ(frame.size(), cv::Size(640, 480));
  EXPECT_EQ(o.device->opens(), 2);
  EXPECT_EQ(o.device->control(V4L2_CID_EXPOSURE_AUTO).value, V4L2_EXPOSURE_MANUAL);
}

// vellum-camera's node over the recorded webcam on an in-process bus: captures of a scan on a
// camera dropping every other frame (counted), then the camera unplugged: the next scan's frame is
// an error of that scan, naming the camera; once it is back, the scan after that is captured.
TEST(V4l2CameraNode, AScanWhileTheCameraIsGoneFailsClearlyAndTheNextOneIsCaptured) {
  testing::MemqBus bus;
  bus.Watch("vellum-camera");
  Opened o = Open("uvc_webcam", At({640, 480}));
  ASSERT_TRUE(o.status.ok()) << o.status.message();
  RecordedDevice* device = o.device;
  Node node("vellum-camera", &bus.lcm());
  CameraNode camera(&node, std::move(o.camera), CameraNodeOptions());
  auto captures = bus.Record<capture_t>(channel::kCapture);
  device->DropEvery(2);  // A struggling USB bus: every other frame lost.
  device->FlagError(4);
  const PatternSequence sequence = MakePatternSequence(PatternOptions{cv::Size(800, 600)});
  auto shown = [&](int64_t scan, int index) {
    pattern_shown_t m{};
    m.scan_id = scan;
    m.pattern_index = index;
    m.pattern_count = static_cast<int32_t>(sequence.patterns.size());
    m.projector_width = 800;
    m.projector_height = 600;
    PatternSpec black;
    black.kind = PatternKind::kBlack;
    m.pattern = ToMessage(index < 0 ? black : sequence.patterns[index]);
    m.utime = NowUs();
    bus.probe().Publish(channel::kPatternShown, &m);
  };
  shown(60, -1);
  shown(60, 0);
  ASSERT_TRUE(bus.RunUntil([&] { return captures->size() == 2; }));
  cv::Mat texture, pattern;
  ASSERT_TRUE(FromMessage((*captures)[0].image, &texture).ok());
  ASSERT_TRUE(FromMessage((*captures)[1].image, &pattern).ok());
  EXPECT_EQ(texture.type(), CV_8UC3);  // The texture in colour, from YUYV.
  EXPECT_EQ(pattern.type(), CV_8UC1);  // A pattern in gray.
  EXPECT_GE(node.Counter("frames the camera dropped"), 1);
  EXPECT_EQ(node.Counter("frames the camera flagged bad"), 1);
  device->UnplugAfter(0);
  shown(61, 1);
  EXPECT_TRUE(bus.WaitForError("vellum-camera", "scan 61, pattern 1: camera /dev/video4 is gone"))
      << bus.Status("vellum-camera").last_error;
  device->Replug();
  shown(62, 1);
  ASSERT_TRUE(bus.RunUntil([&] { return captures->size() == 3; }));
  EXPECT_EQ(captures->back().scan_id, 62);
}

}  // namespace
}  // namespace vellum::station
