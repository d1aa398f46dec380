// vellum-projector: shows each scan's patterns on the projector and conducts the capture
// (daemons/projector/projector_node.h), through an SDL2 window (sdl_projector.h).
#include <memory>
#include <stdexcept>

#include "core/common/text.h"
#include "daemons/projector/projector_node.h"
#include "daemons/projector/sdl_projector.h"
#include "flags/options.h"
#include "io/calibration_io.h"
#include "io/scan_io.h"
#include "station/daemon.h"

int main(int argc, char** argv) {
  using namespace vellum;
  using namespace vellum::station;
  std::vector<Flags::Spec> specs = DaemonFlagSpecs(false);
  const std::vector<Flags::Spec> own = {
      {"calibration", "FILE",
       "station calibration: sets the projector size, published as CALIBRATION per scan", ""},
      {"projector", "WxH", "projector size when no calibration is given", "1024x768"},
      {"display", "N", "SDL display index of the projector", "0"},
      {"fullscreen", "BOOL", "full-screen window on that display", "true"},
      {"flip", "AXIS", "mirror flip: none, horizontal, vertical or both", "none"},
      {"settle-ms", "MS", "wait after vsync and the display's lag before PATTERN_SHOWN", "30"},
      {"display-lag-ms", "MS",
       "the display's lag from vsync to the image on the page, as measured (0: not measured; "
       "the settle time must then cover it)",
       "0"},
      {"measure-lag", "BOOL",
       "measure the display's lag at start-up (once the camera is heard, about a second) and "
       "wait that instead of display-lag-ms",
       "false"},
      {"lag-flashes", "N", "flashes for the display's lag (white and black in turn)", "12"},
      {"refresh-hz", "HZ", "the display's refresh rate where SDL does not know it (0: ask SDL)",
       "0"},
      {"capture-timeout", "S", "fail the scan when a CAPTURE takes longer", "5"},
      {"lights", "FILE",
       "the station's extra lights (the file vellum-lights reads): each scan takes a frame under "
       "each, after its patterns; empty: none",
       ""},
      {"light-timeout", "S", "fail the scan when a light's LIGHT_ON takes longer", "120"},
  };
  specs = Join(Join(specs, own), PatternFlagSpecs());
  return DaemonMain(
      argc, argv, "vellum-projector",
      "Shows the structured-light patterns full screen, one per CAPTURE, for each SCAN_REQUEST;\n"
      "publishes CALIBRATION at the start of a scan and PATTERN_SHOWN for each pattern; then,\n"
      "with --lights, asks vellum-lights for each extra light (LIGHT_REQUEST) and has the\n"
      "camera take a frame under it. The images are of the virtual (unmirrored) projector;\n"
      "--flip undoes the mirror.",
      specs, [](const Flags& flags, Node& node) {
        ProjectorNodeOptions options;
        cv::Size size = flags.GetSize("projector");
        const std::string path = flags.Get("calibration");
        if (!path.empty()) {
          Calibration c;
          const Status s = ReadCalibration(path, &c);
          if (!s.ok()) throw UsageError(s.message());
          if (flags.Has("projector") && size != c.projector.size) {
            throw UsageError("--projector " + SizeText(size) + " but " + path + " calibrates a " +
                             SizeText(c.projector.size) + " projector");
          }
          size = c.projector.size;
          options.calibration = c;
          options.calibration_source = path;
        }
        options.patterns = PatternOptionsFromFlags(flags, size);
        options.settle = std::chrono::milliseconds(flags.GetInt("settle-ms", 0, 10000));
        options.display_lag = std::chrono::microseconds(
            static_cast<int64_t>(1000 * flags.GetDouble("display-lag-ms", 0, 1000)));
        options.measure_lag = flags.GetBool("measure-lag");
        options.lag_flashes = flags.GetInt("lag-flashes", 2, 100);
        options.refresh_hz = flags.GetDouble("refresh-hz", 0, 1000);
        options.capture_timeout =
            std::chrono::duration<double>(flags.GetDouble("capture-timeout", 0.1, 600));
        if (!flags.Get("lights").empty()) {
          StationLights lights;
          const Status s = ReadLightsFile(flags.Get("lights"), &lights);
          if (!s.ok()) throw UsageError(s.message());
          options.lights = lights.lights;
        }
        options.light_timeout =
            std::chrono::duration<double>(flags.GetDouble("light-timeout", 0.1, 3600));
        SdlProjectorOptions screen;
        screen.size = size;
        screen.display = flags.GetInt("display", 0, 63);
        screen.fullscreen = flags.GetBool("fullscreen");
        if (!display::ParseFlip(flags.Get("flip"), &screen.flip)) {
          throw UsageError("--flip must be none, horizontal, vertical or both, got '" +
                           flags.Get("flip") + "'");
        }
        RequireValid(options);
        RequireValid(screen);
        std::unique_ptr<Projector> projector;
        try {
          projector = std::make_unique<SdlProjector>(screen);
        } catch (const std::invalid_argument& e) {
          throw UsageError(std::string("--display ") + e.what());
        }
        ProjectorNode conductor(&node, std::move(projector), options);
        return node.Run([&] { conductor.Tick(); }, 5);
      });
}
