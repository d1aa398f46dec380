// vellum-lights: switches the station's extra lights for each scan (daemons/lights/lights_node.h)
// through a serial relay board (relay_lights.h), the virtual gantry (sim) or the operator's hands
// (manual, prompted in the viewer).
#include <memory>
#include <stdexcept>

#include "daemons/lights/lights_node.h"
#include "daemons/lights/relay_lights.h"
#include "flags/options.h"
#include "station/daemon.h"

int main(int argc, char** argv) {
  using namespace vellum;
  using namespace vellum::station;
  const std::vector<Flags::Spec> own = {
      {"lights", "FILE",
       "the station's lights file (YAML: lights: [{name, direction, channel}], studio_channel); "
       "vellum-projector reads the same file",
       ""},
      {"backend", "NAME", "relay (a serial relay board), manual (the operator) or sim", "sim"},
      {"device", "PATH", "relay: the board's serial device", "/dev/ttyUSB0"},
      {"settle-ms", "MS", "wait after switching a light on, before LIGHT_ON", "200"},
      {"max-on", "S", "switch a light off when no capture of it came within this", "60"},
  };
  return DaemonMain(
      argc, argv, "vellum-lights",
      "Switches the station's extra lights (raking, UV, infrared) one at a time for each scan:\n"
      "on LIGHT_REQUEST from vellum-projector it turns that light on and the others off, and\n"
      "answers LIGHT_ON; with --backend manual it asks the operator (LIGHT_PROMPT, shown in the\n"
      "viewer, which answers). A light goes off when its CAPTURE comes, or after --max-on.",
      Join(DaemonFlagSpecs(false), own), [](const Flags& flags, Node& node) {
        LightsNodeOptions options;
        const std::string path = flags.Get("lights");
        if (path.empty()) throw UsageError("--lights FILE is required (the station's lights)");
        Status s = ReadLightsFile(path, &options.lights);
        if (!s.ok()) throw UsageError(s.message());
        options.settle = std::chrono::milliseconds(flags.GetInt("settle-ms", 0, 60000));
        options.max_on = std::chrono::duration<double>(flags.GetDouble("max-on", 1, 3600));
        const std::string backend = flags.Get("backend");
        std::unique_ptr<Lights> lights;
        if (backend == "relay") {
          for (size_t k = 0; k < options.lights.lights.size(); ++k) {
            if (options.lights.channels[k] < 0) {
              throw UsageError(path + ": the light '" + options.lights.lights[k].name +
                               "' has no channel, which the relay backend needs");
            }
          }
          auto relay =
              std::make_unique<RelayLights>(options.lights.channels, options.lights.studio_channel);
          s = relay->Open(flags.Get("device"));
          if (!s.ok()) throw std::runtime_error(s.message());
          lights = std::move(relay);
        } else if (backend == "manual") {
          lights = std::make_unique<ManualLights>();
        } else if (backend == "sim") {
          lights = std::make_unique<SimLights>();
        } else {
          throw UsageError("--backend must be relay, manual or sim, got '" + backend + "'");
        }
        RequireValid(options);
        LightsNode switcher(&node, std::move(lights), options);
        return node.Run([&] { switcher.Tick(); });
      });
}
