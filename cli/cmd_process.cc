#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/imgproc.hpp>

#include "cli/commands.h"
#include "core/decode/decode.h"
#include "core/geometry/triangulate.h"
#include "core/io/calibration_io.h"
#include "core/io/json.h"
#include "core/io/ply.h"
#include "core/io/scan_io.h"

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

}  // namespace

int RunProcess(const std::vector<std::string>& args) {
  Flags flags(
      "vellum process",
      "Processes a scan directory: decodes the structured light, triangulates every decoded\n"
      "camera pixel and writes points.ply (x y z mm world, u v camera pixel), depth.png and\n"
      "report.json (stage times, pixel counts, the options used).",
      {
          {"scan", "DIR", "scan directory (scan.yaml, texture.png, frame_000.png, ...)", ""},
          {"calibration", "FILE", "calibration YAML of camera and projector", ""},
          {"out", "DIR", "output directory", ""},
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
  lap("rays");
  const PointMap map = triangulator.Triangulate(decoded, tri_options);
  if (!map.status.ok()) return fail(map.status.message());
  lap("triangulate");

  const std::string ply = (fs::path(out) / "points.ply").string();
  s = WritePointsPly(ply, map.points);
  if (!s.ok()) return fail(s.message());
  double zmin = 0, zmax = 0;
  s = WriteImage((fs::path(out) / "depth.png").string(), DepthPicture(map.points, &zmin, &zmax));
  if (!s.ok()) return fail(s.message());
  lap("write");

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
      .Number("rejected_saturated", ds.rejected_saturated)
      .Number("rejected_gray_bits", ds.rejected_bits)
      .Number("rejected_modulation", ds.rejected_modulation)
      .Number("rejected_unwrap", ds.rejected_unwrap)
      .Number("rejected_epipolar", map.rejected_epipolar)
      .Number("rejected_volume", map.rejected_volume)
      .Number("fit_fallbacks", ds.fit_fallbacks)
      .EndObject();
  j.BeginObject("height_mm").Number("min", zmin).Number("max", zmax).EndObject();
  j.BeginArray("outputs");
  j.String("", "points.ply").String("", "depth.png").String("", "report.json");
  j.EndArray();
  j.EndObject();
  const std::string report = (fs::path(out) / "report.json").string();
  std::ofstream(report) << j.str();
  std::printf("%d valid points of %d camera pixels; wrote %s, depth.png, report.json in %s\n",
              map.valid, ds.pixels, "points.ply", out.c_str());
  return 0;
}

}  // namespace vellum
