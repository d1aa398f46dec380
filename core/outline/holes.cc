// FillHoles (steps.h).
#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

#include "core/outline/steps.h"

namespace vellum::outline {
namespace {

// Whether the heights `inside` a hole lie on the surface the leaf makes `around` it (a quadric
// fitted to the leaf around it, so a curled leaf's bend does not pass for a step). What is judged
// is their offset from it, the median of their signed distances: each point's noise averages out
// over the points (the median's spread is about 1.25 sigma / sqrt(n)), a step under the leaf
// does not. `step` is the rim threshold for one point (StepThreshold: some four times its noise,
// more over dark ink); the offset must stay under step * max(1/4, 2 / sqrt(n)), so over dark
// ink, where one point's threshold is several times the leaf's thickness, what shows through a
// hole is still told from the leaf. `slack_px` forgives each point what the surface's slope there
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
    const double slack = slack_px * std::hypot(gx, gy), d = p.z - fit;
    off.push_back(static_cast<float>(d > 0 ? std::max(0.0, d - slack) : std::min(0.0, d + slack)));
  }
  const double n = static_cast<double>(off.size());
  return std::fabs(Median(&off)) < step * std::max(0.25, 2 / std::sqrt(n));
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

}  // namespace

SurroundLook::SurroundLook(const cv::Mat& points, const cv::Mat& colour, const cv::Mat& leaf_mask,
                           const std::vector<Plane>& planes, const Look& leaf, double plane_mm,
                           double look)
    : points_(points),
      colour_(colour),
      planes_(planes),
      leaf_(leaf),
      plane_mm_(plane_mm),
      look_(look),
      looks_(planes.size()),
      range_(planes.size(), {256, -1}) {
  if (leaf.empty()) return;
  // Each plane's own look, from every fourth pixel of the view on it and off the leaf (four
  // pixels clear of it: away from its rim), and the range of its brightness (2nd to 98th
  // percentile).
  std::vector<std::array<int, 256>> levels(planes.size());
  for (auto& l : levels) l.fill(0);
  const cv::Rect view(0, 0, points.cols, points.rows);
  auto clear = [&](int u, int v) {
    for (const cv::Point d :
         {cv::Point(0, 0), cv::Point(4, 0), cv::Point(-4, 0), cv::Point(0, 4), cv::Point(0, -4)}) {
      const cv::Point q(u + d.x, v + d.y);
      if (view.contains(q) && leaf_mask.at<uint8_t>(q)) return false;
    }
    return true;
  };
  for (int v = 0; v < points.rows; v += 4) {
    for (int u = 0; u < points.cols; u += 4) {
      const int k = OnPlane(points.at<cv::Vec3f>(v, u));
      if (k < 0 || !clear(u, v)) continue;
      const cv::Vec3b c = Mean3x3(colour, u, v);
      looks_[k].Add(Look::Bin(c), 1);
      ++levels[k][Level(c)];
    }
  }
  for (size_t k = 0; k < planes.size(); ++k) {
    if (looks_[k].empty()) continue;
    looks_[k].Finish();
    int total = 0;
    for (int n : levels[k]) total += n;
    int seen = 0;
    for (int g = 0; g < 256; ++g) {
      seen += levels[k][g];
      if (range_[k].first > 255 && 50 * seen >= total) range_[k].first = g;
      if (range_[k].second < 0 && 50 * seen >= 49 * total) range_[k].second = g;
    }
  }
}

int SurroundLook::OnPlane(const cv::Vec3f& p) const {
  if (std::isnan(p[2])) return -1;
  for (size_t k = 0; k < planes_.size(); ++k) {
    if (std::fabs(p[2] - planes_[k].At(p[0], p[1])) <= plane_mm_) return static_cast<int>(k);
  }
  return -1;
}

bool SurroundLook::Shows(int u, int v) const {
  const int k = OnPlane(points_.at<cv::Vec3f>(v, u));
  if (k < 0 || looks_[k].empty()) return false;
  const cv::Vec3b c = Mean3x3(colour_, u, v);
  const int bin = Look::Bin(c), g = Level(c);
  return g >= range_[k].first && g <= range_[k].second &&
         looks_[k].Log(bin) - leaf_.Log(bin) >= look_;
}

cv::Mat Filled(const cv::Mat& mask) {
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(mask.clone(), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
  cv::Mat filled = cv::Mat::zeros(mask.size(), CV_8U);
  cv::drawContours(filled, contours, -1, cv::Scalar(255), cv::FILLED);
  return filled;
}

// Fills the holes of `leaf` that show no other surface, and returns how many it keeps. A hole
// with heights is kept when they differ from the leaf's around it (another surface shows
// through), filled when they do not (an island the rim test cut out). The two are compared
// piece by piece along the hole's edge (32 px tiles: the leaf within 12 px outside the edge, a
// quadric, against the hole 3 to 10 px inside it, past the decoder's blur of the step), so a
// hole across a ripple is judged by the surface beside each part of it; the hole is kept when
// most pieces stand off; or, when they do not, when most of the hole shows the surround by its
// heights and its look together (a leaf flush with what it lies on). A hole without heights (the
// projector's light did not reach it: a shadow on the leaf, or what lies under a raised leaf) is
// kept when it looks unlike the leaf along its edge in the texture (within 3 px of it, by more
// than 3% of the paper's brightness), filled otherwise: ink too dark to decode, inside a dark
// square, looks like the decoded ink around it, not like the paper a wider ring would mix in.
int FillHoles(const cv::Mat& z, const cv::Mat& gray, const cv::Mat& threshold, double bright,
              cv::Mat* leaf, const SurroundLook* surround, cv::Point offset) {
  cv::Mat outside = ~*leaf, labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(outside, labels, stats, centroids, 4, CV_32S);
  const cv::Rect all(0, 0, z.cols, z.rows);
  constexpr int kRing = 12, kTile = 32, kNear = 3, kFar = 10, kEdge = 3;
  const cv::Mat disc = cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * kRing + 1, 2 * kRing + 1});
  const cv::Mat edge_disc =
      cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * kEdge + 1, 2 * kEdge + 1});
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
      cv::Mat ring, edge, depth;
      cv::dilate(hole, ring, disc);
      ring &= (*leaf)(near);
      cv::dilate(hole, edge, edge_disc);
      edge &= (*leaf)(near);
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
        const uint8_t* in_edge = edge.ptr<uint8_t>(v);
        const float* d = depth.ptr<float>(v);
        for (int u = 0; u < near.width; ++u) {
          if (!in_hole[u] && !in_ring[u]) continue;
          const int uu = u + near.x, vv = v + near.y;
          const float h = z.at<float>(vv, uu);
          if (in_hole[u]) {
            look_in.push_back(gray.at<uint8_t>(vv, uu));
          } else if (in_edge[u]) {
            look_around.push_back(gray.at<uint8_t>(vv, uu));
          }
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
        if (island && surround) {
          int shows = 0;
          for (int v = 0; v < near.height; ++v) {
            const uint8_t* in_hole = hole.ptr<uint8_t>(v);
            for (int u = 0; u < near.width; ++u) {
              shows += in_hole[u] && surround->Shows(near.x + u + offset.x, near.y + v + offset.y);
            }
          }
          island = 2 * shows < area;
        }
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

}  // namespace vellum::outline
