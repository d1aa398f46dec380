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

SdlProjector::SdlProjector(const SdlProjectorOptions& options)
    : window_(ToWindow(options)), flip_(options.flip) {}

}  // namespace vellum::station
