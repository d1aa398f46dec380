// A guard for reading matrices from untrusted OpenCV YAML: `node >> mat` allocates whatever
// rows x cols the file declares (a fuzzed calibration asked for 48 GB), so the declared size is
// checked first.
#pragma once

#include <opencv2/core/persistence.hpp>

namespace vellum {

// False when `node` is a map (an !!opencv-matrix) that does not declare integer rows and cols
// within max_elements elements; true otherwise (other nodes: reading will judge them).
inline bool MatrixNodeAtMost(const cv::FileNode& node, double max_elements) {
  if (!node.isMap()) return true;
  const cv::FileNode rows = node["rows"], cols = node["cols"];
  if (!rows.isInt() || !cols.isInt()) return false;
  const double r = static_cast<int>(rows), c = static_cast<int>(cols);
  return r >= 0 && c >= 0 && r * c <= max_elements;
}

}  // namespace vellum
