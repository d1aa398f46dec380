// What the camera daemon needs of a camera: the frame taken under a pattern the projector
// shows, and frames for the live preview. A V4L2 camera (v4l2_camera.h) and the virtual
// gantry (sim_camera.h) implement it; the node sees only this interface.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>

#include "core/common/status.h"
#include "core/patterns/patterns.h"
#include "core/patterns/scan.h"

namespace vellum::station {

// The frame a scan asks for: the first whose exposure starts after the pattern was shown.
struct FrameRequest {
  int64_t shown_utime = 0;  // When the pattern was on screen, microseconds since the epoch.
  // When the projector handed it to its display (vsync passed); 0: not said. The virtual
  // gantry's display lag counts from it.
  int64_t handed_utime = 0;
  int pattern_index = -1;  // -1: the texture (projector black, studio light).
  PatternSpec pattern;     // What the projector shows.
  cv::Size projector;      // The projector's image size.
  // Under an extra light (projector black, the studio light off): its name and
  // direction (no image). Empty name: none.
  ScanLight light;
};

class Camera {
 public:
  virtual ~Camera() = default;
  // One line for the log: what camera this is.
  virtual std::string Describe() const = 0;
  // The frame for `request` (8-bit gray or BGR); sets its exposure start (microseconds since
  // the epoch, after request.shown_utime).
  virtual Status Capture(const FrameRequest& request, cv::Mat* image, int64_t* exposure_utime) = 0;
  // A current frame for the live preview.
  virtual Status Preview(cv::Mat* image, int64_t* exposure_utime) = 0;
  // Frames the camera's driver dropped, and frames it gave that were not taken (flagged bad,
  // short, undecodable), in all.
  virtual int64_t dropped_frames() const { return 0; }
  // Whether its frames are linear in the light (offset plus gain times light): a raw or
  // monochrome sensor's are, a webcam's gamma-encoded YUYV or MJPEG are not. A Gray-code pair
  // is checked to add up (core/decode/frame_check.h) only on a linear camera.
  virtual bool linear() const { return true; }
  // Its frame period and each frame's exposure (microseconds); 0 when not known.
  virtual int64_t frame_period_us() const { return 0; }
  virtual int64_t exposure_us() const { return 0; }
  virtual int64_t bad_frames() const { return 0; }
};

}  // namespace vellum::station
