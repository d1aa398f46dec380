#include <chrono>
#include <cmath>
#include <cstdio>

#include "cli/commands.h"
#include "cli/options.h"
#include "cli/progress.h"
#include "core/decode/decode.h"
#include "core/flatten/flatten.h"
#include "core/geometry/triangulate.h"
#include "core/io/calibration_io.h"
#include "core/io/html_report.h"
#include "core/io/products.h"
#include "core/io/scan_io.h"
#include "core/mesh/mesh.h"
#include "core/restore/restore.h"

namespace vellum {

int RunProcess(const std::vector<std::string>& args) {
  std::vector<Flags::Spec> specs = {
      {"scan", "DIR", "scan directory (scan.yaml, texture.png, frame_000.png, ...)", ""},
      {"calibration", "FILE", "calibration YAML of camera and projector", ""},
      {"out", "DIR", "output directory", ""},
  };
  for (const auto& group :
       {DecodeFlagSpecs(), TriangulateFlagSpecs(), FlattenFlagSpecs(), RestoreFlagSpecs()}) {
    specs = Join(specs, group);
  }
  Flags flags(
      "vellum process",
      "Processes a scan directory: decodes the structured light, triangulates every decoded\n"
      "camera pixel, builds the mass-spring sheet over the page, flattens it and restores the\n"
      "texture. Writes points.ply (x y z mm world, u v camera pixel), depth.png, mesh.ply and\n"
      "flat.ply (the sheet before/after flattening), restored.tif (with its dpi in the TIFF\n"
      "tags in orthographic view), restored.json (view, dpi, flat mm -> pixel map) and\n"
      "report.json (stage times, pixel counts, strain, the options used).",
      specs);
  if (!flags.Parse(args)) return 0;
  const std::string scan_dir = flags.Require("scan");
  const std::string calib_path = flags.Require("calibration");
  const std::string out = flags.Require("out");
  const std::string decoder = flags.Get("decoder");
  const DecodeOptions decode_options = DecodeOptionsFromFlags(flags);
  const TriangulateOptions tri_options = TriangulateOptionsFromFlags(flags);
  const MeshOptions mesh_options = MeshOptionsFromFlags(flags);
  const FlattenOptions flatten_options = FlattenOptionsFromFlags(flags);
  const RestoreOptions restore_options = RestoreOptionsFromFlags(flags);

  Progress* shown = nullptr;  // Cleared before an error is printed.
  auto fail = [&shown](const std::string& message) {
    if (shown) shown->Clear();
    std::fprintf(stderr, "vellum process: %s\n", message.c_str());
    return 1;
  };
  struct Stage {
    std::string name;
    double seconds;
  };
  std::vector<Stage> stages;
  auto clock = std::chrono::steady_clock::now();
  // Typical share of the whole run done after each stage (the simulators take longer).
  const bool slow = flatten_options.solver != FlattenSolver::kGaussNewton;
  const std::vector<std::pair<std::string, double>> plan = {
      {"read", 0.35},        {"decode", 0.5},     {"triangulate", 0.6},
      {"write points", 0.7}, {"mesh", 0.75},      {"flatten", slow ? 0.95 : 0.8},
      {"restore", 0.97},     {"write sheet", 1.0}};
  Progress progress;
  auto next_stage = [&](const std::string& done) {
    for (size_t k = 0; k + 1 < plan.size(); ++k) {
      if (plan[k].first == done) return plan[k + 1].first;
    }
    return std::string("report");
  };
  auto share = [&](const std::string& name) {
    for (const auto& [stage, f] : plan) {
      if (stage == name) return f;
    }
    return 1.0;
  };
  auto lap = [&](const std::string& name) {
    const auto now = std::chrono::steady_clock::now();
    stages.push_back({name, std::chrono::duration<double>(now - clock).count()});
    clock = now;
    progress.Update(next_stage(name), share(name));
  };
  shown = &progress;
  progress.Update("read", 0);

  Calibration calibration;
  Status s = ReadCalibration(calib_path, &calibration);
  if (!s.ok()) return fail(s.message());
  Scan scan;
  s = ReadScan(scan_dir, &scan);
  if (!s.ok()) return fail(s.message());
  if (scan.camera_size != calibration.camera.size) {
    return fail(scan_dir + ": camera images are " + SizeText(scan.camera_size) + " but " +
                calib_path + " calibrates a " + SizeText(calibration.camera.size) + " camera");
  }
  if (scan.sequence.projector_size != calibration.projector.size) {
    return fail(scan_dir + "/scan.yaml: projector_size is " +
                SizeText(scan.sequence.projector_size) + " but " + calib_path + " calibrates a " +
                SizeText(calibration.projector.size) + " projector");
  }
  s = MakeDirectories(out);
  if (!s.ok()) return fail(s.message());
  lap("read");

  const DecodeResult decoded = Decode(scan.sequence, scan.frames, decode_options);
  if (!decoded.status.ok()) return fail(scan_dir + ": " + decoded.status.message());
  lap("decode");
  const Triangulator triangulator(calibration);
  const PointMap map = triangulator.Triangulate(decoded, tri_options);
  if (!map.status.ok()) return fail(map.status.message());
  lap("triangulate");
  double zmin = 0, zmax = 0;
  s = WritePointProducts(out, map.points, &zmin, &zmax);
  if (!s.ok()) return fail(s.message());
  lap("write points");

  const cv::Mat page = SegmentPage(scan.texture);
  const Mesh mesh = BuildMesh(map.points, page, mesh_options,
                              [&](const cv::Vec3d& x) { return calibration.camera.Project(x); });
  if (!mesh.status.ok()) return fail(scan_dir + ": " + mesh.status.message());
  lap("mesh");
  const FlattenResult flat = Flatten(mesh, flatten_options);
  if (!flat.status.ok()) return fail(scan_dir + ": " + flat.status.message());
  lap("flatten");
  const RestoreResult restored =
      Restore(scan.texture, mesh, flat.flat, calibration.camera, restore_options);
  if (!restored.status.ok()) return fail(scan_dir + ": " + restored.status.message());
  lap("restore");
  s = WriteSheets(out, mesh, flat.flat);
  if (!s.ok()) return fail(s.message());
  s = WriteRestored(out, restored);
  if (!s.ok()) return fail(s.message());
  lap("write sheet");

  ProcessReport report;
  report.scan = scan_dir;
  report.calibration = calib_path;
  report.text_options = {{"decoder", decoder},
                         {"grid", SizeText(mesh_options.grid)},
                         {"solver", ToString(flatten_options.solver)},
                         {"view", ToString(restore_options.view)}};
  report.number_options = {{"smooth_radius_px", decode_options.smooth_radius_px},
                           {"min_contrast_dn", decode_options.min_contrast_dn},
                           {"min_modulation_dn", decode_options.min_modulation_dn},
                           {"max_unwrap_error", decode_options.max_unwrap_error},
                           {"max_epipolar_error_px", tri_options.max_epipolar_error_px},
                           {"dpi", restored.dpi}};
  report.camera = scan.camera_size;
  report.projector = scan.sequence.projector_size;
  report.patterns = static_cast<int>(scan.sequence.patterns.size());
  for (const Stage& st : stages) report.stages_seconds.emplace_back(st.name, st.seconds);
  const DecodeStats& ds = decoded.stats;
  report.pixels = ds.pixels;
  report.lit = ds.lit;
  report.decoded = ds.valid;
  report.valid = map.valid;
  report.page = cv::countNonZero(page);
  report.rejected_saturated = ds.rejected_saturated;
  report.rejected_gray_bits = ds.rejected_bits;
  report.rejected_modulation = ds.rejected_modulation;
  report.rejected_unwrap = ds.rejected_unwrap;
  report.rejected_epipolar = map.rejected_epipolar;
  report.rejected_volume = map.rejected_volume;
  report.fit_fallbacks = ds.fit_fallbacks;
  report.z_min_mm = zmin;
  report.z_max_mm = zmax;
  report.measured_nodes = mesh.measured;
  report.filled_nodes = mesh.filled;
  report.skirt_nodes = mesh.skirt;
  report.springs = static_cast<int>(mesh.springs.size());
  report.quads = static_cast<int>(mesh.quads.size());
  report.solver = ToString(flatten_options.solver);
  report.iterations = flat.iterations;
  report.mean_strain = flat.mean_strain;
  report.max_strain = flat.max_strain;
  report.folded_quads = flat.folded_quads;
  s = WriteReport(out, report);
  if (!s.ok()) return fail(s.message());
  HtmlReportInput html;
  html.title = scan_dir;
  html.figures = &report;
  html.texture = scan.texture;
  html.points = map.points;
  html.mesh = &mesh;
  html.flat = &flat.flat;
  html.restored = &restored;
  html.camera = calibration.camera;
  s = WriteHtmlReport(out, html);
  if (!s.ok()) return fail(s.message());
  progress.Clear();
  std::printf(
      "%d valid points; sheet %s, %s residual strain mean %.2e max %.2e; restored %dx%d"
      "%s; results in %s\n",
      map.valid, SizeText(mesh_options.grid).c_str(), ToString(flatten_options.solver),
      flat.mean_strain, flat.max_strain, restored.image.cols, restored.image.rows,
      restored.view == RestoreView::kOrthographic
          ? (" at " + std::to_string(static_cast<int>(restored.dpi)) + " dpi").c_str()
          : " (camera view)",
      out.c_str());
  return 0;
}

}  // namespace vellum
