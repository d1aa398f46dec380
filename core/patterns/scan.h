// One structured-light scan as captured: the pattern sequence shown, the texture under studio
// light, and the camera frame taken under each pattern (DESIGN.md's scan directory, in memory).
#pragma once

#include <opencv2/core.hpp>
#include <vector>

#include "core/patterns/patterns.h"

namespace vellum {

struct Scan {
  PatternSequence sequence;
  cv::Size camera_size;         // 0x0 when unknown (a pattern set not yet captured).
  cv::Mat texture;              // 8-bit gray or BGR.
  std::vector<cv::Mat> frames;  // 8-bit gray, one per pattern.
};

}  // namespace vellum
