#include "core/decode/frame_check.h"

#include <cstdint>
#include <cstdlib>
#include <string>

#include "core/common/check.h"

namespace vellum {

bool FrameCheckOptions::Check(std::string* why) const {
  if (min_contrast < 1 || min_contrast > 255 || !(pair_tolerance > 0 && pair_tolerance < 1) ||
      !(mixed_share > 0 && mixed_share < 1) || changed_levels < 1 || changed_levels > 255 ||
      !(changed_share > 0 && changed_share < 1)) {
    *why =
        "frame check: min_contrast and changed_levels in 1..255, the tolerance and shares "
        "between 0 and 1";
    return false;
  }
  return true;
}

double PairMismatch(const cv::Mat& pattern, const cv::Mat& inverse, const cv::Mat& white,
                    const cv::Mat& black, const FrameCheckOptions& o) {
  for (const cv::Mat* m : {&pattern, &inverse, &white, &black}) {
    VELLUM_DEMAND(m->type() == CV_8UC1 && m->size() == pattern.size());
  }
  int64_t lit = 0, off = 0;
  for (int y = 0; y < pattern.rows; ++y) {
    const uint8_t* p = pattern.ptr<uint8_t>(y);
    const uint8_t* q = inverse.ptr<uint8_t>(y);
    const uint8_t* w = white.ptr<uint8_t>(y);
    const uint8_t* b = black.ptr<uint8_t>(y);
    for (int x = 0; x < pattern.cols; ++x) {
      const int contrast = w[x] - b[x];
      if (contrast < o.min_contrast) continue;
      ++lit;
      off += std::abs(p[x] + q[x] - w[x] - b[x]) > o.pair_tolerance * contrast;
    }
  }
  return lit == 0 ? 0.0 : static_cast<double>(off) / static_cast<double>(lit);
}

double FrameChange(const cv::Mat& a, const cv::Mat& b, const FrameCheckOptions& o) {
  VELLUM_DEMAND(a.type() == b.type() && a.size() == b.size() && !a.empty());
  cv::Mat diff;
  cv::absdiff(a, b, diff);
  const int changed = cv::countNonZero(diff.reshape(1) > o.changed_levels);
  return static_cast<double>(changed) / static_cast<double>(diff.total() * diff.channels());
}

}  // namespace vellum
