// Small text helpers shared by messages, logs and reports.
#pragma once

#include <opencv2/core.hpp>
#include <string>

namespace vellum {

// "1600x1200".
inline std::string SizeText(cv::Size size) {
  return std::to_string(size.width) + "x" + std::to_string(size.height);
}

}  // namespace vellum
