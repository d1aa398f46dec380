#include "bench/baseline/outline_v1.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/text.h"
#include "core/mesh/mesh.h"

namespace vellum::baseline {
namespace {

constexpr float kNoData = -1e4f;  // Heights below -1e3 mean "no point".

bool Valid(float z) { return z > -1e3f; }

// SmoothHeights' common case, for the pixels 1 to w - 2 of a row (`up`, `row` and `down` the
// raw heights of three rows): where the pixel and its eight neighbours all have a height, the
// median of the pixel and the means of its four opposite pairs, found without sorting (of the
// four means, the larger of the two pairwise minima and the smaller of the two pairwise maxima
// are the middle two; the median of five is the median of those and the pixel); NaN elsewhere.
// Without branches, so the compiler vectorizes it.
void MedianOfFive(const float* up, const float* row, const float* down, int w,
                  float* __restrict out) {
  for (int u = 1; u < w - 1; ++u) {
    const float l = row[u - 1], r = row[u + 1], t = up[u], b = down[u], tl = up[u - 1],
                br = down[u + 1], tr = up[u + 1], bl = down[u - 1], c = row[u];
    auto lo = [](float x, float y) { return x < y ? x : y; };
    auto hi = [](float x, float y) { return x > y ? x : y; };
    const float least = lo(lo(lo(l, r), lo(t, b)), lo(lo(tl, br), lo(lo(tr, bl), c)));
    const float m0 = 0.5f * (l + r), m1 = 0.5f * (t + b), m2 = 0.5f * (tl + br),
                m3 = 0.5f * (tr + bl);
    const float f = hi(lo(m0, m1), lo(m2, m3)), g = lo(hi(m0, m1), hi(m2, m3));
    const float median = hi(lo(f, g), lo(hi(f, g), c));
    out[u] = Valid(least) ? median : std::numeric_limits<float>::quiet_NaN();
  }
}

// Heights of the point map, each the median of its own and the means of its opposite
// neighbours (left-right, up-down and both diagonals) where both have a point: an isolated
// outlier is dropped, a step stays sharp, and a steep slope with missing points is not biased (a
// plain 3 x 3 median over the points present picks a lower or higher neighbour where points are
// missing on one side: on a 50 degree ripple, a third of a millimetre, a false rim). kNoData
// where the pixel has no point and fewer than two pairs do; `nan` (if given) gets the same
// heights with NaN there instead.
cv::Mat SmoothHeights(const cv::Mat& points, cv::Mat* nan = nullptr) {
  const int w = points.cols, h = points.rows;
  cv::Mat raw(points.size(), CV_32F);
  cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& range) {
    for (int v = range.start; v < range.end; ++v) {
      const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
      float* out = raw.ptr<float>(v);
      for (int u = 0; u < w; ++u) out[u] = std::isfinite(p[u][2]) ? p[u][2] : kNoData;
    }
  });
  cv::Mat smooth(points.size(), CV_32F);
  if (nan) *nan = cv::Mat(points.size(), CV_32F);
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& range) {
    for (int v = range.start; v < range.end; ++v) {
      float* out = smooth.ptr<float>(v);
      if (v == 0 || v == h - 1) {
        std::fill_n(out, w, kNoData);
        if (nan) std::fill_n(nan->ptr<float>(v), w, kNaN);
        continue;
      }
      const float *up = raw.ptr<float>(v - 1), *row = raw.ptr<float>(v),
                  *down = raw.ptr<float>(v + 1);
      out[0] = out[w - 1] = kNoData;
      MedianOfFive(up, row, down, w, out);
      for (int u = 1; u < w - 1; ++u) {
        if (out[u] == out[u]) continue;
        // A pixel or a neighbour without a height (NaN from MedianOfFive): the pairs present.
        out[u] = kNoData;
        float values[5];
        int n = 0;
        auto pair = [&](float a, float b) {
          if (Valid(a) && Valid(b)) values[n++] = 0.5f * (a + b);
        };
        pair(row[u - 1], row[u + 1]);
        pair(up[u], down[u]);
        pair(up[u - 1], down[u + 1]);
        pair(up[u + 1], down[u - 1]);
        if (Valid(row[u])) {
          values[n++] = row[u];
        } else if (n < 2) {
          continue;
        }
        for (int i = 1; i < n; ++i) {  // Insertion sort: at most five values.
          const float x = values[i];
          int j = i;
          for (; j > 0 && values[j - 1] > x; --j) values[j] = values[j - 1];
          values[j] = x;
        }
        out[u] = n % 2 ? values[n / 2] : 0.5f * (values[n / 2 - 1] + values[n / 2]);
      }
      if (nan) {
        float* with_nan = nan->ptr<float>(v);
        for (int u = 0; u < w; ++u) with_nan[u] = Valid(out[u]) ? out[u] : kNaN;
      }
    }
  });
  return smooth;
}

