// SplitAtGutter and UnseenAtGutter: an open book's two pages.
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "core/outline/steps.h"

namespace vellum {
namespace outline {

// An open book's gutter: a straight valley down the leaf from which the surface rises at least
// `options.gutter_rise_mm` on both sides, a crease (within gutter_width_mm each side rises
// gutter_crease_mm, or is hidden from view), not a trough. Splits the leaf into its left and
// right pages; false if there is no such valley.
bool SplitAtGutter(const cv::Mat& points, const cv::Mat& z, const cv::Mat& leaf,
                   const OutlineOptions& options, cv::Vec4f* line, cv::Mat* left, cv::Mat* right,
                   bool* parted) {
  if (parted) *parted = true;
  const double rise = options.gutter_rise_mm;
  const cv::Rect box = cv::boundingRect(leaf);
  if (box.width < 20 || box.height < 20) return false;
  std::vector<cv::Point2f> valley;
  for (int v = box.y + box.height / 10; v < box.y + box.height * 9 / 10; v += 4) {
    const float* row = z.ptr<float>(v);
    const uint8_t* in = leaf.ptr<uint8_t>(v);
    // The lowest leaf point in the middle half of the row, and the highest on either side.
    int lowest = -1;
    for (int u = box.x + box.width / 4; u < box.x + box.width * 3 / 4; ++u) {
      if (in[u] && Valid(row[u]) && (lowest < 0 || row[u] < row[lowest])) lowest = u;
    }
    if (lowest < 0) continue;
    float high_left = kNoData, high_right = kNoData;
    for (int u = box.x; u < box.x + box.width; ++u) {
      if (!in[u] || !Valid(row[u])) continue;
      if (u < lowest) high_left = std::max(high_left, row[u]);
      if (u > lowest) high_right = std::max(high_right, row[u]);
    }
    if (!(high_left - row[lowest] >= rise && high_right - row[lowest] >= rise)) continue;
    // A crease: near the valley, each side rises steeply or is out of sight.
    const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
    const cv::Point2f bottom(p[lowest][0], p[lowest][1]);
    if (!std::isfinite(bottom.x) || !std::isfinite(bottom.y)) continue;
    float near_left = kNoData, near_right = kNoData;
    for (int u = box.x; u < box.x + box.width; ++u) {
      if (u == lowest || !in[u] || !Valid(row[u]) || !std::isfinite(p[u][0])) continue;
      if (cv::norm(cv::Point2f(p[u][0], p[u][1]) - bottom) > options.gutter_width_mm) continue;
      (u < lowest ? near_left : near_right) = std::max(u < lowest ? near_left : near_right, row[u]);
    }
    auto steep = [&](float near) {
      return near == kNoData || near - row[lowest] >= options.gutter_crease_mm;
    };
    if (steep(near_left) && steep(near_right)) {
      valley.emplace_back(static_cast<float>(lowest), static_cast<float>(v));
    }
  }
  // Most rows must show the valley, on one straight line.
  const int rows = (box.height * 8 / 10) / 4;
  if (static_cast<int>(valley.size()) < rows * 2 / 3 || valley.size() < 5) return false;
  cv::fitLine(valley, *line, cv::DIST_HUBER, 0, 0.01, 0.01);
  const float vx = (*line)[0], vy = (*line)[1], x0 = (*line)[2], y0 = (*line)[3];
  int off = 0;
  for (const cv::Point2f& p : valley) {
    off += std::fabs((p.x - x0) * vy - (p.y - y0) * vx) > 8;  // Pixels from the line.
  }
  if (off > static_cast<int>(valley.size()) / 4) return false;
  *left = cv::Mat::zeros(leaf.size(), CV_8U);
  *right = cv::Mat::zeros(leaf.size(), CV_8U);
  // Where the line falls within a couple of pixels of the end of a run of leaf pixels that is a
  // page's body (the line runs through each row's lowest point, which can be the first pixel of
  // the far page's wall, beyond the gap between the pages), the whole run is that page's.
  constexpr int kEdge = 2, kBody = 20, kGap = 8;
  for (int v = 0; v < leaf.rows; ++v) {
    // The line's column at this row (the gutter runs down the image).
    float at = std::fabs(vy) > 1e-6f ? x0 + (v - y0) * vx / vy : x0;
    const uint8_t* in = leaf.ptr<uint8_t>(v);
    const int c = static_cast<int>(std::floor(at));
    if (c >= 0 && c < leaf.cols && in[c]) {
      int a = c, b = c;
      while (a > 0 && in[a - 1]) --a;
      while (b + 1 < leaf.cols && in[b + 1]) ++b;
      // The gap beyond the run's end, up to kGap pixels.
      auto gap = [&](int u, int step) {
        int n = 0;
        while (n < kGap && u >= 0 && u < leaf.cols && !in[u]) ++n, u += step;
        return n;
      };
      if (b - a + 1 >= kBody && c - a <= kEdge && gap(a - 1, -1) >= kGap) at = a;
      if (b - a + 1 >= kBody && b - c <= kEdge && gap(b + 1, 1) >= kGap) at = b + 1.0f;
    }
    for (int u = 0; u < leaf.cols; ++u) {
      if (!in[u]) continue;
      (u < at ? left : right)->at<uint8_t>(v, u) = 255;
    }
  }
  return true;
}

}  // namespace outline

GutterGap UnseenAtGutter(const cv::Mat& points, const Outline& outline) {
  GutterGap gap;
  if (outline.pages.size() != 2 || points.type() != CV_32FC3) return gap;
  const cv::Mat &left = outline.pages[0], &right = outline.pages[1];
  if (left.size() != points.size() || right.size() != points.size()) return gap;
  const cv::Rect box = cv::boundingRect(outline.mask);
  std::vector<float> lengths;
  for (int v = box.y + box.height / 10; v < box.y + box.height * 9 / 10; ++v) {
    const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
    const uint8_t *in_left = left.ptr<uint8_t>(v), *in_right = right.ptr<uint8_t>(v);
    auto measured = [&](int u) { return std::isfinite(p[u][2]); };
    int last_left = -1, first_right = -1;
    for (int u = box.x; u < box.x + box.width; ++u) {
      if (in_left[u] && measured(u)) last_left = u;
      if (first_right < 0 && in_right[u] && measured(u)) first_right = u;
    }
    if (last_left < 0 || first_right < 0 || first_right <= last_left) continue;
    lengths.push_back(static_cast<float>(cv::norm(p[first_right] - p[last_left])));
  }
  gap.rows = static_cast<int>(lengths.size());
  if (lengths.empty()) return gap;
  std::sort(lengths.begin(), lengths.end());
  gap.median_mm = lengths[lengths.size() / 2];
  gap.p95_mm = lengths[std::min(lengths.size() - 1, lengths.size() * 95 / 100)];
  return gap;
}

}  // namespace vellum
