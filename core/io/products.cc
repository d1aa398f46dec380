#include "core/io/products.h"

#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/io/json.h"
#include "core/io/ply.h"
#include "core/io/scan_io.h"

namespace vellum {
namespace fs = std::filesystem;
namespace {

Status WriteText(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
  out.close();
  if (!out) return Status::Error(path + ": cannot write");
  return Status::Ok();
}

}  // namespace

std::string SizeText(cv::Size size) {
  return std::to_string(size.width) + "x" + std::to_string(size.height);
}

cv::Mat DepthPicture(const cv::Mat& points, double* z_min_mm, double* z_max_mm) {
  std::vector<cv::Mat> planes;
  cv::split(points, planes);
  const cv::Mat valid = planes[2] == planes[2];  // Not NaN.
  *z_min_mm = 0;
  *z_max_mm = 1;
  if (cv::countNonZero(valid) > 0) {
    cv::minMaxLoc(planes[2], z_min_mm, z_max_mm, nullptr, nullptr, valid);
  }
  cv::Mat z8;
  const double range = std::max(*z_max_mm - *z_min_mm, 1e-3);
  planes[2].convertTo(z8, CV_8U, 255.0 / range, -*z_min_mm * 255.0 / range);
  cv::Mat color;
  cv::applyColorMap(z8, color, cv::COLORMAP_TURBO);
  color.setTo(cv::Scalar::all(0), ~valid);
  return color;
}

Status WritePointProducts(const std::string& dir, const cv::Mat& points, double* z_min_mm,
                          double* z_max_mm) {
  Status s = WritePointsPly((fs::path(dir) / "points.ply").string(), points);
  if (!s.ok()) return s;
  return WriteImage((fs::path(dir) / "depth.png").string(),
                    DepthPicture(points, z_min_mm, z_max_mm));
}

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

Status WriteRestored(const std::string& dir, const RestoreResult& restored) {
  std::vector<int> tiff_params;
  if (restored.view == RestoreView::kOrthographic) {
    const int dpi = static_cast<int>(std::lround(restored.dpi));
    tiff_params = {cv::IMWRITE_TIFF_RESUNIT, 2,  cv::IMWRITE_TIFF_XDPI, dpi,
                   cv::IMWRITE_TIFF_YDPI,    dpi};
  }
  const std::string tif = (fs::path(dir) / "restored.tif").string();
  try {
    if (!cv::imwrite(tif, restored.image, tiff_params)) {
      return Status::Error(tif + ": cannot write image");
    }
  } catch (const cv::Exception& e) {
    return Status::Error(tif + ": cannot write image: " + e.what());
  }
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
  return WriteText((fs::path(dir) / "restored.json").string(), r.str());
}

Status WriteReport(const std::string& dir, const ProcessReport& report) {
  JsonWriter j;
  j.BeginObject();
  j.String("scan", report.scan).String("calibration", report.calibration);
  j.BeginObject("options");
  for (const auto& [key, value] : report.text_options) j.String(key, value);
  for (const auto& [key, value] : report.number_options) j.Number(key, value);
  j.EndObject();
  j.BeginObject("sizes")
      .String("camera", SizeText(report.camera))
      .String("projector", SizeText(report.projector))
      .Number("patterns", report.patterns)
      .EndObject();
  j.BeginObject("stages_seconds");
  double total = 0;
  for (const auto& [name, seconds] : report.stages_seconds) {
    j.Number(name, seconds);
    total += seconds;
  }
  j.Number("total", total).EndObject();
  j.BeginObject("pixels")
      .Number("camera", report.pixels)
      .Number("lit", report.lit)
      .Number("decoded", report.decoded)
      .Number("valid", report.valid)
      .Number("page", report.page)
      .Number("rejected_saturated", report.rejected_saturated)
      .Number("rejected_gray_bits", report.rejected_gray_bits)
      .Number("rejected_modulation", report.rejected_modulation)
      .Number("rejected_unwrap", report.rejected_unwrap)
      .Number("rejected_epipolar", report.rejected_epipolar)
      .Number("rejected_volume", report.rejected_volume)
      .Number("fit_fallbacks", report.fit_fallbacks)
      .EndObject();
  j.BeginObject("height_mm").Number("min", report.z_min_mm).Number("max", report.z_max_mm);
  j.EndObject();
  j.BeginObject("sheet")
      .Number("measured_nodes", report.measured_nodes)
      .Number("filled_nodes", report.filled_nodes)
      .Number("skirt_nodes", report.skirt_nodes)
      .Number("springs", report.springs)
      .Number("quads", report.quads)
      .EndObject();
  j.BeginObject("flattening")
      .String("solver", report.solver)
      .Number("iterations", report.iterations)
      .Number("mean_strain", report.mean_strain)
      .Number("max_strain", report.max_strain)
      .Number("folded_quads", report.folded_quads)
      .EndObject();
  j.BeginArray("outputs");
  for (const char* name : {"points.ply", "depth.png", "mesh.ply", "flat.ply", "restored.tif",
                           "restored.json", "report.json"}) {
    j.String("", name);
  }
  j.EndArray();
  j.EndObject();
  return WriteText((fs::path(dir) / "report.json").string(), j.str());
}

}  // namespace vellum