// One row of RimStrength's step test: for each pixel, the strongest disagreement of the surface
// `a` and `b` = 2a pixels before and after it, extrapolated to it, along the row (`row`), the
// column and both diagonals (the rows b and a above, a and b below). A plain function over
// pointers, so the compiler vectorizes it.
void StepDisagreement(const float* row, const float* rb, const float* ra, const float* sa,
                      const float* sb, int a, int b, int w, float* __restrict out) {
  const float slope = 2.0f * a;
  // |after - before|, less what a steep, curved surface gives without any step (its samples
  // thin out as it turns from the camera: half the height it changes per pixel there).
  auto disagree = [slope](float fb, float nb, float na, float fa) {
    const float d =
        std::fabs((na - (fa - na)) - (nb + (nb - fb))) - 0.5f * std::fabs(na - nb) / slope;
    return d > 0.0f ? d : 0.0f;  // NaN (a missing height) gives 0: no evidence.
  };
  for (int u = b; u < w - b; ++u) {
    // By value (std::max returns a reference, which can keep a loop from vectorizing).
    const float d0 = disagree(row[u - b], row[u - a], row[u + a], row[u + b]);
    const float d1 = disagree(rb[u], ra[u], sa[u], sb[u]);
    const float d2 = disagree(rb[u - b], ra[u - a], sa[u + a], sb[u + b]);
    const float d3 = disagree(rb[u + b], ra[u + a], sa[u - a], sb[u - b]);
    const float e0 = d0 > d1 ? d0 : d1, e1 = d2 > d3 ? d2 : d3;
    out[u] = e0 > e1 ? e0 : e1;
  }
}

// How strongly each pixel lies on a rim, mm: where the height steps, or where the surface
// turns nearly parallel to the camera's rays (a silhouette, with its flying mixed pixels).
// The decoder's local fit spreads a step over its window, so a step is measured at that scale:
// the surface `scale` to 2 * `scale` pixels away on either side, extrapolated linearly to the
// pixel, must agree (a plane or a symmetric curve agrees exactly; a step of height S disagrees
// by S over a band about as wide as the fit's window, centred on the edge). Along rows, columns
// and both diagonals; the strongest disagreement is kept.
// `zn`: the heights with NaN where there is none (the comparisons below then drop out by
// themselves).
cv::Mat RimStrength(const cv::Mat& points, const cv::Mat& zn, int scale, double max_slope_deg) {
  cv::Mat strength = cv::Mat::zeros(zn.size(), CV_32F);
  const int a = scale, b = 2 * scale, w = zn.cols;
  const float tan_max = static_cast<float>(std::tan(max_slope_deg * M_PI / 180.0));
  const float tan2 = tan_max * tan_max;
  cv::parallel_for_(cv::Range(0, zn.rows), [&](const cv::Range& range) {
    for (int v = range.start; v < range.end; ++v) {
      const float* row = zn.ptr<float>(v);
      float* out = strength.ptr<float>(v);
      if (v >= b && v + b < zn.rows) {
        StepDisagreement(row, zn.ptr<float>(v - b), zn.ptr<float>(v - a), zn.ptr<float>(v + a),
                         zn.ptr<float>(v + b), a, b, w, out);
      }
      // Silhouettes: the height changes faster than a surface at max_slope_deg would between a
      // point and its right or lower neighbour. Written without branches (a missing height or
      // point is NaN, and a comparison with NaN is false), so the compiler vectorizes it.
      const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
      auto steeper = [tan2](float rise, float dx, float dy, float was) {
        return rise * rise > tan2 * (dx * dx + dy * dy) ? std::max(was, std::fabs(rise)) : was;
      };
      for (int u = 0; u + 1 < w; ++u) {
        out[u] = steeper(row[u + 1] - row[u], p[u + 1][0] - p[u][0], p[u + 1][1] - p[u][1], out[u]);
      }
      if (v + 1 < zn.rows) {
        const cv::Vec3f* q = points.ptr<cv::Vec3f>(v + 1);
        const float* below = zn.ptr<float>(v + 1);
        for (int u = 0; u < w; ++u) {
          out[u] = steeper(below[u] - row[u], q[u][0] - p[u][0], q[u][1] - p[u][1], out[u]);
        }
      }
    }
  });
  return strength;
}

// The texture's paper brightness: the level 95% of its pixels are at or below (gray levels).
double BrightLevel(const cv::Mat& gray) {
  int hist[256] = {0};
  for (int v = 0; v < gray.rows; v += 2) {
    const uint8_t* row = gray.ptr<uint8_t>(v);
    for (int u = 0; u < gray.cols; u += 2) ++hist[row[u]];
  }
  long total = 0, acc = 0;
  for (int h : hist) total += h;
  for (int i = 0; i < 256; ++i) {
    acc += hist[i];
    if (acc >= 0.95 * total) return std::max(i, 1);
  }
  return 255;
}

// The height step that counts as a rim at each pixel, mm: `step` where the surface is at least
// half as bright as paper, step * 0.5 / brightness below it (the decoder's noise goes as
// 1 / brightness over dark ink, and its fit is biased at the edges of ink). `darkest` takes the
// darkest brightness the decoder's fit reaches (a cautious threshold, for deciding whether a hole
// is real); otherwise the mean brightness there (a sensitive one, for finding rims across lines
// of text). Brightness is relative to the texture's bright level.
// If `in_steps` is given, it is divided by the threshold in the same pass.
cv::Mat StepThreshold(const cv::Mat& gray, double bright, double step, int scale, bool darkest,
                      cv::Mat* in_steps = nullptr) {
  cv::Mat around;
  const int reach = 2 * scale + 1;
  if (darkest) {
    cv::erode(gray, around, cv::getStructuringElement(cv::MORPH_RECT, {reach, reach}));
  } else {
    cv::blur(gray, around, {2 * reach + 1, 2 * reach + 1});
  }
  cv::Mat threshold(gray.size(), CV_32F);
  const float to_paper = static_cast<float>(1.0 / bright), half = static_cast<float>(0.5 * step),
              least = static_cast<float>(step);
  cv::parallel_for_(cv::Range(0, gray.rows), [&](const cv::Range& range) {
    for (int v = range.start; v < range.end; ++v) {
      const uint8_t* in = around.ptr<uint8_t>(v);
      float* out = threshold.ptr<float>(v);
      for (int u = 0; u < gray.cols; ++u) {
        out[u] = std::max(least, half / std::max(in[u] * to_paper, 0.05f));
      }
      if (in_steps) {
        float* x = in_steps->ptr<float>(v);
        for (int u = 0; u < gray.cols; ++u) x[u] /= out[u];
      }
    }
  });
  return threshold;
}

