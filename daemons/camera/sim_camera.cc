#include "daemons/camera/sim_camera.h"

#include <algorithm>

#include "core/common/text.h"
#include "station/node.h"

namespace vellum::station {

bool SimTiming::Check(std::string* why) const {
  if (!(refresh_hz > 0) || display_lag_refreshes < 0 || display_lag_refreshes > 10 ||
      !(frame_ms >= 0) || !(exposure_ms >= 0) || drop_every < 0 || drop_every == 1 ||
      (frame_ms > 0 && exposure_ms > frame_ms)) {
    *why =
        "sim timing: refresh_hz > 0, display_lag_refreshes 0..10, frame_ms and exposure_ms "
        ">= 0 (the exposure within the frame), drop_every 0 (none) or >= 2";
    return false;
  }
  return true;
}

bool SimCameraOptions::Check(std::string* why) const {
  return rig.Check(why) && page.Check(why) && texture.Check(why) && light.Check(why) &&
         scene.Check(why) && timing.Check(why);
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
  const uint64_t seed =
      options_.seed * 1000003ULL + static_cast<uint64_t>(request.pattern_index + 1);
  const SimTiming& t = options_.timing;
  const bool timed = t.frame_ms > 0 || t.exposure_ms > 0 || t.display_lag_refreshes > 0;
  if (!timed) {
    *exposure_utime = std::max(NowUtime(), request.shown_utime + 1);
    *image = Render(request, seed);
    return Status::Ok();
  }
  const bool again = request.pattern_index == current_.pattern_index && request.pattern_index >= 0;
  if (!again) {
    previous_ = current_;
    if (request.pattern_index <= 0) {  // The texture and white follow the projector's black.
      previous_ = request;
      previous_.pattern_index = 0;
      previous_.pattern = PatternSpec();
      previous_.pattern.kind = PatternKind::kBlack;
    }
    current_ = request;
  }
  // The first frame for a pattern starts just after it was shown (the camera's phase at its
  // worst, whatever real time the rendering took); the next one asked for the same pattern a
  // frame period after the last; a lost frame means the one after it.
  const auto period = static_cast<int64_t>(1000 * t.frame_ms);
  int64_t start = request.shown_utime + 1;
  if (again) start = std::max(start, last_frame_utime_ + period);
  ++frames_;
  if (t.drop_every > 0 && frames_ % t.drop_every == 0) {
    ++dropped_;
    ++frames_;
    start += std::max<int64_t>(period, 1);
  }
  last_frame_utime_ = start;
  *exposure_utime = start;
  // The share of the exposure during which the display showed this pattern.
  const int64_t on = (request.handed_utime > 0 ? request.handed_utime : request.shown_utime) +
                     static_cast<int64_t>(1e6 * t.display_lag_refreshes / t.refresh_hz);
  const double exposure = 1000 * t.exposure_ms;
  const double share = exposure > 0 ? std::clamp((start + exposure - on) / exposure, 0.0, 1.0)
                                    : (start >= on ? 1.0 : 0.0);
  const bool projected = request.pattern_index >= 0 && request.light.name.empty();
  if (!projected || share >= 1) {
    *image = Render(request, seed);
    return Status::Ok();
  }
  const cv::Mat before = Render(previous_, seed);
  if (share <= 0) {
    *image = before;
    return Status::Ok();
  }
  cv::addWeighted(Render(request, seed), share, before, 1 - share, 0, *image);
  return Status::Ok();
}

cv::Mat SimCamera::Render(const FrameRequest& request, uint64_t seed) const {
  if (!request.light.name.empty()) {
    // A light of known direction is a distant lamp from there; one without, a flood lamp the
    // page fluoresces under (UV).
    SceneLight light = UvLight();
    if (request.light.directed()) {
      light = SceneLight();
      light.direction = request.light.direction;
    }
    light.name = request.light.name;
    return gantry_->RenderLight(light, seed);
  }
  return request.pattern_index < 0
             ? gantry_->RenderTexture(seed)
             : gantry_->RenderFrame(RenderPattern(request.pattern, request.projector), seed);
}

Status SimCamera::Preview(cv::Mat* image, int64_t* exposure_utime) {
  *image = preview_;
  *exposure_utime = NowUtime();
  return Status::Ok();
}

}  // namespace vellum::station
