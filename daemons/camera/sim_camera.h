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

struct SimCameraOptions {
  Calibration rig = DefaultRig();  // The rig it renders (its projector must show the patterns).
  PageOptions page;
  TextureOptions texture;
  LightOptions light;
  SceneOptions scene;
  uint64_t seed = 1;  // Each frame's noise from it and the pattern index: repeatable.
  bool Check(std::string* why) const;
};

class SimCamera : public Camera {
 public:
  // Renders the idle preview at once: a full-resolution render takes a second or more, which
  // must not wait in the worker's queue when a scan's first pattern comes.
  explicit SimCamera(const SimCameraOptions& options);
  std::string Describe() const override;
  // A request for a projector other than the rig's is refused.
  Status Capture(const FrameRequest& request, cv::Mat* image, int64_t* exposure_utime) override;
  Status Preview(cv::Mat* image, int64_t* exposure_utime) override;

 private:
  SimCameraOptions options_;
  std::unique_ptr<VirtualGantry> gantry_;
  cv::Mat preview_;  // Read-only after construction.
};

}  // namespace vellum::station