// Labels (1 leaf, 2 surround) spread from their seeds over the pixels with a height, lowest rim
// strength (in rim-threshold units) first (a watershed: two floods meet on the rim's crest, even
// where the rim is faint). `labels` holds the seeds on input; pixels without a height stay 0.
void Flood(const cv::Mat& strength, const cv::Mat& z, cv::Mat* labels) {
  constexpr int kLevels = 256;
  const int w = z.cols, h = z.rows;
  // Each pixel's level (rim strength in 1/32 of the threshold, capped), or -1 without a height,
  // and its label: flat, row-major and framed by a pixel without a height, so a neighbour is an
  // offset and never out of bounds.
  const int stride = w + 2;
  std::vector<int16_t> level(static_cast<size_t>(stride) * (h + 2), -1);
  std::vector<uint8_t> label(level.size(), 0);
  for (int v = 0; v < h; ++v) {
    const float* s = strength.ptr<float>(v);
    const float* zr = z.ptr<float>(v);
    const uint8_t* in = labels->ptr<uint8_t>(v);
    const size_t row = static_cast<size_t>(v + 1) * stride + 1;
    for (int u = 0; u < w; ++u) {
      const float x = s[u] * 32;
      level[row + u] = !Valid(zr[u])      ? -1
                       : x >= kLevels - 1 ? kLevels - 1
                                          : static_cast<int16_t>(x);
      label[row + u] = in[u];
    }
  }
  const int around[4] = {1, -1, stride, -stride};
  // A pixel is queued once: it is taken at the level of its first queueing (later ones come
  // from higher levels), so a pixel queued is marked as if it had no height.
  constexpr int16_t kQueued = -2;
  std::vector<std::vector<int>> buckets(kLevels);
  // The floods start from the seeds' edges: unlabelled pixels with a height beside a seed.
  for (int at = stride; at < stride * (h + 1); ++at) {
    if (label[at] != 0 || level[at] < 0) continue;
    if (label[at + 1] | label[at - 1] | label[at + stride] | label[at - stride]) {
      buckets[level[at]].push_back(at);
      level[at] = kQueued;
    }
  }
  for (int l = 0; l < kLevels; ++l) {
    for (size_t k = 0; k < buckets[l].size(); ++k) {
      const int at = buckets[l][k];
      if (label[at] != 0) continue;
      // The label of the flood that reached it: a labelled 4-neighbour.
      uint8_t from = 0;
      for (int d = 0; d < 4 && !from; ++d) from = label[at + around[d]];
      if (!from) continue;
      label[at] = from;
      for (int d = 0; d < 4; ++d) {
        const int next = at + around[d];
        if (label[next] != 0 || level[next] < 0) continue;
        buckets[std::max<int>(l, level[next])].push_back(next);
        level[next] = kQueued;
      }
    }
    std::vector<int>().swap(buckets[l]);
  }
  for (int v = 0; v < h; ++v) {
    std::copy_n(label.data() + static_cast<size_t>(v + 1) * stride + 1, w, labels->ptr<uint8_t>(v));
  }
}

double Median(std::vector<float>* values) {
  if (values->empty()) return 0;
  std::nth_element(values->begin(), values->begin() + values->size() / 2, values->end());
  return (*values)[values->size() / 2];
}

