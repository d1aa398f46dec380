// vellum-camera: captures a frame for each PATTERN_SHOWN (daemons/camera/camera_node.h), from
// a V4L2 camera (v4l2_camera.h) or the virtual gantry (sim_camera.h).
#include <memory>

#include "daemons/camera/camera_node.h"
#include "daemons/camera/sim_camera.h"
#include "daemons/camera/v4l2_camera.h"
#include "flags/options.h"
#include "io/calibration_io.h"
#include "station/daemon.h"

int main(int argc, char** argv) {
  using namespace vellum;
  using namespace vellum::station;
  const std::vector<Flags::Spec> own = {
      {"backend", "NAME", "v4l2 (a real camera) or sim (the virtual gantry)", "sim"},
      {"device", "PATH", "v4l2: the camera device", "/dev/video0"},
      {"size", "WxH", "v4l2: frame size", "1600x1200"},
      {"format", "FOURCC",
       "v4l2: auto (the camera's best: colour where it has it, the most bits, uncompressed), "
       "GREY (gray first) or a FourCC to insist on (Y16, YUYV, RGGB, MJPG, ...)",
       "auto"},
      {"exposure", "N", "v4l2: manual exposure, 100 us units; -1 = camera's setting", "-1"},
      {"gain", "N", "v4l2: gain; -1 = camera's setting", "-1"},
      {"rig", "FILE", "sim: the rig's calibration (default: the built-in default rig)", ""},
      {"preview-hz", "HZ", "live preview rate on PREVIEW while idle", "2"},
      {"sim-refresh-hz", "HZ", "sim: the projector's refresh rate", "60"},
      {"sim-display-lag", "REFRESHES",
       "sim: the display shows an image this many refreshes after vsync (a fault, for testing "
       "the handshake)",
       "0"},
      {"sim-frame-ms", "MS", "sim: the camera's frame period (0: a frame whenever asked)", "0"},
      {"sim-exposure-ms", "MS", "sim: each frame's exposure (0: instantaneous)", "0"},
      {"sim-drop-every", "N", "sim: every Nth frame is lost (0: none; a fault)", "0"},
  };
  return DaemonMain(argc, argv, "vellum-camera",
                    "Captures a frame for each PATTERN_SHOWN (the first whose exposure starts\n"
                    "after it) and publishes CAPTURE: the texture in colour, patterns in gray.",
                    Join(Join(DaemonFlagSpecs(false), own), SimFlagSpecs("sim: ")),
                    [](const Flags& flags, Node& node) {
                      CameraNodeOptions options;
                      options.preview_hz = flags.GetDouble("preview-hz", 0.1, 30);
                      std::unique_ptr<Camera> camera;
                      const std::string backend = flags.Get("backend");
                      if (backend == "sim") {
                        SimCameraOptions sim;
                        if (!flags.Get("rig").empty()) {
                          const Status s = ReadCalibration(flags.Get("rig"), &sim.rig);
                          if (!s.ok()) throw UsageError(s.message());
                        }
                        const Status s = SimOptionsFromFlags(flags, &sim.page, &sim.texture,
                                                             &sim.light, &sim.scene, &sim.seed);
                        if (!s.ok()) throw UsageError("--texture " + s.message());
                        sim.timing.refresh_hz = flags.GetDouble("sim-refresh-hz", 1, 1000);
                        sim.timing.display_lag_refreshes = flags.GetInt("sim-display-lag", 0, 10);
                        sim.timing.frame_ms = flags.GetDouble("sim-frame-ms", 0, 10000);
                        sim.timing.exposure_ms = flags.GetDouble("sim-exposure-ms", 0, 10000);
                        sim.timing.drop_every = flags.GetInt("sim-drop-every", 0, 1000000);
                        RequireValid(sim);
                        camera = std::make_unique<SimCamera>(sim);
                      } else if (backend == "v4l2") {
                        V4l2Options v4l2;
                        v4l2.device = flags.Get("device");
                        v4l2.size = flags.GetSize("size");
                        v4l2.format = flags.Get("format");
                        v4l2.exposure = flags.GetInt("exposure", -1, 1 << 24);
                        v4l2.gain = flags.GetInt("gain", -1, 1 << 16);
                        auto v4l2_camera = std::make_unique<V4l2Camera>();
                        const Status s = v4l2_camera->Open(v4l2);
                        if (!s.ok()) throw std::runtime_error(s.message());
                        camera = std::move(v4l2_camera);
                      } else {
                        throw UsageError("--backend must be sim or v4l2, got '" + backend + "'");
                      }
                      RequireValid(options);
                      CameraNode capture(&node, std::move(camera), options);
                      return node.Run([&] { capture.Tick(); });
                    });
}
