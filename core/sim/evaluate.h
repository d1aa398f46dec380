// Accuracy of a measured point map against the virtual gantry's ground truth.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include "core/patterns/patterns.h"
#include "core/sim/gantry.h"

namespace vellum {

struct PointErrorStats {
  int page_lit_pixels = 0;  // Page pixels the projector lights directly.
  int valid = 0;            // Of those, pixels with a measured point.
  double valid_fraction = 0;
  double median_mm = 0, rms_mm = 0, p99_mm = 0, max_mm = 0;  // 3D error over valid page pixels.
};

// Compares a CV_32FC3 point map with the truth over page pixels lit by the projector.
PointErrorStats ComparePoints(const GroundTruth& truth, const cv::Mat& points);

// Renders one camera frame per pattern of the sequence; frame k uses noise seed seed + k + 1.
std::vector<cv::Mat> RenderSequence(const VirtualGantry& gantry, const PatternSequence& sequence,
                                    uint64_t seed);

}  // namespace vellum
