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

// Checks that `path` is a text file of a sane size, with nothing known to hang OpenCV 4.6's
// YAML parser, before OpenCV parses it: the parser loops forever on a NUL byte, on a second
// document not started by "---", and on a "---" line with an entry after it (all found by
// fuzz/fuzz_files). Returns "" when fine, else what is wrong.
inline std::string YamlTextProblem(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return "cannot open";
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size > (16 << 20)) return "too large for a YAML file (" + std::to_string(size) + " bytes)";
  in.seekg(0);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (text.find('\0') != std::string::npos) return "not a text file (it contains NUL bytes)";
  // OpenCV 4.6's parser also loops forever when a second YAML document follows the first one
  // and does not start with "---" (found by fuzz/fuzz_files): the first document must be at
  // column 0 (so it runs to the end of the file), and "..." (end of document) is refused.
  bool content = false;
  for (size_t start = 0; start < text.size();) {
    size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    const std::string line = text.substr(start, end - start);
    const size_t first = line.find_first_not_of(" \r");
    start = end + 1;
    if (first == std::string::npos || line[first] == '#') continue;
    if (line.compare(first, 3, "...") == 0) {
      return "a \"...\" line (end of a YAML document) is not supported";
    }
    if (line.compare(first, 3, "---") == 0) {
      const size_t rest = line.find_first_not_of(" \r", first + 3);
      if (rest != std::string::npos && line[rest] != '#') {
        return "an entry on a \"---\" line is not supported (start it on the next line)";
      }
    }
    if (content || line[first] == '%' || line.compare(first, 3, "---") == 0) continue;
    if (first != 0) return "the first entry is indented (it must start at column 0)";
    content = true;
  }
  return "";
}

}  // namespace vellum
