// MakeBlocks and FitSurround (steps.h).
#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "core/outline/steps.h"

namespace vellum {

bool SurroundOptions::Check(std::string* why) const {
  if (max_planes < 1 || max_planes > 8 || !(min_share > 0 && min_share < 1) ||
      !(tolerance_mm > 0) || !(max_tilt_deg > 0 && max_tilt_deg < 90) ||
      !(max_relative_tilt_deg > 0 && max_relative_tilt_deg < 90)) {
    *why =
        "surround: max_planes in [1, 8], min_share in (0, 1), tolerance_mm > 0, max_tilt_deg and "
        "max_relative_tilt_deg in (0, 90)";
    return false;
  }
  return true;
}

namespace outline {

int BlockSize(cv::Size view, int target) {
  return std::max(2, static_cast<int>(std::lround(std::max(view.width, view.height) /
                                                  static_cast<double>(std::max(1, target)))));
}

Blocks MakeBlocks(const Cues& cues, const cv::Mat& points, int size) {
  Blocks b;
  b.size = size;
  b.grid = cv::Size(points.cols / size, points.rows / size);
  const cv::Size g = b.grid;
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  b.valid.create(g, CV_32F);
  b.x.create(g, CV_32F);
  b.y.create(g, CV_32F);
  b.z.create(g, CV_32F);
  b.colour.create(g, CV_8UC3);
  b.rim.create(g, CV_32F);
  b.edge.create(g, CV_32F);
  const float area = static_cast<float>(size * size);
  cv::parallel_for_(cv::Range(0, g.height), [&](const cv::Range& range) {
    for (int by = range.start; by < range.end; ++by) {
      for (int bx = 0; bx < g.width; ++bx) {
        int n = 0;
        double sx = 0, sy = 0, sz = 0;
        int colour[3] = {0, 0, 0};
        float rim = 0, edge = 0;
        for (int v = by * size; v < (by + 1) * size; ++v) {
          const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
          const float* z = cues.z.ptr<float>(v);
          const cv::Vec3b* c = cues.colour.ptr<cv::Vec3b>(v);
          const float* r = cues.rim.ptr<float>(v);
          const float* e = cues.edge.ptr<float>(v);
          for (int u = bx * size; u < (bx + 1) * size; ++u) {
            for (int k = 0; k < 3; ++k) colour[k] += c[u][k];
            rim = std::max(rim, r[u]);
            edge = std::max(edge, e[u]);
            if (!Valid(z[u]) || !std::isfinite(p[u][0])) continue;
            ++n;
            sx += p[u][0];
            sy += p[u][1];
            sz += z[u];
          }
        }
        b.valid.at<float>(by, bx) = n / area;
        b.x.at<float>(by, bx) = n ? static_cast<float>(sx / n) : kNaN;
        b.y.at<float>(by, bx) = n ? static_cast<float>(sy / n) : kNaN;
        b.z.at<float>(by, bx) = n ? static_cast<float>(sz / n) : kNaN;
        b.colour.at<cv::Vec3b>(by, bx) = cv::Vec3b(cv::saturate_cast<uint8_t>(colour[0] / area),
                                                   cv::saturate_cast<uint8_t>(colour[1] / area),
                                                   cv::saturate_cast<uint8_t>(colour[2] / area));
        b.rim.at<float>(by, bx) = rim;
        b.edge.at<float>(by, bx) = edge;
      }
    }
  });
  // The noise of a block's height at the blocks' own scale: how far it stands from the mean of
  // its measured neighbours (a plane, and nearly a gently curved surface, gives 0), averaged over
  // 5 x 5 blocks (the mean absolute value of a Gaussian is 0.8 sigma).
  cv::Mat off(g, CV_32F, cv::Scalar(0)), counted(g, CV_32F, cv::Scalar(0));
  for (int by = 1; by + 1 < g.height; ++by) {
    for (int bx = 1; bx + 1 < g.width; ++bx) {
      const float z = b.z.at<float>(by, bx);
      if (std::isnan(z)) continue;
      float sum = 0;
      int n = 0;
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const float w = b.z.at<float>(by + dy, bx + dx);
          if ((dx || dy) && !std::isnan(w)) sum += w, ++n;
        }
      }
      if (n < 6) continue;
      off.at<float>(by, bx) = std::fabs(z - sum / n);
      counted.at<float>(by, bx) = 1;
    }
  }
  cv::boxFilter(off, off, -1, cv::Size(5, 5), cv::Point(-1, -1), false);
  cv::boxFilter(counted, counted, -1, cv::Size(5, 5), cv::Point(-1, -1), false);
  b.noise.create(g, CV_32F);
  for (int by = 0; by < g.height; ++by) {
    for (int bx = 0; bx < g.width; ++bx) {
      const float n = counted.at<float>(by, bx);
      b.noise.at<float>(by, bx) = n > 0 ? 1.25f * off.at<float>(by, bx) / n : kNaN;
    }
  }
  return b;
}

