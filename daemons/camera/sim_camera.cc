#include "daemons/camera/sim_camera.h"

#include <algorithm>

#include "core/common/text.h"
#include "station/node.h"

namespace vellum::station {

bool SimCameraOptions::Check(std::string* why) const {
  return rig.Check(why) && page.Check(why) && texture.Check(why) && light.Check(why) &&
         scene.Check(why);
}

SimCamera::SimCamera(const SimCameraOptions& options)
    : options_(options),
      gantry_(std::make_unique<VirtualGantry>(options.rig, options.page, options.texture,
                                              options.light, options.scene)) {
  preview_ = gantry_->RenderTexture(options.seed);
}

std::string SimCamera::Describe() const {
  return "sim: tracing a " + std::string(ToString(options_.page.shape)) + " page for a " +
         SizeText(options_.rig.camera.size) + " camera";
}

Status SimCamera::Capture(const FrameRequest& request, cv::Mat* image, int64_t* exposure_utime) {
  if (request.projector != gantry_->rig().projector.size) {
    return Status::Error("the projector shows " + SizeText(request.projector) +
                         " images but the sim rig's projector is " +
                         SizeText(gantry_->rig().projector.size));
  }
  *exposure_utime = std::max(NowUtime(), request.shown_utime + 1);
  const uint64_t seed =
      options_.seed * 1000003ULL + static_cast<uint64_t>(request.pattern_index + 1);
  if (!request.light.name.empty()) {
    // A light of known direction is a distant lamp from there; one without, a flood lamp the
    // page fluoresces under (UV).
    SceneLight light = UvLight();
    if (request.light.directed()) {
      light = SceneLight();
      light.direction = request.light.direction;
    }
    light.name = request.light.name;
    *image = gantry_->RenderLight(light, seed);
    return Status::Ok();
  }
  *image = request.pattern_index < 0
               ? gantry_->RenderTexture(seed)
               : gantry_->RenderFrame(RenderPattern(request.pattern, request.projector), seed);
  return Status::Ok();
}

Status SimCamera::Preview(cv::Mat* image, int64_t* exposure_utime) {
  *image = preview_;
  *exposure_utime = NowUtime();
  return Status::Ok();
}

}  // namespace vellum::station
