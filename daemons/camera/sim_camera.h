// The virtual gantry as a camera: renders what the camera would see of a known warped page
// under the pattern shown, with the light model's noise (core/sim), and under a scan's extra
// lights (a light with a direction as a distant lamp from there, one without as the page's UV
// fluorescence). The station's tests, the demo's recording and a station without hardware run
// on it.
#pragma once

#include <memory>

#include "core/sim/gantry.h"
#include "daemons/camera/camera.h"

namespace vellum::station {

// The virtual gantry's timing, and its faults: a display that shows a pattern some refreshes
// after it was handed over, a camera whose exposure lasts (and so can straddle the change from
// one pattern to the next), on a frame clock that drops frames. Frames are on a virtual clock:
// the first after a pattern was shown starts just after it (the worst case: an exposure that
// starts as early as it may), each next one a frame period later. All zero: every frame shows
// its own pattern, whenever it is asked for.
struct SimTiming {
  double refresh_hz = 60;         // The projector's refresh rate.
  int display_lag_refreshes = 0;  // The image reaches the page this many refreshes after vsync.
  double frame_ms = 0;            // The camera's frame period (0: a frame whenever asked).
  double exposure_ms = 0;         // How long each frame exposes.
  int drop_every = 0;             // Every Nth frame is lost on its way (0: none).
  bool Check(std::string* why) const;
};

struct SimCameraOptions {
  Calibration rig = DefaultRig();  // The rig it renders (its projector must show the patterns).
  PageOptions page;
  TextureOptions texture;
  LightOptions light;
  SceneOptions scene;
  uint64_t seed = 1;  // Each frame's noise from it and the pattern index: repeatable.
  SimTiming timing;
  bool Check(std::string* why) const;
};

class SimCamera : public Camera {
 public:
  // Renders the idle preview at once: a full-resolution render takes a second or more, which
  // must not wait in the worker's queue when a scan's first pattern comes.
  explicit SimCamera(const SimCameraOptions& options);
  std::string Describe() const override;
  // A request for a projector other than the rig's is refused. With SimTiming's faults, the
  // frame is what the camera would see over its exposure: the pattern before this one where
  // the display has not yet changed, a blend of the two where the change falls within it.
  Status Capture(const FrameRequest& request, cv::Mat* image, int64_t* exposure_utime) override;
  int64_t dropped_frames() const override { return dropped_; }
  int64_t frame_period_us() const override {
    return static_cast<int64_t>(1000 * options_.timing.frame_ms);
  }
  int64_t exposure_us() const override {
    return static_cast<int64_t>(1000 * options_.timing.exposure_ms);
  }
  Status Preview(cv::Mat* image, int64_t* exposure_utime) override;

 private:
  SimCameraOptions options_;
  std::unique_ptr<VirtualGantry> gantry_;
  cv::Mat preview_;  // Read-only after construction.
  // The worker thread's (Capture):
  cv::Mat Render(const FrameRequest& request, uint64_t seed) const;
  // The projector's image before the one asked for (black before the first pattern).
  FrameRequest previous_, current_;
  int64_t last_frame_utime_ = 0;
  int64_t frames_ = 0, dropped_ = 0;
};

}  // namespace vellum::station
