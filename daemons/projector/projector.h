// What the projector daemon needs of a projector: show a pattern and return once it is on
// screen. The SDL implementation (sdl_projector.h) drives a real projector through a
// full-screen window; the node sees only this interface.
#pragma once

#include <opencv2/core.hpp>

namespace vellum::station {

class Projector {
 public:
  virtual ~Projector() = default;
  // The image size it shows (the virtual, unmirrored projector's).
  virtual cv::Size size() const = 0;
  // Shows an 8-bit gray image of size(); returns once it is on screen (after vsync).
  virtual void Show(const cv::Mat& gray) = 0;
  // Handles its window's events; false once it was closed.
  virtual bool Poll() = 0;
  // Its display's refresh rate (Hz); 0 when not known.
  virtual double refresh_hz() const { return 0; }
};

}  // namespace vellum::station