// Whether the heights `inside` a hole lie on the surface the leaf makes `around` it (a quadric
// fitted to the leaf around it, so a curled leaf's bend does not pass for a step): their median
// distance from it is under `step`. `slack_px` forgives each point what the surface's slope there
// gives over that many pixels (on a wall turned nearly edge-on to the camera a height changes by
// half a millimetre per pixel, and a fit extrapolated across a gap is not better than a pixel).
bool OnSurface(const std::vector<cv::Point3f>& around, const std::vector<cv::Point3f>& inside,
               double step, double slack_px = 0) {
  if (around.size() < 12 || inside.empty()) return false;
  // Centred and scaled, for a well-conditioned fit.
  cv::Point2f centre(0, 0);
  for (const cv::Point3f& p : around) centre += cv::Point2f(p.x, p.y);
  centre *= 1.0f / around.size();
  float scale = 1;
  for (const cv::Point3f& p : around) {
    scale = std::max({scale, std::fabs(p.x - centre.x), std::fabs(p.y - centre.y)});
  }
  auto terms = [&](const cv::Point3f& p, double* row) {
    const double x = (p.x - centre.x) / scale, y = (p.y - centre.y) / scale;
    row[0] = 1, row[1] = x, row[2] = y, row[3] = x * x, row[4] = x * y, row[5] = y * y;
  };
  // Least squares by the normal equations (the terms are scaled to [-1, 1]: well conditioned);
  // an SVD of the whole system only where they are not (points on a line).
  Eigen::Matrix<double, 6, 6> ata = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> atb = Eigen::Matrix<double, 6, 1>::Zero(), quadric;
  double row[6];
  for (const cv::Point3f& p : around) {
    terms(p, row);
    for (int i = 0; i < 6; ++i) {
      for (int j = i; j < 6; ++j) ata(i, j) += row[i] * row[j];
      atb(i) += row[i] * p.z;
    }
  }
  ata.triangularView<Eigen::StrictlyLower>() = ata.transpose();
  const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> ldlt(ata);
  if (ldlt.info() == Eigen::Success && ldlt.rcond() > 1e-9) {
    quadric = ldlt.solve(atb);
  } else {
    cv::Mat a(static_cast<int>(around.size()), 6, CV_64F), b(a.rows, 1, CV_64F), x;
    for (int k = 0; k < a.rows; ++k) {
      terms(around[k], a.ptr<double>(k));
      b.at<double>(k) = around[k].z;
    }
    if (!cv::solve(a, b, x, cv::DECOMP_SVD)) return false;
    for (int t = 0; t < 6; ++t) quadric(t) = x.at<double>(t);
  }
  std::vector<float> off;
  for (const cv::Point3f& p : inside) {
    terms(p, row);
    double fit = 0;
    for (int t = 0; t < 6; ++t) fit += row[t] * quadric(t);
    // The quadric's slope there, mm per pixel (row[1] and row[2] are the scaled x and y).
    const double gx = (quadric(1) + 2 * quadric(3) * row[1] + quadric(4) * row[2]) / scale,
                 gy = (quadric(2) + quadric(4) * row[1] + 2 * quadric(5) * row[2]) / scale;
    const double slack = slack_px * std::hypot(gx, gy);
    off.push_back(static_cast<float>(std::max(0.0, std::fabs(p.z - fit) - slack)));
  }
  return Median(&off) < step;
}

// Heights beside the leaf (a hole's, or a surface's that may join the leaf) against the leaf's
// around them, compared square tile by square tile of a grid of `size` cells: each tile's
// points `inside` against a quadric of the leaf's points `around` them in that tile or within a
// quarter tile of it (OnSurface).
class TileComparison {
 public:
  TileComparison(cv::Size size, int tile)
      : tile_(tile),
        tiles_x_((size.width + tile - 1) / tile),
        tiles_y_((size.height + tile - 1) / tile),
        inside_(tiles_x_ * tiles_y_),
        around_(tiles_x_ * tiles_y_),
        steps_(tiles_x_ * tiles_y_) {}

  // A point at cell (u, v) of the grid, with the step threshold there.
  void Inside(int u, int v, const cv::Point3f& p, float step) {
    const int t = (v / tile_) * tiles_x_ + u / tile_;
    inside_[t].push_back(p);
    steps_[t].push_back(step);
  }
  void Around(int u, int v, const cv::Point3f& p) {
    for (int ty = std::max(0, (v - tile_ / 4) / tile_);
         ty <= std::min(tiles_y_ - 1, (v + tile_ / 4) / tile_); ++ty) {
      for (int tx = std::max(0, (u - tile_ / 4) / tile_);
           tx <= std::min(tiles_x_ - 1, (u + tile_ / 4) / tile_); ++tx) {
        around_[ty * tiles_x_ + tx].push_back(p);
      }
    }
  }
  // The tiles with points enough to judge (8 inside, 24 around), and how many of them stand off
  // the leaf's surface (by more than the median step threshold of their points inside; OnSurface
  // with `slack_px`).
  std::pair<int, int> Judge(double slack_px) {
    int judged = 0, off = 0;
    for (size_t t = 0; t < inside_.size(); ++t) {
      if (inside_[t].size() < 8 || around_[t].size() < 24) continue;
      ++judged;
      off += !OnSurface(around_[t], inside_[t], Median(&steps_[t]), slack_px);
    }
    return {judged, off};
  }

 private:
  int tile_, tiles_x_, tiles_y_;
  std::vector<std::vector<cv::Point3f>> inside_, around_;
  std::vector<std::vector<float>> steps_;
};

