// Guards for reading untrusted OpenCV YAML: `node >> mat` allocates whatever rows x cols the
// file declares (a fuzzed calibration asked for 48 GB), so the declared size is checked first;
// the parser hangs on some texts, so they are refused first; and image sizes are bounded, so
// that arithmetic on them cannot overflow (fuzz/fuzz_files found a 70000 x 70000 one).
#pragma once

#include <fstream>
#include <iterator>
#include <opencv2/core/mat.hpp>
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
// document not started by "---", on a "---" line with an entry after it, and on a "%" directive
// after "---" (all found by fuzz/fuzz_files). Returns "" when fine, else what is wrong.
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
  bool content = false, begun = false;  // An entry seen; a "---" seen.
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
      begun = true;
    }
    // A directive ("%YAML:1.0") opens the file, at column 0: after "---" or an entry, or
    // indented, the parser may never return.
    if (line[first] == '%' && (first != 0 || begun || content)) {
      return "a \"%\" directive after the start of the document is not supported";
    }
    if (content || line[first] == '%' || line.compare(first, 3, "---") == 0) continue;
    if (first != 0) return "the first entry is indented (it must start at column 0)";
    content = true;
  }
  return "";
}

// The most pixels a side of any camera, projector or image vellum reads may have (a 150 MP
// back is 14204 x 10652; a 24 MP camera 6000 x 4000). A bound, so that an area, a cell count or
// a rectangle's far edge computed from a file's numbers always fits in an int.
constexpr int kMaxImageSide = 16384;

// Reads a [ width, height ] size from untrusted YAML: a sequence of two integers (how cv::Size
// is written), or a matrix of two whole numbers. Returns "" and sets *size, or says what is
// wrong ("is missing", "must be ...") for the caller to prefix with its file and key.
inline std::string ReadSizeNode(const cv::FileNode& node, cv::Size* size) {
  *size = cv::Size();
  if (node.empty() || node.isNone()) return "is missing";
  const std::string form = "must be [ width, height ], two whole numbers of pixels";
  double w = 0, h = 0;
  if (node.isSeq()) {
    if (node.size() != 2 || !node[0].isInt() || !node[1].isInt()) return form;
    w = static_cast<int>(node[0]);
    h = static_cast<int>(node[1]);
  } else {
    if (!node.isMap() || !MatrixNodeAtMost(node, 2)) return form;
    cv::Mat m;
    try {
      node >> m;
    } catch (const std::exception&) {
      return form;
    }
    if (m.total() != 2 || m.channels() != 1) return form;
    m.convertTo(m, CV_64F);
    w = m.at<double>(0);
    h = m.at<double>(1);
  }
  // Whole numbers, finite, and in range, judged before any conversion to int.
  if (!(w >= 1 && w <= kMaxImageSide && h >= 1 && h <= kMaxImageSide)) {
    return "must be 1 to " + std::to_string(kMaxImageSide) + " pixels each way";
  }
  if (w != static_cast<int>(w) || h != static_cast<int>(h)) return form;
  *size = cv::Size(static_cast<int>(w), static_cast<int>(h));
  return "";
}

}  // namespace vellum
