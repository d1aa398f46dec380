#include <cstdio>

#include "cli/commands.h"
#include "cli/progress.h"
#include "core/common/text.h"
#include "flags/options.h"
#include "pipeline/process.h"

namespace vellum {

int RunProcess(const std::vector<std::string>& args) {
  const std::vector<Flags::Spec> specs = Join(
      {
          {"scan", "DIR", "scan directory (scan.yaml, texture.png, frame_000.png, ...)", ""},
          {"calibration", "FILE", "calibration YAML of camera and projector", ""},
          {"out", "DIR", "output directory", ""},
      },
      PipelineFlagSpecs());
  Flags flags(
      "vellum process",
      "Processes a scan directory: decodes the structured light, triangulates every decoded\n"
      "camera pixel, builds the mass-spring sheet over the page, flattens it and restores the\n"
      "texture. Writes points.ply (x y z mm world, u v camera pixel), depth.png, mesh.ply and\n"
      "flat.ply (the sheet before/after flattening), restored.tif (with its dpi in the TIFF\n"
      "tags in orthographic view), restored.json (view, dpi, flat mm -> pixel map),\n"
      "report.json (stage times, pixel counts, strain, the options used, the files written)\n"
      "and report.html (the same with pictures, for a browser).",
      specs);
  if (!flags.Parse(args)) return 0;
  const std::string scan_dir = flags.Require("scan");
  const std::string calibration = flags.Require("calibration");
  const std::string out = flags.Require("out");
  const PipelineOptions options = PipelineOptionsFromFlags(flags);

  Progress progress;
  progress.Update("read", 0);
  ProcessInput input;
  ProcessResult result;
  Status s = ReadProcessInput(scan_dir, calibration, &input);
  if (s.ok()) {
    result = RunPipeline(input, options, out, [&](const std::string& stage, double done) {
      progress.Update(stage, done);
    });
    s = result.status;
  }
  progress.Clear();
  if (!s.ok()) {
    std::fprintf(stderr, "vellum process: %s\n", s.message().c_str());
    return 1;
  }
  const RestoreResult& restored = result.restored;
  std::printf(
      "%d valid points; sheet %s, %s residual strain mean %.2e max %.2e; restored %dx%d"
      "%s; results in %s\n",
      result.map.valid, SizeText(options.mesh.grid).c_str(), ToString(options.flatten.solver),
      result.flat.mean_strain, result.flat.max_strain, restored.image.cols, restored.image.rows,
      restored.view == RestoreView::kOrthographic
          ? (" at " + std::to_string(static_cast<int>(restored.dpi)) + " dpi").c_str()
          : " (camera view)",
      out.c_str());
  return 0;
}

}  // namespace vellum