// Fills the holes of `leaf` that show no other surface, and returns how many it keeps. A hole
// with heights is kept when they differ from the leaf's around it (another surface shows
// through), filled when they do not (an island the rim test cut out). The two are compared
// piece by piece along the hole's edge (32 px tiles: the leaf within 12 px outside the edge, a
// quadric, against the hole 3 to 10 px inside it, past the decoder's blur of the step), so a
// hole across a ripple is judged by the surface beside each part of it; the hole is kept when
// most pieces stand off. A hole without heights (the projector's light did not reach it: a
// shadow on the leaf, or what lies under a raised leaf) is kept when it looks unlike the leaf
// around it in the texture (by more than 3% of the paper's brightness), filled otherwise.
int FillHoles(const cv::Mat& z, const cv::Mat& gray, const cv::Mat& threshold, double bright,
              cv::Mat* leaf) {
  cv::Mat outside = ~*leaf, labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(outside, labels, stats, centroids, 4, CV_32S);
  const cv::Rect all(0, 0, z.cols, z.rows);
  constexpr int kRing = 12, kTile = 32, kNear = 3, kFar = 10;
  const cv::Mat disc = cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * kRing + 1, 2 * kRing + 1});
  std::vector<uint8_t> fill(n, 0), kept_label(n, 0);
  // Each hole judged on its own, the holes shared among the threads.
  cv::parallel_for_(cv::Range(1, std::max(n, 1)), [&](const cv::Range& range) {
    for (int l = range.start; l < range.end; ++l) {
      const cv::Rect box(stats.at<int>(l, cv::CC_STAT_LEFT), stats.at<int>(l, cv::CC_STAT_TOP),
                         stats.at<int>(l, cv::CC_STAT_WIDTH), stats.at<int>(l, cv::CC_STAT_HEIGHT));
      const int area = stats.at<int>(l, cv::CC_STAT_AREA);
      if (box.x == 0 || box.y == 0 || box.br().x == z.cols || box.br().y == z.rows) continue;
      if (area < 9) {
        fill[l] = 1;
        continue;
      }
      const cv::Rect near = (box + cv::Size(2 * kRing, 2 * kRing) - cv::Point(kRing, kRing)) & all;
      const cv::Mat hole = labels(near) == l;
      cv::Mat ring, depth;
      cv::dilate(hole, ring, disc);
      ring &= (*leaf)(near);
      cv::distanceTransform(hole, depth, cv::DIST_L2, 3);
      double deepest = 0;
      cv::minMaxLoc(depth, nullptr, &deepest);
      // A hole too narrow for the band: all of it.
      const float lo = deepest >= kFar ? kNear : 0, hi = deepest >= kFar ? kFar : 1e9f;
      TileComparison tiles(near.size(), kTile);
      std::vector<float> look_in, look_around;
      int valid = 0;
      for (int v = 0; v < near.height; ++v) {
        const uint8_t* in_hole = hole.ptr<uint8_t>(v);
        const uint8_t* in_ring = ring.ptr<uint8_t>(v);
        const float* d = depth.ptr<float>(v);
        for (int u = 0; u < near.width; ++u) {
          if (!in_hole[u] && !in_ring[u]) continue;
          const int uu = u + near.x, vv = v + near.y;
          const float h = z.at<float>(vv, uu);
          (in_hole[u] ? look_in : look_around).push_back(gray.at<uint8_t>(vv, uu));
          if (!Valid(h)) continue;
          if (in_hole[u]) {
            ++valid;
            if (d[u] >= lo && d[u] <= hi) {
              tiles.Inside(u, v, cv::Point3f(uu, vv, h), threshold.at<float>(vv, uu));
            }
          } else {
            tiles.Around(u, v, cv::Point3f(uu, vv, h));
          }
        }
      }
      bool island;
      if (valid >= area / 2) {
        const auto [judged, off] = tiles.Judge(/*slack_px=*/0);
        island = 2 * off <= judged;
      } else {
        island = std::fabs(Median(&look_in) - Median(&look_around)) <= 0.03 * bright;
      }
      fill[l] = island;
      kept_label[l] = !island;
    }
  });
  const int kept = static_cast<int>(std::count(kept_label.begin(), kept_label.end(), 1));
  // The holes kept, closed over leaf bridges narrower than the rim's blur (4 px: two pieces of
  // one hole the flood split are one hole), and counted.
  cv::Mat holes = cv::Mat::zeros(z.size(), CV_8U);
  for (int v = 0; v < z.rows; ++v) {
    const int* lab = labels.ptr<int>(v);
    uint8_t* out = leaf->ptr<uint8_t>(v);
    uint8_t* hole = holes.ptr<uint8_t>(v);
    for (int u = 0; u < z.cols; ++u) {
      if (fill[lab[u]]) out[u] = 255;
      if (lab[u] > 0 && !fill[lab[u]] && kept_label[lab[u]]) hole[u] = 255;
    }
  }
  if (kept == 0) return 0;
  cv::morphologyEx(holes, holes, cv::MORPH_CLOSE,
                   cv::getStructuringElement(cv::MORPH_ELLIPSE, {5, 5}));
  leaf->setTo(0, holes);
  cv::Mat pieces;
  return cv::connectedComponents(holes, pieces, 8, CV_32S) - 1;
}

