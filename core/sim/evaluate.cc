#include "core/sim/evaluate.h"

#include <algorithm>
#include <cmath>

namespace vellum {

PointErrorStats ComparePoints(const GroundTruth& truth, const cv::Mat& points) {
  PointErrorStats st;
  std::vector<double> errors;
  double sum2 = 0;
  for (int v = 0; v < points.rows; ++v) {
    const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
    const cv::Vec3f* t = truth.points.ptr<cv::Vec3f>(v);
    const uint8_t* page = truth.on_page.ptr<uint8_t>(v);
    const uint8_t* lit = truth.lit.ptr<uint8_t>(v);
    for (int u = 0; u < points.cols; ++u) {
      if (!page[u] || !lit[u]) continue;
      ++st.page_lit_pixels;
      if (!std::isfinite(p[u][0])) continue;
      const double e = cv::norm(cv::Vec3d(p[u]) - cv::Vec3d(t[u]));
      errors.push_back(e);
      sum2 += e * e;
    }
  }
  st.valid = static_cast<int>(errors.size());
  if (st.page_lit_pixels > 0)
    st.valid_fraction = static_cast<double>(st.valid) / st.page_lit_pixels;
  if (errors.empty()) return st;
  auto quantile = [&](double q) {
    const size_t k =
        std::min(errors.size() - 1, static_cast<size_t>(q * (errors.size() - 1) + 0.5));
    std::nth_element(errors.begin(), errors.begin() + k, errors.end());
    return errors[k];
  };
  st.median_mm = quantile(0.5);
  st.p99_mm = quantile(0.99);
  st.max_mm = *std::max_element(errors.begin(), errors.end());
  st.rms_mm = std::sqrt(sum2 / errors.size());
  return st;
}

std::vector<cv::Mat> RenderSequence(const VirtualGantry& gantry, const PatternSequence& sequence,
                                    uint64_t seed) {
  std::vector<cv::Mat> frames;
  frames.reserve(sequence.patterns.size());
  for (size_t k = 0; k < sequence.patterns.size(); ++k) {
    frames.push_back(gantry.RenderFrame(
        RenderPattern(sequence.patterns[k], sequence.projector_size), seed + k + 1));
  }
  return frames;
}

}  // namespace vellum
