// SplitAtGutter and UnseenAtGutter: an open book's two pages.
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "core/outline/steps.h"

namespace vellum {
namespace outline {

namespace {

// The valley in one row `v` of the leaf, if it has one: its lowest point in the middle three
// fifths of the row's leaf, each side rising gutter_rise_mm within gutter_reach_mm of it and
// creased within gutter_width_mm of where that side begins; whether both sides level off
// beyond the bend, and whether the pages part there (a gap within gutter_apart_px).
struct ValleyRow {
  bool found = false;
  float u = 0;  // The valley's column (down a gap's middle where the pages part).
  bool levels = false, gap = false;
};
ValleyRow ValleyInRow(const cv::Mat& points, const cv::Mat& z, const cv::Mat& leaf,
                      const cv::Rect& box, int v, const OutlineOptions& options) {
  ValleyRow out;
  const int near_px = options.gutter_apart_px;  // Pixels either side of the valley's point.
  const float* row = z.ptr<float>(v);
  const uint8_t* in = leaf.ptr<uint8_t>(v);
  const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
  // The lowest leaf point in the middle three fifths of the row's leaf.
  int first = -1, last = -1;
  for (int u = box.x; u < box.x + box.width; ++u) {
    if (!in[u]) continue;
    if (first < 0) first = u;
    last = u;
  }
  if (first < 0 || last - first < 20) return out;
  int lowest = -1;
  for (int u = first + (last - first) / 5; u <= last - (last - first) / 5; ++u) {
    if (in[u] && Valid(row[u]) && (lowest < 0 || row[u] < row[lowest])) lowest = u;
  }
  if (lowest < 0 || !std::isfinite(p[lowest][0])) return out;
  // Each side rises gutter_rise_mm within gutter_reach_mm of the bottom, and gutter_crease_mm
  // within gutter_width_mm of where that side begins (across a gap between the pages, the far
  // page begins at its first point; a side with no point that near is hidden in the gutter).
  const cv::Point2f bottom(p[lowest][0], p[lowest][1]);
  cv::Point2f begins[2] = {bottom, bottom};
  for (int side = 0; side < 2; ++side) {
    for (int u = lowest + (side ? 1 : -1); u >= first && u <= last; u += side ? 1 : -1) {
      if (!in[u] || !Valid(row[u]) || !std::isfinite(p[u][0])) continue;
      if (cv::norm(cv::Point2f(p[u][0], p[u][1]) - bottom) <= options.gutter_width_mm) {
        begins[side] = cv::Point2f(p[u][0], p[u][1]);
      }
      break;
    }
  }
  float high[2] = {kNoData, kNoData}, near[2] = {kNoData, kNoData}, beyond[2] = {kNoData, kNoData};
  for (int u = first; u <= last; ++u) {
    if (u == lowest || !in[u] || !Valid(row[u]) || !std::isfinite(p[u][0])) continue;
    const cv::Point2f at(p[u][0], p[u][1]);
    const int side = u > lowest;
    const double from_bottom = cv::norm(at - bottom);
    if (from_bottom <= options.gutter_reach_mm) {
      high[side] = std::max(high[side], row[u]);
    } else if (from_bottom <= 2 * options.gutter_reach_mm) {
      beyond[side] = std::max(beyond[side], row[u]);
    }
    if (cv::norm(at - begins[side]) <= options.gutter_width_mm) {
      near[side] = std::max(near[side], row[u]);
    }
  }
  bool valley_here = true;
  for (int side = 0; side < 2; ++side) {
    valley_here = valley_here && high[side] - row[lowest] >= options.gutter_rise_mm &&
                  (near[side] == kNoData || near[side] - row[lowest] >= options.gutter_crease_mm);
  }
  if (!valley_here) return out;
  // Where the pages part, the lowest point is the foot of either page's wall, a gap's width
  // from the other: the valley runs down the gap's middle.
  float valley_u = static_cast<float>(lowest);
  for (int d = 1; d <= near_px && lowest - d >= first && lowest + d <= last; ++d) {
    const int u = !in[lowest - d] ? lowest - d : (!in[lowest + d] ? lowest + d : -1);
    if (u < 0) continue;
    int a = u, b = u;
    while (a > first && !in[a - 1]) --a;
    while (b < last && !in[b + 1]) ++b;
    if (b - a <= 2 * near_px) valley_u = 0.5f * (a + b);
    break;
  }
  out.found = true;
  out.u = valley_u;
  bool levels = true;
  for (int side = 0; side < 2; ++side) {
    levels = levels && beyond[side] != kNoData &&
             beyond[side] - high[side] < 0.5f * (high[side] - row[lowest]);
  }
  out.levels = levels;
  bool gap = false;
  for (int u = std::max(first, lowest - near_px); u <= std::min(last, lowest + near_px); ++u) {
    gap = gap || !in[u];
  }
  out.gap = gap;
  return out;
}

// Where the pages part in each row along the valley's `line` (a gap in the leaf within near_px
// pixels of it): the split follows the gap nearest the line, since the line runs through each
// row's lowest point, which can be the first pixels of the far page's wall, beyond the gap
// between the pages. `line_at` is the line's column in each row, `gap_at` the gap's middle
// from it (kNoGap: none), `grazing` each page's last pixel before the gap: seen at a grazing
// angle down the gutter, its point mixes both walls, so it is left out of both pages.
constexpr float kNoGap = -1e9f;
void GapsAlongLine(const cv::Mat& leaf, const cv::Vec4f& line, int near_px,
                   std::vector<float>* line_at_out, std::vector<float>* gap_at_out,
                   std::vector<std::pair<int, int>>* grazing_out) {
  const float vx = line[0], vy = line[1], x0 = line[2], y0 = line[3];
  std::vector<float>& line_at = *line_at_out;
  std::vector<float>& gap_at = *gap_at_out;
  std::vector<std::pair<int, int>>& grazing = *grazing_out;
  line_at.assign(leaf.rows, 0);
  gap_at.assign(leaf.rows, kNoGap);
  grazing.assign(leaf.rows, {-1, -1});
  for (int v = 0; v < leaf.rows; ++v) {
    // The line's column at this row (the gutter runs down the image).
    line_at[v] = std::fabs(vy) > 1e-6f ? x0 + (v - y0) * vx / vy : x0;
    const uint8_t* in = leaf.ptr<uint8_t>(v);
    const int c = static_cast<int>(std::floor(line_at[v]));
    int best = -1;
    for (int d = 0; d <= near_px && best < 0; ++d) {
      for (const int u : {c - d, c + d}) {
        if (u > 0 && u + 1 < leaf.cols && !in[u] && best < 0) best = u;
      }
    }
    if (best < 0) continue;
    // The gap's ends; it parts the pages only with leaf on both sides near it.
    int a = best, b = best;
    while (a > 0 && !in[a - 1]) --a;
    while (b + 1 < leaf.cols && !in[b + 1]) ++b;
    if (a > 0 && b + 1 < leaf.cols && a >= c - 2 * near_px && b <= c + 2 * near_px) {
      gap_at[v] = 0.5f * (a + b) + 0.5f - line_at[v];
      grazing[v] = {a - 1, b + 1};
    }
  }
}

// The leaf's pixels either side of the split (each row's gap, or the line where the pages
// meet; a row with no gap of its own, noise closed it, takes the median gap of the rows around
// it): into *left and *right.
void DividePages(const cv::Mat& leaf, const std::vector<float>& line_at,
                 const std::vector<float>& gap_at, const std::vector<std::pair<int, int>>& grazing,
                 const OutlineOptions& options, cv::Mat* left, cv::Mat* right) {
  *left = cv::Mat::zeros(leaf.size(), CV_8U);
  *right = cv::Mat::zeros(leaf.size(), CV_8U);
  const int borrow = options.gutter_borrow_rows;  // Rows either side a closed row borrows from.
  const float meet_px = static_cast<float>(options.gutter_meet_px);
  for (int v = 0; v < leaf.rows; ++v) {
    float at = line_at[v];
    bool meet = false;  // The pages meet at the line in this row.
    if (gap_at[v] != kNoGap) {
      at += gap_at[v];
    } else {
      std::vector<float> near;
      for (int w = std::max(0, v - borrow); w <= std::min(leaf.rows - 1, v + borrow); ++w) {
        if (gap_at[w] != kNoGap) near.push_back(gap_at[w]);
      }
      if (near.size() >= static_cast<size_t>(borrow / 2)) {
        std::nth_element(near.begin(), near.begin() + near.size() / 2, near.end());
        at += near[near.size() / 2];
      } else {
        meet = true;
      }
    }
    const uint8_t* in = leaf.ptr<uint8_t>(v);
    for (int u = 0; u < leaf.cols; ++u) {
      if (!in[u] || u == grazing[v].first || u == grazing[v].second) continue;
      // Where the pages meet, the pixels within meet_px of the line belong to both (the line is
      // fitted to the rows' lowest points to about a pixel): left out of both.
      if (meet && std::fabs(u + 0.5f - at) < meet_px) continue;
      (u < at ? left : right)->at<uint8_t>(v, u) = 255;
    }
  }
}

}  // namespace

bool SplitAtGutter(const cv::Mat& points, const cv::Mat& z, const cv::Mat& leaf,
                   const OutlineOptions& options, cv::Vec4f* line, cv::Mat* left, cv::Mat* right,
                   GutterSigns* signs) {
  const cv::Rect box = cv::boundingRect(leaf);
  if (box.width < 20 || box.height < 20) return false;
  std::vector<cv::Point2f> valley;
  int apart = 0;  // Valley rows where the two sides do not meet (a gap, or a band out of view).
  int level = 0;  // Valley rows where both sides level off beyond the bend.
  for (int v = box.y + box.height / 10; v < box.y + box.height * 9 / 10; v += 4) {
    const ValleyRow row = ValleyInRow(points, z, leaf, box, v, options);
    if (!row.found) continue;
    valley.emplace_back(row.u, static_cast<float>(v));
    level += row.levels;
    apart += row.gap;
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
  if (signs) {
    signs->parted = 2 * apart >= static_cast<int>(valley.size());
    signs->bound = 2 * level >= static_cast<int>(valley.size());
  }
  std::vector<float> line_at, gap_at;
  std::vector<std::pair<int, int>> grazing;
  GapsAlongLine(leaf, *line, options.gutter_apart_px, &line_at, &gap_at, &grazing);
  DividePages(leaf, line_at, gap_at, grazing, options, left, right);
  return true;
}

}  // namespace outline

GutterGap UnseenAtGutter(const cv::Mat& points, const Outline& outline) {
  GutterGap gap;
  if (outline.pages.size() != 2 || points.type() != CV_32FC3) return gap;
  const cv::Mat &left = outline.pages[0], &right = outline.pages[1];
  if (left.size() != points.size() || right.size() != points.size() ||
      outline.mask.size() != points.size()) {
    return gap;
  }
  const cv::Rect box = cv::boundingRect(outline.mask);
  std::vector<float> lengths, bounds;
  for (int v = box.y + box.height / 10; v < box.y + box.height * 9 / 10; ++v) {
    const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
    const uint8_t *in_left = left.ptr<uint8_t>(v), *in_right = right.ptr<uint8_t>(v),
                  *in_leaf = outline.mask.ptr<uint8_t>(v);
    auto measured = [&](int u) { return std::isfinite(p[u][2]); };
    int last_left = -1, first_right = -1;
    for (int u = box.x; u < box.x + box.width; ++u) {
      if (in_left[u] && measured(u)) last_left = u;
      if (first_right < 0 && in_right[u] && measured(u)) first_right = u;
    }
    if (last_left < 0 || first_right < 0 || first_right <= last_left) continue;
    // Where the pages part and what lies under them is measured between them (off the leaf: the
    // pixels the split gave neither page are the pages' too), each page is seen down to its foot:
    // what is missing is from its last point to the first point beside it.
    int after_left = -1, before_right = -1;
    for (int u = last_left + 1; u < first_right; ++u) {
      if (in_leaf[u] || !measured(u)) continue;
      if (after_left < 0) after_left = u;
      before_right = u;
    }
    // A page's length per pixel at its innermost point, over its last kSlopePx pixels.
    auto per_px = [&](int at, int outward) {
      const int out = at + outward * GutterGap::kSlopePx;
      const uint8_t* page = outward < 0 ? in_left : in_right;
      if (out < box.x || out >= box.x + box.width || !page[out] || !measured(out)) return 1e9;
      return cv::norm(p[at] - p[out]) / GutterGap::kSlopePx;
    };
    // Beside a parted page, the line to the first point measured beside it runs down the page's
    // edge to the table (no page), and its pixels between may be the page's shadow on the table:
    // the page is missing over no more than either, its own length per pixel over them.
    const double length = after_left < 0
                              ? cv::norm(p[first_right] - p[last_left])
                              : std::min(cv::norm(p[after_left] - p[last_left]),
                                         (after_left - last_left) * per_px(last_left, -1)) +
                                    std::min(cv::norm(p[first_right] - p[before_right]),
                                             (first_right - before_right) * per_px(first_right, 1));
    lengths.push_back(static_cast<float>(length));
    double bound = length;
    const int out_left = last_left - GutterGap::kSlopePx,
              out_right = first_right + GutterGap::kSlopePx;
    if (after_left < 0 && out_left >= box.x && out_right < box.x + box.width && in_left[out_left] &&
        measured(out_left) && in_right[out_right] && measured(out_right)) {
      // The two slopes, A + s a and B + t b, where they come closest.
      const cv::Vec3d A(p[last_left]), B(p[first_right]);
      const cv::Vec3d a = cv::normalize(A - cv::Vec3d(p[out_left]));
      const cv::Vec3d b = cv::normalize(B - cv::Vec3d(p[out_right]));
      const cv::Vec3d w = A - B;
      const double ab = a.dot(b), d = a.dot(w), e = b.dot(w), denom = 1 - ab * ab;
      if (denom > 1e-6) {
        const double s = (ab * e - d) / denom, t = (e - ab * d) / denom;
        if (s > 0 && t > 0) bound = std::max(length, s + t + cv::norm((A + s * a) - (B + t * b)));
      }
    }
    bounds.push_back(static_cast<float>(bound));
  }
  gap.rows = static_cast<int>(lengths.size());
  if (lengths.empty()) return gap;
  std::sort(lengths.begin(), lengths.end());
  gap.median_mm = lengths[lengths.size() / 2];
  gap.p95_mm = lengths[std::min(lengths.size() - 1, lengths.size() * 95 / 100)];
  std::nth_element(bounds.begin(), bounds.begin() + bounds.size() / 2, bounds.end());
  gap.bound_mm = bounds[bounds.size() / 2];
  return gap;
}

}  // namespace vellum
