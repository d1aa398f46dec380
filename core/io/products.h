// What processing a scan writes (DESIGN.md, `vellum process`): points.ply and depth.png,
// mesh.ply and flat.ply, restored.tif and restored.json, report.json. One writer for each,
// used alike by `vellum process` and by the station's daemons, so both give the same files.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <utility>
#include <vector>

#include "core/common/status.h"
#include "core/mesh/mesh.h"
#include "core/restore/restore.h"

namespace vellum {

// The figures of report.json. Stage times are in seconds, in pipeline order.
struct ProcessReport {
  std::string scan, calibration;  // Where the input came from.
  std::vector<std::pair<std::string, std::string>> text_options;
  std::vector<std::pair<std::string, double>> number_options;
  cv::Size camera, projector;
  int patterns = 0;
  std::vector<std::pair<std::string, double>> stages_seconds;
  // Pixels.
  int pixels = 0, lit = 0, decoded = 0, valid = 0, page = 0;
  int rejected_saturated = 0, rejected_gray_bits = 0, rejected_modulation = 0;
  int rejected_unwrap = 0, rejected_epipolar = 0, rejected_volume = 0, fit_fallbacks = 0;
  double z_min_mm = 0, z_max_mm = 0;
  // Sheet and flattening.
  int measured_nodes = 0, filled_nodes = 0, skirt_nodes = 0, springs = 0, quads = 0;
  std::string solver;
  int iterations = 0, folded_quads = 0;
  double mean_strain = 0, max_strain = 0;
};

// The height map as a picture: z over the valid points' range in colour, invalid black; sets
// the range in mm.
cv::Mat DepthPicture(const cv::Mat& points, double* z_min_mm, double* z_max_mm);

// points.ply and depth.png of an organised point map (CV_32FC3, NaN where invalid).
Status WritePointProducts(const std::string& dir, const cv::Mat& points, double* z_min_mm,
                          double* z_max_mm);
// mesh.ply (3D) and flat.ply (z = 0): the sheet's active nodes in the same order, quad faces.
Status WriteSheets(const std::string& dir, const Mesh& mesh, const std::vector<cv::Point2d>& flat);
// restored.tif (TIFF dpi tags in orthographic view) and restored.json.
Status WriteRestored(const std::string& dir, const RestoreResult& restored);
// report.json.
Status WriteReport(const std::string& dir, const ProcessReport& report);

// "1600x1200".
std::string SizeText(cv::Size size);

}  // namespace vellum