namespace {

// The solidly measured blocks: each and the blocks within two of it all measured (the edge of
// the projector's light or of a shadow biases the decoder's heights there).
cv::Mat SolidBlocks(const Blocks& blocks) {
  cv::Mat solid = blocks.valid >= 0.9f;
  cv::erode(solid, solid, cv::Mat::ones(5, 5, CV_8U), cv::Point(-1, -1), 1, cv::BORDER_CONSTANT,
            cv::Scalar(0));
  return solid;
}

// How far off a plane a sample of this noise may lie and be on it: the option's tolerance, or
// three times the noise where that is more.
double OnPlaneTolerance(const SurroundOptions& options, float noise) {
  return std::max<double>(options.tolerance_mm, 3 * noise);
}

// Least-squares plane z = a x + b y + c through `points` (x, y, z).
bool FitPlane(const std::vector<cv::Vec3f>& points, Plane* plane) {
  if (points.size() < 3) return false;
  cv::Matx33d ata = cv::Matx33d::zeros();
  cv::Vec3d atb(0, 0, 0);
  double cx = 0, cy = 0;
  for (const cv::Vec3f& p : points) cx += p[0], cy += p[1];
  cx /= points.size(), cy /= points.size();
  for (const cv::Vec3f& p : points) {
    const cv::Vec3d row(p[0] - cx, p[1] - cy, 1);
    ata += row * row.t();
    atb += row * static_cast<double>(p[2]);
  }
  cv::Vec3d x;
  if (!cv::solve(ata, atb, x, cv::DECOMP_SVD)) return false;
  plane->a = x[0];
  plane->b = x[1];
  plane->c = x[2] - x[0] * cx - x[1] * cy;
  return true;
}

// The plane with the most of `samples[candidates]` within tolerance (the option's, or three times
// a sample's noise where that is more), level within max_tilt_deg, by RANSAC from `rng`, refined
// by least squares on its inliers; false unless it holds at least `least`.
bool RansacPlane(const std::vector<cv::Vec3f>& samples, const std::vector<float>& noise,
                 const std::vector<int>& candidates, size_t least, const SurroundOptions& options,
                 cv::RNG* rng, Plane* plane, std::vector<int>* inliers) {
  if (candidates.size() < std::max<size_t>(3, least)) return false;
  const double max_slope = std::tan(options.max_tilt_deg * M_PI / 180);
  auto tolerance = [&](int k) { return OnPlaneTolerance(options, noise[k]); };
  auto collect = [&](const Plane& p, std::vector<int>* in) {
    in->clear();
    for (int m : candidates) {
      if (std::fabs(samples[m][2] - p.At(samples[m][0], samples[m][1])) <= tolerance(m)) {
        in->push_back(m);
      }
    }
  };
  const int count = static_cast<int>(candidates.size());
  Plane best;
  std::vector<int> best_in, in;
  for (int it = 0; it < 300; ++it) {
    const int i = candidates[rng->uniform(0, count)], j = candidates[rng->uniform(0, count)],
              k = candidates[rng->uniform(0, count)];
    Plane p;
    if (i == j || j == k || i == k || !FitPlane({samples[i], samples[j], samples[k]}, &p) ||
        std::hypot(p.a, p.b) > max_slope) {
      continue;
    }
    collect(p, &in);
    if (in.size() > best_in.size()) best_in.swap(in), best = p;
  }
  // Refined on its inliers, twice, the second time on those within three times the first fit's
  // own scatter (a board's edge, its heights spread by the decoder's fit, stays out).
  for (int round = 0; round < 2 && best_in.size() >= 3; ++round) {
    std::vector<cv::Vec3f> points;
    for (int m : best_in) points.push_back(samples[m]);
    if (!FitPlane(points, &best)) break;
    collect(best, &best_in);
    if (round == 0 && best_in.size() >= 3) {
      std::vector<float> off;
      for (int m : best_in)
        off.push_back(std::fabs(samples[m][2] - best.At(samples[m][0], samples[m][1])));
      const double scatter = 1.4826 * Median(&off);
      std::vector<int> close;
      for (int m : best_in) {
        if (std::fabs(samples[m][2] - best.At(samples[m][0], samples[m][1])) <=
            std::max(3 * scatter, 0.003)) {
          close.push_back(m);
        }
      }
      if (close.size() >= 3) best_in.swap(close);
    }
  }
  if (best_in.size() < least || std::hypot(best.a, best.b) > max_slope) return false;
  best.inliers = static_cast<int>(best_in.size());
  *plane = best;
  *inliers = best_in;
  return true;
}

}  // namespace