// The blocks of the half-resolution grid `half` that lie outside the leaf and its holes
// (reached from the grid's border without crossing the leaf) but within its convex hull: the
// bays of its outline, and between the two pages of a spread.
cv::Mat BaysOfLeaf(const cv::Mat& leaf, cv::Size half) {
  cv::Mat blocks(half.height + 2, half.width + 2, CV_8U, cv::Scalar(0));
  cv::resize(leaf(cv::Rect(0, 0, 2 * half.width, 2 * half.height)),
             blocks(cv::Rect(1, 1, half.width, half.height)), half, 0, 0, cv::INTER_NEAREST);
  std::vector<std::vector<cv::Point>> outlines;
  cv::findContours(blocks, outlines, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
  std::vector<cv::Point> points, hull;
  for (const auto& outline : outlines) points.insert(points.end(), outline.begin(), outline.end());
  cv::Mat bays = cv::Mat::zeros(blocks.size(), CV_8U);
  if (points.size() < 3) return bays(cv::Rect(1, 1, half.width, half.height));
  cv::convexHull(points, hull);
  cv::fillConvexPoly(bays, hull, cv::Scalar(255));
  cv::floodFill(blocks, cv::Point(0, 0), cv::Scalar(128), nullptr, 0, 0, 4);
  bays &= blocks == 128;
  return bays(cv::Rect(1, 1, half.width, half.height));
}

// Surfaces outside the leaf whose heights continue it join it (`kind` 2 -> 1), and how many:
// on a page's wall turned from the projector, ink the decoder cannot read and the noise of
// grazing light around it cut the strip beyond from the page, which the rim test then took for
// another surface. Each surface mostly in the leaf's bays (`bays`, from BaysOfLeaf: not under
// it, nor beyond its outline), near the leaf's surfaces (within the rims' reach), small beside
// them (a twentieth of their area at most: a support, a frame or the table is not a piece cut
// off the leaf) and not touching the view's border is judged as FillHoles judges a hole, piece by
// piece (32 px tiles) where the two come near: a quadric fitted to the leaf there, against the
// surface's heights, within the cautious step threshold, less what the slope gives over a pixel (a
// fit extrapolated across the rims is not better than that, and on a wall nearly edge-on to the
// camera a pixel is half a millimetre of height). It joins when most pieces lie on the leaf's
// surface. Works on the half-resolution surface labels (`half`, their `stats`).
int JoinContinuations(const cv::Mat& z, const cv::Mat& gray, double bright, double step,
                      const OutlineOptions& options, const cv::Mat& half, const cv::Mat& stats,
                      const cv::Mat& bays, std::vector<uint8_t>* kind) {
  const int count = static_cast<int>(kind->size());
  // Near: within the rims' reach (a square of that many blocks either way).
  const int reach = options.scale_px + options.gap_px + 4;
  const cv::Mat square = cv::Mat::ones(2 * reach + 1, 2 * reach + 1, CV_8U);
  cv::Mat near_leaf(half.size(), CV_8U);
  for (int v = 0; v < half.rows; ++v) {
    const int* c = half.ptr<int>(v);
    uint8_t* out = near_leaf.ptr<uint8_t>(v);
    for (int u = 0; u < half.cols; ++u) out[u] = (*kind)[c[u]] == 1 ? 255 : 0;
  }
  const int leaf_blocks = cv::countNonZero(near_leaf);
  cv::dilate(near_leaf, near_leaf, square);
  std::vector<uint8_t> near(count, 0);
  std::vector<int> in_bays(count, 0);
  for (int v = 0; v < half.rows; ++v) {
    const int* c = half.ptr<int>(v);
    const uint8_t* by = near_leaf.ptr<uint8_t>(v);
    const uint8_t* bay = bays.ptr<uint8_t>(v);
    for (int u = 0; u < half.cols; ++u) {
      near[c[u]] |= by[u];
      in_bays[c[u]] += bay[u] != 0;
    }
  }
  const cv::Rect all(0, 0, half.cols, half.rows);
  constexpr int kTile = 16, kMinBlocks = 16;  // Blocks: 32 px tiles; 64 px surfaces.
  std::vector<int> candidates;
  for (int l = 1; l < count; ++l) {
    const cv::Rect box(stats.at<int>(l, cv::CC_STAT_LEFT), stats.at<int>(l, cv::CC_STAT_TOP),
                       stats.at<int>(l, cv::CC_STAT_WIDTH), stats.at<int>(l, cv::CC_STAT_HEIGHT));
    const int area = stats.at<int>(l, cv::CC_STAT_AREA);
    if ((*kind)[l] == 2 && near[l] && 2 * in_bays[l] >= area && area >= kMinBlocks &&
        area * 20 <= leaf_blocks && box.x > 0 && box.y > 0 && box.br().x < half.cols &&
        box.br().y < half.rows) {
      candidates.push_back(l);
    }
  }
  std::vector<uint8_t> joins(count, 0);
  cv::parallel_for_(cv::Range(0, static_cast<int>(candidates.size())), [&](const cv::Range& r) {
    for (int i = r.start; i < r.end; ++i) {
      const int l = candidates[i];
      const cv::Rect box =
          (cv::Rect(stats.at<int>(l, cv::CC_STAT_LEFT), stats.at<int>(l, cv::CC_STAT_TOP),
                    stats.at<int>(l, cv::CC_STAT_WIDTH), stats.at<int>(l, cv::CC_STAT_HEIGHT)) +
           cv::Size(2 * reach, 2 * reach) - cv::Point(reach, reach)) &
          all;
      const cv::Rect pixels(2 * box.x, 2 * box.y, 2 * box.width, 2 * box.height);
      const cv::Mat cautious = StepThreshold(gray(pixels), bright, step, options.scale_px,
                                             /*darkest=*/true);
      cv::Mat near_it;
      cv::dilate(half(box) == l, near_it, square);
      TileComparison tiles(box.size(), kTile);
      for (int v = 0; v < box.height; ++v) {
        const int* c = half.ptr<int>(v + box.y);
        const uint8_t* by_leaf = near_leaf.ptr<uint8_t>(v + box.y);
        const uint8_t* by_it = near_it.ptr<uint8_t>(v);
        for (int u = 0; u < box.width; ++u) {
          const int lab = c[u + box.x];
          const bool in = lab == l && by_leaf[u + box.x];
          const bool by = lab > 0 && (*kind)[lab] == 1 && by_it[u];
          if (!in && !by) continue;
          const int uu = 2 * (u + box.x), vv = 2 * (v + box.y);
          const float h = z.at<float>(vv, uu);
          if (!Valid(h)) continue;
          if (in) {
            tiles.Inside(u, v, cv::Point3f(uu, vv, h),
                         cautious.at<float>(vv - pixels.y, uu - pixels.x));
          } else {
            tiles.Around(u, v, cv::Point3f(uu, vv, h));
          }
        }
      }
      const auto [judged, off] = tiles.Judge(/*slack_px=*/1);
      joins[l] = judged > 0 && 2 * off < judged;
    }
  });
  int joined = 0;
  for (int l = 1; l < count; ++l) {
    if (joins[l]) {
      (*kind)[l] = 1;
      ++joined;
    }
  }
  return joined;
}

// Share of the leaf's rim pixels that are set apart from what is beside them: on a rim (a
// step or a silhouette), beside pixels without a height (shadow, or the leaf seen edge-on), or
// at the image border.
double RimConfidence(const cv::Mat& leaf, const cv::Mat& strength, const cv::Mat& z) {
  cv::Mat eroded;
  cv::erode(leaf, eroded, cv::Mat());
  const cv::Mat rim = leaf & ~eroded;
  cv::Mat apart = strength > 0.5f;
  cv::dilate(apart, apart, cv::Mat(), cv::Point(-1, -1), 3);
  cv::Mat no_data = z < -1e3f;
  cv::dilate(no_data, no_data, cv::Mat(), cv::Point(-1, -1), 2);
  const int total = cv::countNonZero(rim);
  if (total == 0) return 0;
  return static_cast<double>(cv::countNonZero(rim & (apart | no_data))) / total;
}

// Whether the leaf runs off the view: leaf pixels within `border` of the image edge.
bool TouchesBorder(const cv::Mat& leaf, int border) {
  const cv::Rect inner(border, border, leaf.cols - 2 * border, leaf.rows - 2 * border);
  if (inner.width <= 0 || inner.height <= 0) return true;
  return cv::countNonZero(leaf) > cv::countNonZero(leaf(inner));
}

// An open book's gutter: a straight valley down the leaf from which the surface rises at least
// `options.gutter_rise_mm` on both sides, a crease (within gutter_width_mm each side rises
// gutter_crease_mm, or is hidden from view), not a trough. Splits the leaf into its left and
// right pages; false if there is no such valley.
bool SplitAtGutter(const cv::Mat& points, const cv::Mat& z, const cv::Mat& leaf,
                   const OutlineOptions& options, cv::Vec4f* line, cv::Mat* left, cv::Mat* right) {
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

}  // namespace

bool OutlineOptions::Check(std::string* why) const {
  if (!(step_mm > 0) || gap_px < 0 || gap_px > 10 || !(min_area > 0 && min_area < 1) ||
      border_px < 0 || !(gutter_rise_mm > 0) || !(gutter_width_mm > 0) ||
      !(gutter_crease_mm >= 0)) {
    *why =
        "step_mm, gutter_rise_mm and gutter_width_mm must be > 0, gutter_crease_mm >= 0, "
        "gap_px in [0, 10], min_area in (0, 1)";
    return false;
  }
  return true;
}

Outline FindLeaf(const cv::Mat& points, const cv::Mat& texture, const OutlineOptions& options) {
  Outline out;
  std::string why;
  if (!options.Check(&why)) {
    out.status = Status::Error("outline options: " + why);
    return out;
  }
  if (points.type() != CV_32FC3 || points.empty()) {
    out.status = Status::Error("outline input: the point map must be CV_32FC3");
    return out;
  }
  if (texture.size() != points.size()) {
    out.status = Status::Error("the texture is " + SizeText(texture.size()) + ", the point map " +
                               SizeText(points.size()));
    return out;
  }
  const cv::Size size = points.size();
  const double step = options.step_mm;
  cv::Mat gray = texture;
  if (gray.channels() == 3) cv::cvtColor(gray, gray, cv::COLOR_BGR2GRAY);
  if (gray.depth() != CV_8U) gray.convertTo(gray, CV_8U, 1.0 / 257);
  cv::Mat zn;
  const cv::Mat z = SmoothHeights(points, &zn);
  // Rim strength in units of the step that counts as a rim there: `step` where the surface is
  // bright (paper), more over dark ink, whose heights are as noisy as its signal is weak.
  cv::Mat strength = RimStrength(points, zn, options.scale_px, options.max_slope_deg);
  const double bright = BrightLevel(gray);
  StepThreshold(gray, bright, step, options.scale_px, /*darkest=*/false, &strength);
  // Surfaces: pixels with a height, away from every rim (gaps in a rim closed), as components.
  cv::Mat rims;
  cv::dilate(strength > 1, rims, cv::getStructuringElement(cv::MORPH_CROSS, {3, 3}),
             cv::Point(-1, -1), options.gap_px);
  const cv::Mat surface = (z > -1e3f) & ~rims;
  // Labelled at half resolution (a 2 x 2 block is surface when all of it is; rims are several
  // pixels wide, so no surface joins another by it), then brought back to full size.
  cv::Mat blocks, half_components, stats, centroids;
  cv::erode(surface, blocks, cv::Mat::ones(2, 2, CV_8U), cv::Point(0, 0));
  cv::resize(blocks, blocks, cv::Size(size.width / 2, size.height / 2), 0, 0, cv::INTER_NEAREST);
  const int count =
      cv::connectedComponentsWithStats(blocks, half_components, stats, centroids, 4, CV_32S);
  // A pixel's component: its block's (none in an odd last row or column).
  const cv::Size half = half_components.size();
  auto component = [&](int v, int u) {
    return v / 2 < half.height && u / 2 < half.width ? half_components.at<int>(v / 2, u / 2) : 0;
  };
  // The leaf: the surfaces that cover much of the seed region (the hint, or the centre of the
  // view; an open book's two pages share it).
  cv::Rect seed = options.hint & cv::Rect(0, 0, size.width, size.height);
  if (seed.area() == 0) {
    seed = cv::Rect(size.width * 2 / 5, size.height * 2 / 5, size.width / 5, size.height / 5);
  }
  std::vector<int> votes(count, 0);
  for (int v = seed.y; v < seed.y + seed.height; ++v) {
    for (int u = seed.x; u < seed.x + seed.width; ++u) ++votes[component(v, u)];
  }
  votes[0] = 0;
  const int most = *std::max_element(votes.begin(), votes.end());
  // Seeds for the flood: 1 the leaf's surfaces, 2 every other surface.
  std::vector<uint8_t> kind(count, 0);
  for (int l = 1; l < count; ++l) {
    const bool leafy =
        most > 0 && votes[l] >= std::max(1, most / 4) && votes[l] >= seed.area() / 10;
    kind[l] = leafy ? 1 : 2;  // 2: every other surface, however small (what shows through a hole).
  }
  int leaf_area = 0;
  for (int l = 1; l < count; ++l) {
    if (kind[l] == 1) leaf_area += 4 * stats.at<int>(l, cv::CC_STAT_AREA);
  }
  // Each pixel of a surface labelled with its kind.
  cv::Mat labels(size, CV_8U);
  auto label_surfaces = [&] {
    cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& range) {
      for (int v = range.start; v < range.end; ++v) {
        uint8_t* out = labels.ptr<uint8_t>(v);
        const uint8_t* in = surface.ptr<uint8_t>(v);
        if (v / 2 >= half.height) {
          std::fill_n(out, size.width, 0);
          continue;
        }
        const int* c = half_components.ptr<int>(v / 2);
        for (int u = 0; u < size.width; ++u) {
          out[u] = in[u] && u / 2 < half.width ? kind[c[u / 2]] : 0;
        }
      }
    });
  };
  const double area_min = options.min_area * size.area();
  cv::Mat leaf;
  if (leaf_area >= area_min) {
    // The leaf grows from its seed by no more than a rim's width: the floods and the holes are
    // worked out in the seed's box with a margin.
    const int margin = 4 * (options.scale_px + options.gap_px) + 4;
    cv::Mat bays;  // The bays of the leaf as first found: where surfaces may join it.
    for (int pass = 0;; ++pass) {
      label_surfaces();
      cv::Rect box = cv::boundingRect(labels == 1);
      box = cv::Rect(box.x - margin, box.y - margin, box.width + 2 * margin,
                     box.height + 2 * margin) &
            cv::Rect(0, 0, size.width, size.height);
      cv::Mat box_labels = labels(box).clone();
      Flood(strength(box), z(box), &box_labels);
      leaf = cv::Mat::zeros(size, CV_8U);
      leaf(box).setTo(255, box_labels == 1);
      if (pass == 3) break;
      // Surfaces outside the leaf whose heights continue it join it, and the leaf is flooded
      // again (a few times: a surface joined can bring the next within reach).
      if (pass == 0) bays = BaysOfLeaf(leaf, half);
      if (JoinContinuations(z, gray, bright, step, options, half_components, stats, bays, &kind) ==
          0) {
        break;
      }
    }
    const cv::Rect holes_box = (cv::boundingRect(leaf) + cv::Size(4, 4) - cv::Point(2, 2)) &
                               cv::Rect(0, 0, size.width, size.height);
    cv::Mat box_leaf = leaf(holes_box);
    const cv::Mat cautious =
        StepThreshold(gray(holes_box), bright, step, options.scale_px, /*darkest=*/true);
    out.holes = FillHoles(z(holes_box), gray(holes_box), cautious, bright, &box_leaf);
    out.confidence = RimConfidence(leaf(holes_box), strength(holes_box), z(holes_box));
    out.touches_border = TouchesBorder(leaf, options.border_px);
    out.method = "shape";
  }
  // The brightness rule: the fallback when the shape finds no leaf, or one that spreads over
  // the view with nothing setting it apart, where a bright page on a dark surround is clear.
  if (leaf.empty() || (out.touches_border && out.confidence < 0.5)) {
    const cv::Mat bright = SegmentPage(texture);
    if (cv::countNonZero(bright) >= area_min && !TouchesBorder(bright, options.border_px)) {
      leaf = bright.clone();
      out.method = "brightness";
      out.holes = 0;
      out.confidence = RimConfidence(leaf, strength, z);
      out.touches_border = false;
    } else if (leaf.empty()) {
      out.status = Status::Error(
          "no leaf found: no surface set apart by its rim around the centre of the view, and "
          "no bright page on a darker surround");
      return out;
    }
  }
  out.mask = leaf;
  cv::Mat left, right;
  if (options.find_spread && SplitAtGutter(points, z, leaf, options, &out.gutter, &left, &right)) {
    out.pages = {left, right};
  } else {
    out.pages = {leaf};
  }
  out.status = Status::Ok();
  return out;
}

}  // namespace vellum::baseline
