// A projector on an SDL2 window: full screen on the projector's display, the mirror's flip
// applied, each pattern shown after vsync.
#pragma once

#include "daemons/projector/projector.h"
#include "display/window.h"

namespace vellum::station {

struct SdlProjectorOptions {
  cv::Size size{1024, 768};  // The projector's native resolution (the calibration's).
  int display = 0;           // SDL display index of the projector.
  bool fullscreen = true;
  display::Flip flip = display::Flip::kNone;  // Undoes the mirror.
  bool Check(std::string* why) const;
};

class SdlProjector : public Projector {
 public:
  // Throws std::runtime_error or std::invalid_argument (see display::Window).
  explicit SdlProjector(const SdlProjectorOptions& options);
  cv::Size size() const override { return window_.size(); }
  void Show(const cv::Mat& gray) override { window_.Show(gray, flip_); }
  bool Poll() override { return window_.Poll(); }
  double refresh_hz() const override { return window_.refresh_hz(); }
  // What the projector shows now (BGR): the last pattern with the flip applied.
  cv::Mat Screen() const { return window_.Screen(); }

 private:
  display::Window window_;
  display::Flip flip_;
};

}  // namespace vellum::station