double TiltBetweenDeg(const Plane& p, const Plane& q) {
  const cv::Vec3d n(-p.a, -p.b, 1), m(-q.a, -q.b, 1);
  const double c = n.dot(m) / (cv::norm(n) * cv::norm(m));
  return std::acos(std::clamp(c, -1.0, 1.0)) * 180 / M_PI;
}

std::vector<Plane> FitSurround(const Blocks& blocks, const SurroundOptions& options) {
  const cv::Size g = blocks.grid;
  // The samples: the outermost solidly measured block of each row and column from each side,
  // within the grid's outer quarter (SolidBlocks).
  const cv::Mat solid = SolidBlocks(blocks);
  cv::Mat taken(g, CV_8U, cv::Scalar(0));
  auto measured = [&](int bx, int by) { return solid.at<uint8_t>(by, bx) != 0; };
  for (int by = 0; by < g.height; ++by) {
    for (int bx = 0; bx < g.width / 4; ++bx) {
      if (measured(bx, by)) {
        taken.at<uint8_t>(by, bx) = 1;
        break;
      }
    }
    for (int bx = g.width - 1; bx >= g.width * 3 / 4; --bx) {
      if (measured(bx, by)) {
        taken.at<uint8_t>(by, bx) = 1;
        break;
      }
    }
  }
  for (int bx = 0; bx < g.width; ++bx) {
    for (int by = 0; by < g.height / 4; ++by) {
      if (measured(bx, by)) {
        taken.at<uint8_t>(by, bx) = 1;
        break;
      }
    }
    for (int by = g.height - 1; by >= g.height * 3 / 4; --by) {
      if (measured(bx, by)) {
        taken.at<uint8_t>(by, bx) = 1;
        break;
      }
    }
  }
  std::vector<cv::Vec3f> samples;
  std::vector<float> noise;
  for (int by = 0; by < g.height; ++by) {
    for (int bx = 0; bx < g.width; ++bx) {
      if (!taken.at<uint8_t>(by, bx)) continue;
      samples.emplace_back(blocks.x.at<float>(by, bx), blocks.y.at<float>(by, bx),
                           blocks.z.at<float>(by, bx));
      const float n = blocks.noise.at<float>(by, bx);
      noise.push_back(std::isnan(n) ? 0.0f : n);
    }
  }
  std::vector<Plane> planes;
  const size_t least = std::max<size_t>(8, static_cast<size_t>(options.min_share * samples.size()));
  cv::RNG rng(0x5a11);  // Deterministic: the same scan gives the same planes.
  std::vector<uint8_t> used(samples.size(), 0);
  // A plane tilted against the first is set aside (its samples too), and the next sought.
  for (int tries = 0;
       tries < 2 * options.max_planes && static_cast<int>(planes.size()) < options.max_planes;
       ++tries) {
    std::vector<int> left;
    for (size_t k = 0; k < samples.size(); ++k) {
      if (!used[k]) left.push_back(static_cast<int>(k));
    }
    Plane plane;
    std::vector<int> in;
    if (!RansacPlane(samples, noise, left, least, options, &rng, &plane, &in)) break;
    for (int m : in) used[m] = 1;
    if (planes.empty() || TiltBetweenDeg(planes.front(), plane) <= options.max_relative_tilt_deg) {
      planes.push_back(plane);
    }
  }
  return planes;
}

double RefitSurround(const Blocks& blocks, const cv::Mat& leaf, const SurroundOptions& options,
                     std::vector<Plane>* planes) {
  if (planes->empty()) return 0;
  const cv::Mat solid = SolidBlocks(blocks);
  cv::Mat near_leaf;
  cv::dilate(leaf, near_leaf, cv::Mat::ones(5, 5, CV_8U));
  const double max_slope = std::tan(options.max_tilt_deg * M_PI / 180);
  std::vector<std::vector<cv::Vec3f>> on(planes->size());
  for (int by = 0; by < blocks.grid.height; ++by) {
    for (int bx = 0; bx < blocks.grid.width; ++bx) {
      if (!solid.at<uint8_t>(by, bx) || near_leaf.at<uint8_t>(by, bx)) continue;
      const cv::Vec3f p(blocks.x.at<float>(by, bx), blocks.y.at<float>(by, bx),
                        blocks.z.at<float>(by, bx));
      const float n = blocks.noise.at<float>(by, bx);
      const double tolerance = OnPlaneTolerance(options, std::isnan(n) ? 0.0f : n);
      int nearest = -1;
      double off = tolerance;
      for (size_t k = 0; k < planes->size(); ++k) {
        const double d = std::fabs(p[2] - (*planes)[k].At(p[0], p[1]));
        if (d <= off) off = d, nearest = static_cast<int>(k);
      }
      if (nearest >= 0) on[nearest].push_back(p);
    }
  }
  double moved = 0;
  for (size_t k = 0; k < planes->size(); ++k) {
    Plane plane;
    if (static_cast<int>(on[k].size()) < (*planes)[k].inliers || !FitPlane(on[k], &plane) ||
        std::hypot(plane.a, plane.b) > max_slope) {
      continue;
    }
    for (const cv::Vec3f& p : on[k])
      moved = std::max(moved, std::fabs(plane.At(p[0], p[1]) - (*planes)[k].At(p[0], p[1])));
    plane.inliers = static_cast<int>(on[k].size());
    (*planes)[k] = plane;
  }
  return moved;
}

