// A guard for reading matrices from untrusted OpenCV YAML: `node >> mat` allocates whatever
// rows x cols the file declares (a fuzzed calibration asked for 48 GB), so the declared size is
// checked first.
#pragma once

#include <fstream>
#include <iterator>
#include <opencv2/core/persistence.hpp>
#include <string>

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

// Checks that `path` is a text file of a sane size before OpenCV parses it: OpenCV 4.6's YAML
// parser loops forever on a file with a NUL byte in it (found by fuzz/fuzz_files), so such a
// file is refused. Returns "" when fine, else what is wrong.
inline std::string YamlTextProblem(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return "cannot open";
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size > (16 << 20)) return "too large for a YAML file (" + std::to_string(size) + " bytes)";
  in.seekg(0);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (text.find('\0') != std::string::npos) return "not a text file (it contains NUL bytes)";
  return "";
}

}  // namespace vellum
