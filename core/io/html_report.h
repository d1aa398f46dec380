// The per-scan report an operator opens in a browser (no network needed): report.html with
// the pictures in report/ (texture, valid pixels, depth with a colour bar in mm, the flattened
// grid over the restored page, strain, before/after crops), the key figures and the options.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/geometry/calibration.h"
#include "core/io/products.h"
#include "core/mesh/mesh.h"
#include "core/restore/restore.h"

namespace vellum {

struct HtmlReportInput {
  std::string title;  // "scan 1795…", or the scan directory.
  const ProcessReport* figures = nullptr;
  cv::Mat texture;  // The scan's texture.
  cv::Mat points;   // Organised point map (CV_32FC3); empty: no depth or mask.
  const Mesh* mesh = nullptr;
  const std::vector<cv::Point2d>* flat = nullptr;
  const RestoreResult* restored = nullptr;
  CameraModel camera;
};

// Writes <dir>/report.html and <dir>/report/*.png.
Status WriteHtmlReport(const std::string& dir, const HtmlReportInput& input);

}  // namespace vellum