bool PlaneAlongOutline(const Blocks& blocks, const cv::Mat& leaf, const std::vector<Plane>& planes,
                       const SurroundOptions& options, Plane* plane, cv::Mat* ring, int* known) {
  // The blocks within three of the outer outline, inside (not those along its holes: a leaf's
  // dark squares cut out of a frame taken with it lie on the table the frame lies on).
  const cv::Mat filled = Filled(leaf);
  cv::Mat inner;
  cv::erode(filled, inner, cv::Mat::ones(7, 7, CV_8U), cv::Point(-1, -1), 1, cv::BORDER_CONSTANT,
            cv::Scalar(0));
  const cv::Mat band = leaf & ~inner;
  std::vector<cv::Vec3f> samples;
  std::vector<float> noise;
  std::vector<cv::Point> where;
  for (int by = 0; by < band.rows; ++by) {
    for (int bx = 0; bx < band.cols; ++bx) {
      if (!band.at<uint8_t>(by, bx) || blocks.valid.at<float>(by, bx) < 0.5f) continue;
      samples.emplace_back(blocks.x.at<float>(by, bx), blocks.y.at<float>(by, bx),
                           blocks.z.at<float>(by, bx));
      const float n = blocks.noise.at<float>(by, bx);
      noise.push_back(std::isnan(n) ? 0.0f : n);
      where.emplace_back(bx, by);
    }
  }
  if (samples.size() < 24) return false;
  std::vector<int> all(samples.size());
  for (size_t k = 0; k < all.size(); ++k) all[k] = static_cast<int>(k);
  cv::RNG rng(0x5a12);
  std::vector<int> in;
  // Most of the outline's blocks on it: a support or a frame surrounds the leaf.
  if (!RansacPlane(samples, noise, all, samples.size() * 6 / 10, options, &rng, plane, &in)) {
    return false;
  }
  // Not a plane already known (it stands off each by more than the tolerance), or a raised one.
  *known = -1;
  size_t lowest = 0;
  for (size_t k = 0; k < planes.size(); ++k) {
    if (planes[k].c < planes[lowest].c) lowest = k;
  }
  for (size_t k = 0; k < planes.size(); ++k) {
    double off = 0;
    for (int m : in) off += std::fabs(planes[k].At(samples[m][0], samples[m][1]) - samples[m][2]);
    if (off / in.size() > 2 * options.tolerance_mm) continue;
    if (k == lowest) return false;
    *known = static_cast<int>(k);
  }
  if (*known >= 0) {
    // Fitted again without the outermost blocks, which straddle its edge and draw the fit toward
    // what lies beyond it: fitted as it was, the face stands off it by a thin leaf's height.
    cv::Mat off_edge;
    cv::erode(filled, off_edge, cv::Mat(), cv::Point(-1, -1), 1, cv::BORDER_CONSTANT,
              cv::Scalar(0));
    std::vector<cv::Vec3f> kept;
    for (int m : in) {
      if (off_edge.at<uint8_t>(where[m])) kept.push_back(samples[m]);
    }
    Plane refit;
    if (kept.size() >= 24 && FitPlane(kept, &refit)) {
      refit.inliers = static_cast<int>(kept.size());
      *plane = refit;
    }
  }
  *ring = cv::Mat::zeros(leaf.size(), CV_8U);
  for (int m : in) ring->at<uint8_t>(where[m]) = 255;
  return true;
}

cv::Mat AboveSurround(const Blocks& blocks, const std::vector<Plane>& planes) {
  cv::Mat above(blocks.grid, CV_32F);
  for (int by = 0; by < blocks.grid.height; ++by) {
    for (int bx = 0; bx < blocks.grid.width; ++bx) {
      const float x = blocks.x.at<float>(by, bx), y = blocks.y.at<float>(by, bx),
                  z = blocks.z.at<float>(by, bx);
      if (std::isnan(z)) {
        above.at<float>(by, bx) = z;
        continue;
      }
      double nearest = z;
      for (const Plane& p : planes) {
        const double d = z - p.At(x, y);
        if (&p == &planes.front() || std::fabs(d) < std::fabs(nearest)) nearest = d;
      }
      above.at<float>(by, bx) = static_cast<float>(nearest);
    }
  }
  return above;
}

}  // namespace outline
}  // namespace vellum
