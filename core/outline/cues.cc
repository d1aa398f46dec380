#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "core/outline/steps.h"

namespace vellum::outline {
namespace {

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

// One row of RimStrength's step test: for each pixel, how far apart the surface's two sides stay
// near it: the surface `a` and `b` = 2a pixels before the pixel and after it, each extrapolated
// linearly, along the row (`row`), the column and both diagonals (the rows b and a above, a and b
// below). Where the two lines meet within a pixels of the pixel, the surface is continuous there
// (a crease or a bend: no rim); otherwise the nearer of their gaps at -a and +a. A plain function
// over pointers, so the compiler vectorizes it.
void StepDisagreement(const float* row, const float* rb, const float* ra, const float* sa,
                      const float* sb, int a, int b, int w, float* __restrict out) {
  const float slope = 2.0f * a;
  // fb, nb: the surface b and a before; na, fa: a and b after. The gap R(x) - L(x) between the
  // line after (through na, fa) and the line before (through fb, nb) at x = -a and x = +a:
  // 3 na - 2 fa - nb and na - 3 nb + 2 fb. Less what a steep, curved surface gives without any
  // step (its samples thin out as it turns from the camera: half the height it changes per pixel
  // there).
  auto disagree = [slope](float fb, float nb, float na, float fa) {
    const float at_before = 3 * na - 2 * fa - nb, at_after = na - 3 * nb + 2 * fb;
    const float lo =
        std::fabs(at_before) < std::fabs(at_after) ? std::fabs(at_before) : std::fabs(at_after);
    const float gap = at_before * at_after > 0.0f ? lo : 0.0f;  // Opposite signs: they meet.
    const float d = gap - 0.5f * std::fabs(na - nb) / slope;
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

}  // namespace

// Heights of the point map, each the median of its own and the means of its opposite
// neighbours (left-right, up-down and both diagonals) where both have a point: an isolated
// outlier is dropped, a step stays sharp, and a steep slope with missing points is not biased (a
// plain 3 x 3 median over the points present picks a lower or higher neighbour where points are
// missing on one side: on a 50 degree ripple, a third of a millimetre, a false rim). kNoData
// where the pixel has no point and fewer than two pairs do; `nan` (if given) gets the same
// heights with NaN there instead.
cv::Mat SmoothHeights(const cv::Mat& points, cv::Mat* nan) {
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
                      cv::Mat* in_steps) {
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

Cues MeasureCues(const cv::Mat& points, const cv::Mat& texture, const OutlineOptions& options) {
  Cues c;
  if (texture.channels() == 3) {
    c.colour = texture;
    if (c.colour.depth() != CV_8U) c.colour.convertTo(c.colour, CV_8U, 1.0 / 257);
    cv::cvtColor(c.colour, c.gray, cv::COLOR_BGR2GRAY);
  } else {
    c.gray = texture;
    if (c.gray.depth() != CV_8U) c.gray.convertTo(c.gray, CV_8U, 1.0 / 257);
    cv::cvtColor(c.gray, c.colour, cv::COLOR_GRAY2BGR);
  }
  c.z = SmoothHeights(points, &c.zn);
  // Rim strength in units of the step that counts as a rim there: `step` where the surface is
  // bright (paper), more over dark ink, whose heights are as noisy as its signal is weak.
  c.rim = RimStrength(points, c.zn, options.scale_px, options.max_slope_deg);
  c.bright = BrightLevel(c.gray);
  StepThreshold(c.gray, c.bright, options.step_mm, options.scale_px, /*darkest=*/false, &c.rim);
  // The texture's edges: the gradient of its brightness (a Gaussian of a pixel, then Sobel), as
  // a share of the paper's brightness per pixel, in units of edge_contrast.
  cv::Mat smooth, gx, gy;
  cv::GaussianBlur(c.gray, smooth, cv::Size(5, 5), 1.0);
  cv::Sobel(smooth, gx, CV_32F, 1, 0, 3, 1.0 / 8);
  cv::Sobel(smooth, gy, CV_32F, 0, 1, 3, 1.0 / 8);
  cv::magnitude(gx, gy, c.edge);
  c.edge *= 1.0 / (c.bright * options.edge_contrast);
  return c;
}

}  // namespace vellum::outline
