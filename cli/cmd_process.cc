#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "cli/commands.h"
#include "core/decode/decode.h"
#include "core/flatten/flatten.h"
#include "core/geometry/triangulate.h"
#include "core/io/calibration_io.h"
#include "core/io/json.h"
#include "core/io/ply.h"
#include "core/io/scan_io.h"
#include "core/mesh/mesh.h"
#include "core/restore/restore.h"

namespace vellum {
namespace {

namespace fs = std::filesystem;

std::string SizeText(cv::Size s) {
  return std::to_string(s.width) + "x" + std::to_string(s.height);
}

// Height map as a picture: z mapped to colour over the valid points' range, invalid black.
cv::Mat DepthPicture(const cv::Mat& points, double* zmin, double* zmax) {
  std::vector<cv::Mat> planes;
  cv::split(points, planes);
  const cv::Mat valid = planes[2] == planes[2];  // Not NaN.
  *zmin = 0;
  *zmax = 1;
  if (cv::countNonZero(valid) > 0) cv::minMaxLoc(planes[2], zmin, zmax, nullptr, nullptr, valid);
  cv::Mat z8;
  const double range = std::max(*zmax - *zmin, 1e-3);
  planes[2].convertTo(z8, CV_8U, 255.0 / range, -*zmin * 255.0 / range);
  cv::Mat color;
  cv::applyColorMap(z8, color, cv::COLORMAP_TURBO);
  color.setTo(cv::Scalar::all(0), ~valid);
  return color;
}

// mesh.ply (3D) and flat.ply (z = 0): the active nodes in the same order, quad faces.
Status WriteSheets(const std::string& dir, const Mesh& mesh, const std::vector<cv::Point2d>& flat) {
  std::vector<int> index(mesh.kind.size(), -1);
  std::vector<cv::Vec3f> before, after;
  for (size_t k = 0; k < mesh.kind.size(); ++k) {
    if (!mesh.Active(static_cast<int>(k))) continue;
    index[k] = static_cast<int>(before.size());
    before.push_back(cv::Vec3f(mesh.point[k]));
    after.emplace_back(static_cast<float>(flat[k].x), static_cast<float>(flat[k].y), 0.0f);
  }
  std::vector<cv::Vec4i> quads;
  for (const cv::Vec4i& q : mesh.quads)
    quads.emplace_back(index[q[0]], index[q[1]], index[q[2]], index[q[3]]);
  Status s = WriteQuadMeshPly((fs::path(dir) / "mesh.ply").string(), before, quads,
                              "vellum sheet before flattening: world frame, mm");
  if (!s.ok()) return s;
  return WriteQuadMeshPly(
      (fs::path(dir) / "flat.ply").string(), after, quads,
      "vellum sheet after flattening: page plane, mm (same vertices as mesh.ply)");
}

}  // namespace

int RunProcess(const std::vector<std::string>& args) {
  Flags flags(
      "vellum process",
      "Processes a scan directory: decodes the structured light, triangulates every decoded\n"
      "camera pixel, builds the mass-spring sheet over the page, flattens it and restores the\n"
      "texture. Writes points.ply (x y z mm world, u v camera pixel), depth.png, mesh.ply and\n"
      "flat.ply (the sheet before/after flattening), restored.tif (with its dpi in the TIFF\n"
      "tags in orthographic view), restored.json (view, dpi, flat mm -> pixel map) and\n"
      "report.json (stage times, pixel counts, strain, the options used).",
      {
          {"scan", "DIR", "scan directory (scan.yaml, texture.png, frame_000.png, ...)", ""},
          {"calibration", "FILE", "calibration YAML of camera and projector", ""},
          {"out", "DIR", "output directory", ""},
          {"grid", "GxH", "flattening grid, nodes across x down", "45x45"},
          {"view", "NAME", "orthographic (true scale) or camera (as the camera would see it)",
           "orthographic"},
          {"dpi", "N", "orthographic resolution; 0 = the camera's sampling on the table", "0"},
          {"solver", "NAME", "gauss-newton (fast), euler or rk4 (the paper's simulator)",
           "gauss-newton"},
          {"decoder", "NAME", "phase (Gray code + phase shift) or gray (Gray code only)", "phase"},
          {"smooth-radius", "PX", "local fit radius, camera pixels (0..8); 0 = per-pixel decode",
           "3"},
          {"max-epipolar", "PX", "reject points farther from their epipolar line, projector px",
           "1.5"},
      });
  if (!flags.Parse(args)) return 0;
  const std::string scan_dir = flags.Require("scan");
  const std::string calib_path = flags.Require("calibration");
  const std::string out = flags.Require("out");
  DecodeOptions decode_options;
  const std::string decoder = flags.Get("decoder");
  if (decoder != "phase" && decoder != "gray") {
    throw UsageError("--decoder must be phase or gray, got '" + decoder + "'");
  }
  decode_options.use_phase = decoder == "phase";
  decode_options.smooth_radius_px = flags.GetInt("smooth-radius", 0, 8);
  TriangulateOptions tri_options;
  tri_options.max_epipolar_error_px = flags.GetDouble("max-epipolar", 0.01, 100);
  MeshOptions mesh_options;
  mesh_options.grid = flags.GetSize("grid");
  std::string why;
  if (!mesh_options.Check(&why)) throw UsageError("--grid: " + why);
  FlattenOptions flatten_options;
  if (!ParseFlattenSolver(flags.Get("solver"), &flatten_options.solver)) {
    throw UsageError("--solver must be gauss-newton, euler or rk4, got '" + flags.Get("solver") +
                     "'");
  }
  RestoreOptions restore_options;
  if (!ParseRestoreView(flags.Get("view"), &restore_options.view)) {
    throw UsageError("--view must be orthographic or camera, got '" + flags.Get("view") + "'");
  }
  restore_options.dpi = flags.GetDouble("dpi", 0, 4800);

  auto fail = [](const std::string& message) {
    std::fprintf(stderr, "vellum process: %s\n", message.c_str());
    return 1;
  };
  struct Stage {
    std::string name;
    double seconds;
  };
  std::vector<Stage> stages;
  auto clock = std::chrono::steady_clock::now();
  auto lap = [&](const std::string& name) {
    const auto now = std::chrono::steady_clock::now();
    stages.push_back({name, std::chrono::duration<double>(now - clock).count()});
    clock = now;
    std::fprintf(stderr, "process: %-12s %7.3f s\n", name.c_str(), stages.back().seconds);
  };

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
  const std::string ply = (fs::path(out) / "points.ply").string();
  s = WritePointsPly(ply, map.points);
  if (!s.ok()) return fail(s.message());
  double zmin = 0, zmax = 0;
  s = WriteImage((fs::path(out) / "depth.png").string(), DepthPicture(map.points, &zmin, &zmax));
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
  std::vector<int> tiff_params;
  if (restored.view == RestoreView::kOrthographic) {
    const int dpi = static_cast<int>(std::lround(restored.dpi));
    tiff_params = {cv::IMWRITE_TIFF_RESUNIT, 2,  cv::IMWRITE_TIFF_XDPI, dpi,
                   cv::IMWRITE_TIFF_YDPI,    dpi};
  }
  const std::string tif = (fs::path(out) / "restored.tif").string();
  try {
    if (!cv::imwrite(tif, restored.image, tiff_params)) return fail(tif + ": cannot write image");
  } catch (const cv::Exception& e) {
    return fail(tif + ": cannot write image: " + e.what());
  }
  {
    JsonWriter r;
    r.BeginObject();
    r.String("view", ToString(restored.view));
    r.String("image", "restored.tif");
    r.Number("width", restored.image.cols).Number("height", restored.image.rows);
    if (restored.view == RestoreView::kOrthographic) {
      const cv::Matx23d& a = restored.pixel_from_flat;
      r.Number("dpi", restored.dpi);
      r.String("flat_frame", "the x, y of flat.ply, mm");
      r.BeginArray("pixel_from_flat_mm");
      for (int row = 0; row < 2; ++row) {
        r.BeginArray();
        for (int col = 0; col < 3; ++col) r.Number("", a(row, col));
        r.EndArray();
      }
      r.EndArray();
      r.String("pixel_convention", "pixel centres at integer coordinates; column = x, row = -y");
    } else {
      r.String("flat_frame", "the x, y of flat.ply, mm, on the table plane z = 0");
      r.String("pixel_from_flat_mm", "the calibrated camera's projection of (x, y, 0)");
    }
    r.EndObject();
    std::ofstream((fs::path(out) / "restored.json").string()) << r.str();
  }
  lap("write sheet");

  JsonWriter j;
  j.BeginObject();
  j.String("scan", scan_dir).String("calibration", calib_path);
  j.BeginObject("options")
      .String("decoder", decoder)
      .Number("smooth_radius_px", decode_options.smooth_radius_px)
      .Number("min_contrast_dn", decode_options.min_contrast_dn)
      .Number("min_modulation_dn", decode_options.min_modulation_dn)
      .Number("max_unwrap_error", decode_options.max_unwrap_error)
      .Number("max_epipolar_error_px", tri_options.max_epipolar_error_px)
      .String("grid", SizeText(mesh_options.grid))
      .String("solver", ToString(flatten_options.solver))
      .String("view", ToString(restore_options.view))
      .Number("dpi", restored.dpi)
      .EndObject();
  j.BeginObject("sizes")
      .String("camera", SizeText(scan.camera_size))
      .String("projector", SizeText(scan.sequence.projector_size))
      .Number("patterns", static_cast<double>(scan.sequence.patterns.size()))
      .EndObject();
  j.BeginObject("stages_seconds");
  double total = 0;
  for (const Stage& st : stages) {
    j.Number(st.name, st.seconds);
    total += st.seconds;
  }
  j.Number("total", total).EndObject();
  const DecodeStats& ds = decoded.stats;
  j.BeginObject("pixels")
      .Number("camera", ds.pixels)
      .Number("lit", ds.lit)
      .Number("decoded", ds.valid)
      .Number("valid", map.valid)
      .Number("page", cv::countNonZero(page))
      .Number("rejected_saturated", ds.rejected_saturated)
      .Number("rejected_gray_bits", ds.rejected_bits)
      .Number("rejected_modulation", ds.rejected_modulation)
      .Number("rejected_unwrap", ds.rejected_unwrap)
      .Number("rejected_epipolar", map.rejected_epipolar)
      .Number("rejected_volume", map.rejected_volume)
      .Number("fit_fallbacks", ds.fit_fallbacks)
      .EndObject();
  j.BeginObject("height_mm").Number("min", zmin).Number("max", zmax).EndObject();
  j.BeginObject("sheet")
      .Number("measured_nodes", mesh.measured)
      .Number("filled_nodes", mesh.filled)
      .Number("skirt_nodes", mesh.skirt)
      .Number("springs", static_cast<double>(mesh.springs.size()))
      .Number("quads", static_cast<double>(mesh.quads.size()))
      .EndObject();
  j.BeginObject("flattening")
      .String("solver", ToString(flatten_options.solver))
      .Number("iterations", flat.iterations)
      .Number("mean_strain", flat.mean_strain)
      .Number("max_strain", flat.max_strain)
      .Number("folded_quads", flat.folded_quads)
      .EndObject();
  j.BeginArray("outputs");
  for (const char* name : {"points.ply", "depth.png", "mesh.ply", "flat.ply", "restored.tif",
                           "restored.json", "report.json"}) {
    j.String("", name);
  }
  j.EndArray();
  j.EndObject();
  std::ofstream((fs::path(out) / "report.json").string()) << j.str();
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
