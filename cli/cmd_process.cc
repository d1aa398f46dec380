#include <cstdio>

#include "cli/commands.h"
#include "cli/progress.h"
#include "core/common/text.h"
#include "flags/options.h"
#include "io/calibration_io.h"
#include "pipeline/process.h"
#include "pipeline/qc.h"
#include "runtime/memory.h"

namespace vellum {

int RunProcess(const std::vector<std::string>& args) {
  const std::vector<Flags::Spec> specs = Join(
      {
          {"scan", "DIR", "scan directory (scan.yaml, texture.png, frame_000.png, ...)", ""},
          {"calibration", "FILE", "calibration YAML of camera and projector", ""},
          {"out", "DIR", "output directory", ""},
          {"until", "STAGE",
           "restored (every stage), or points: stop after the point cloud (points.ply, "
           "depth.png, the report), for an object that is not a page",
           "restored"},
      },
      PipelineFlagSpecs());
  Flags flags(
      "vellum process",
      "Processes a scan directory: decodes the structured light, triangulates every decoded\n"
      "camera pixel, builds the mass-spring sheet over the page, flattens it and restores the\n"
      "texture. Writes points.ply (x y z mm world, u v camera pixel), depth.png, mesh.ply and\n"
      "flat.ply (the sheet before/after flattening), restored.tif (with its dpi in the TIFF\n"
      "tags in orthographic view), restored.json (view, dpi, flat mm -> pixel map),\n"
      "report.json (stage times, pixel counts, strain, the options used, the files written,\n"
      "warnings) and report.html (the same with pictures, for a browser). On a spread (an\n"
      "open book) each page's files go to pages/left/ and pages/right/.\n"
      "Exit status: 0 restored; 1 an error (one line names the file and the problem); 2 bad\n"
      "flags; 3 restored with a verdict other than PASS: warnings that make the result\n"
      "doubtful (the leaf runs off the view, an uncertain outline, high strain or fold-over,\n"
      "an unexpected leaf size, a spread's pages missing over 5 mm at the gutter) or a figure\n"
      "short of the collection's target (--target-*): check report.html before delivering it.",
      specs);
  if (!flags.Parse(args)) return 0;
  // One scan, processed once: fresh pages are dear (each faults in zeroed; on this project's
  // VM touching 180 MB of new 4 kB pages takes about half a second), so large images go on huge
  // pages and a stage's freed buffers serve the next stage's.
  UseMemoryForOneRun();
  const std::string scan_dir = flags.Require("scan");
  const std::string calibration = flags.Require("calibration");
  const std::string out = flags.Require("out");
  PipelineOptions options = PipelineOptionsFromFlags(flags);
  const std::string until = flags.Get("until");
  if (until != "restored" && until != "points") {
    throw UsageError("--until must be restored or points, got '" + until + "'");
  }
  options.points_only = until == "points";

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
  if (options.points_only) {
    std::printf("%d valid points; stopped after the point cloud (--until points)\n",
                result.map.valid);
  } else {
    std::printf("%d valid points; %s\n", result.map.valid,
                result.outline.pages.size() > 1 ? "a spread of two pages" : "one leaf");
  }
  for (const PageResult& page : result.pages) {
    const RestoreResult& restored = page.restored;
    std::printf("%s: sheet %dx%d, %s residual strain mean %.2e max %.2e; restored %dx%d%s\n",
                page.name.empty() ? "leaf" : page.name.c_str(), page.mesh.cols, page.mesh.rows,
                ToString(options.flatten.solver), page.flat.mean_strain, page.flat.max_strain,
                restored.image.cols, restored.image.rows,
                restored.view == RestoreView::kOrthographic
                    ? (" at " + std::to_string(static_cast<int>(restored.dpi)) + " dpi").c_str()
                    : " (camera view)");
  }
  std::printf("results in %s\n", out.c_str());
  const QcResult qc = AssessQuality(result.report);
  std::printf("quality: %s\n", VerdictName(qc.verdict));
  for (const QcCheck& c : qc.checks) {
    if (c.verdict != QcVerdict::kPass) {
      std::printf("  %s: %s: %s\n", c.name.c_str(), VerdictName(c.verdict), c.detail.c_str());
    }
  }
  // A doubtful result is written, and said so: on stderr and in the exit status.
  const std::vector<Warning> warnings = result.report.Warnings();
  for (const Warning& w : warnings) {
    std::fprintf(stderr, "vellum process: warning %s: %s\n", w.code.c_str(), w.message.c_str());
  }
  if (!warnings.empty() || qc.verdict != QcVerdict::kPass) return kExitDoubtful;
  return 0;
}

}  // namespace vellum
