#include "core/geometry/flying.h"

#include <atomic>
#include <cmath>
#include <limits>
#include <opencv2/core/utility.hpp>

namespace vellum {

int RejectFlyingPoints(cv::Mat* points, double max_off_mm, int reach) {
  CV_Assert(points->type() == CV_32FC3 && reach >= 1);
  const cv::Mat& p = *points;
  const int w = p.cols, h = p.rows;
  const float limit2 = static_cast<float>(max_off_mm * max_off_mm);
  cv::Mat flying = cv::Mat::zeros(p.size(), CV_8U);
  const ptrdiff_t stride = static_cast<ptrdiff_t>(p.step1() / 3);  // Points from a row to the next.
  // Each direction's step through the map (du, dv below): +1 column, +1 row, and the diagonals.
  const ptrdiff_t offset[4] = {1, stride, stride + 1, 1 - stride};
  std::atomic<int> total{0};
  cv::parallel_for_(cv::Range(0, h), [&](const cv::Range& range) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    int found = 0;
    for (int v = range.start; v < range.end; ++v) {
      const cv::Vec3f* row = p.ptr<cv::Vec3f>(v);
      uint8_t* out = flying.ptr<uint8_t>(v);
      // Rows and columns 3 * reach from every border: each look lies inside the map.
      const bool inner_row = v >= 3 * reach && v < h - 3 * reach;
      for (int u = 0; u < w; ++u) {
        const cv::Vec3f at0 = row[u];
        if (!std::isfinite(at0[2])) continue;
        if (inner_row && u >= 3 * reach && u < w - 3 * reach) {
          // Most points: on the surface before them along every direction, two looks each
          // without bounds, no root. The same test as side(-1) and off() below: a miss within
          // the limit is never off, and a point on one side's surface everywhere is kept.
          bool on_everywhere = true;
          for (int d = 0; d < 4 && on_everywhere; ++d) {
            const cv::Vec3f near = row[u - reach * offset[d]], far = row[u - 2 * reach * offset[d]];
            const cv::Vec3f miss = at0 - (2 * near - far);
            on_everywhere =
                std::isfinite(near[2]) && std::isfinite(far[2]) && miss.dot(miss) <= limit2;
          }
          if (on_everywhere) continue;
        }
        const int du[4] = {1, 0, 1, 1}, dv[4] = {0, 1, 1, -1};
        int directions = 0;
        for (int d = 0; d < 4; ++d) {
          auto at = [&](int k) -> cv::Vec3f {
            const int uu = u + k * du[d], vv = v + k * dv[d];
            if (uu < 0 || vv < 0 || uu >= w || vv >= h) return {nan, nan, nan};
            return p.at<cv::Vec3f>(vv, uu);
          };
          // One side's surface, `sign` = +1 or -1: the miss of its linear extrapolation to the
          // point, and its bend (the second difference one step further out), which a
          // curved surface gives the linear extrapolation and a mixed pixel does not.
          struct Side {
            bool seen;
            cv::Vec3f miss;
            float bend2;
          };
          auto side = [&](int sign) {
            const cv::Vec3f near = at(sign * reach), far = at(sign * 2 * reach);
            Side s{std::isfinite(near[2]) && std::isfinite(far[2]), {}, 0.0f};
            if (!s.seen) return s;
            s.miss = at0 - (2 * near - far);
            // Within the limit the bend cannot matter: most points stop here, two looks a side.
            if (s.miss.dot(s.miss) <= limit2) return s;
            const cv::Vec3f farther = at(sign * 3 * reach);
            if (std::isfinite(farther[2])) {
              const cv::Vec3f bend = near - 2 * far + farther;
              s.bend2 = bend.dot(bend);
            }
            return s;
          };
          // Off a side: past the limit plus that side's own bend.
          auto off = [&](const Side& s) {
            if (!s.seen) return true;
            const float allowance = std::sqrt(limit2) + std::sqrt(s.bend2);
            return s.miss.dot(s.miss) > allowance * allowance;
          };
          // On either side's surface is enough: the other is not looked at.
          const Side before = side(-1);
          if (before.seen && !off(before)) continue;
          const Side after = side(+1);
          if (!before.seen && !after.seen) continue;
          if (!off(after)) continue;
          // Off both sides' surfaces is enough. Where a side has no surface, the point must be
          // far off the other (three times the limit), or off along two directions: a mixed
          // pixel is off across its silhouette (straight and both diagonals), while a good point
          // at a leaf's corner is a little off only along the diagonal that leaves the leaf.
          const Side& seen = before.seen ? before : after;
          const bool sure = (before.seen && after.seen) || seen.miss.dot(seen.miss) > 9 * limit2;
          if (!sure && ++directions < 2) continue;
          out[u] = 1;
          ++found;
          break;
        }
      }
    }
    total += found;
  });
  points->setTo(cv::Scalar::all(std::numeric_limits<float>::quiet_NaN()), flying);
  return total;
}

}  // namespace vellum
