#include <chrono>
#include <cstdio>
#include <filesystem>

#include "cli/commands.h"
#include "core/sim/evaluate.h"
#include "core/sim/gantry.h"
#include "flags/options.h"
#include "io/calibration_io.h"
#include "io/image_file.h"
#include "io/scan_io.h"

namespace vellum {

int RunRender(const std::vector<std::string>& args) {
  std::vector<Flags::Spec> specs = {
      {"out", "DIR", "scan directory to write", ""},
      {"calibration", "FILE", "rig calibration YAML (default: the built-in default rig)", ""},
      {"ambient", "FRACTION", "ambient light", "0.08"},
      {"defocus", "PX", "projector defocus sigma, projector pixels", "0.7"},
      {"projector-falloff", "BOOL",
       "the projector's light falls with the square of the distance and towards its image's "
       "corners, as a real projector's does (off by default: the scans the tests were set on)",
       "false"},
      {"studio-lamps", "X,Y,Z;...",
       "light the texture with these point lamps (world mm, ';' between lamps) instead of evenly",
       ""},
      {"raking", "N",
       "also capture the page under N raking lights evenly around it (light_raking-000.png, ...; "
       "their directions in scan.yaml)",
       "0"},
      {"raking-elevation", "DEG", "the raking lights' elevation above the table", "30"},
      {"uv", "BOOL", "also capture the page's UV fluorescence (light_uv.png)", "false"},
      {"truth", "BOOL", "also write truth_points.tiff and truth_page.tiff", "true"},
  };
  specs = Join(Join(specs, SimFlagSpecs()), PatternFlagSpecs());
  Flags flags("vellum render",
              "Renders a scan of a warped page with the virtual gantry: scan.yaml, texture.png,\n"
              "frame_000.png, ..., the rig's calibration.yaml, and the ground truth of every\n"
              "camera pixel (truth_points.tiff: x y z mm; truth_page.tiff: s t mm and the page:\n"
              "1, on a spread 1 left and 2 right, 0 off it); with --raking or --uv, the page\n"
              "under those lights too (light_<name>.png, named in scan.yaml).",
              specs);
  if (!flags.Parse(args)) return 0;
  const std::string out = flags.Require("out");
  Calibration rig = DefaultRig();
  if (flags.Has("calibration")) {
    const Status s = ReadCalibration(flags.Get("calibration"), &rig);
    if (!s.ok()) {
      std::fprintf(stderr, "vellum render: %s\n", s.message().c_str());
      return 1;
    }
  }
  PageOptions page;
  TextureOptions texture;
  LightOptions light;
  SceneOptions scene;
  uint64_t seed = 1;
  const Status sim = SimOptionsFromFlags(flags, &page, &texture, &light, &scene, &seed);
  if (!sim.ok()) {
    std::fprintf(stderr, "vellum render: %s\n", sim.message().c_str());
    return 1;
  }
  light.ambient = flags.GetDouble("ambient", 0, 1);
  light.defocus_sigma_px = flags.GetDouble("defocus", 0, 20);
  light.projector_falloff = flags.GetBool("projector-falloff");
  light.studio_lamps = ParseLamps("studio-lamps", flags.Get("studio-lamps"));
  const PatternSequence seq =
      MakePatternSequence(PatternOptionsFromFlags(flags, rig.projector.size));

  const auto t0 = std::chrono::steady_clock::now();
  std::fprintf(stderr, "render: tracing a %s page...\n", ToString(page.shape));
  const VirtualGantry gantry(rig, page, texture, light, scene);
  Scan scan;
  scan.sequence = seq;
  scan.camera_size = rig.camera.size;
  scan.texture = gantry.RenderTexture(seed);
  std::vector<SceneLight> lights =
      RakingLights(flags.GetInt("raking", 0, 36), flags.GetDouble("raking-elevation", 1, 89));
  if (flags.GetBool("uv")) lights.push_back(UvLight());
  if (!lights.empty()) std::fprintf(stderr, "render: %zu lights...\n", lights.size());
  scan.lights = RenderLights(gantry, lights, seed);
  std::fprintf(stderr, "render: %zu frames...\n", seq.patterns.size());
  scan.frames = RenderSequence(gantry, seq, seed);
  Status s = WriteScan(out, scan);
  namespace fs = std::filesystem;
  if (s.ok()) s = WriteCalibration((fs::path(out) / "calibration.yaml").string(), rig);
  if (s.ok() && flags.GetBool("truth")) {
    s = WriteImage((fs::path(out) / "truth_points.tiff").string(), gantry.truth().points);
    if (s.ok()) {
      std::vector<cv::Mat> planes;
      cv::split(gantry.truth().page, planes);
      cv::Mat mask;  // 1 on the page (on a spread: 1 left page, 2 right page), 0 off it.
      gantry.truth().page_index.convertTo(mask, CV_32F);
      planes.push_back(mask);
      cv::Mat page_truth;
      cv::merge(planes, page_truth);
      s = WriteImage((fs::path(out) / "truth_page.tiff").string(), page_truth);
    }
  }
  if (!s.ok()) {
    std::fprintf(stderr, "vellum render: %s\n", s.message().c_str());
    return 1;
  }
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("rendered a %s page (%zu frames, %.1f s) to %s\n", ToString(page.shape),
              seq.patterns.size(), secs, out.c_str());
  return 0;
}

}  // namespace vellum
