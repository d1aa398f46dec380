#include "daemons/projector/sdl_projector.h"

namespace vellum::station {
namespace {

display::WindowOptions ToWindow(const SdlProjectorOptions& o) {
  display::WindowOptions w;
  w.title = "vellum-projector";
  w.size = o.size;
  w.display = o.display;
  w.fullscreen = o.fullscreen;
  w.vsync = true;
  return w;
}

}  // namespace

bool SdlProjectorOptions::Check(std::string* why) const {
  if (size.width < 1 || size.height < 1 || display < 0) {
    *why = "projector screen: its size must be at least 1 x 1 and its display >= 0";
    return false;
  }
  return true;
}

SdlProjector::SdlProjector(const SdlProjectorOptions& options)
    : window_(ToWindow(options)), flip_(options.flip) {}

}  // namespace vellum::station
