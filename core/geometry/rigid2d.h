// Least-squares rigid motion in the plane (rotation and translation: no scale, no reflection).
#pragma once

#include <opencv2/core.hpp>
#include <vector>

namespace vellum {

struct Rigid2D {
  double angle = 0;         // Rotation, radians.
  cv::Point2d translation;  // Applied after the rotation.

  cv::Point2d Apply(const cv::Point2d& p) const {
    const double c = std::cos(angle), s = std::sin(angle);
    return {c * p.x - s * p.y + translation.x, s * p.x + c * p.y + translation.y};
  }
};

// The rigid motion taking `from` onto `to` (same length, >= 1 point) in least squares.
inline Rigid2D FitRigid2D(const std::vector<cv::Point2d>& from,
                          const std::vector<cv::Point2d>& to) {
  cv::Point2d cf(0, 0), ct(0, 0);
  for (size_t k = 0; k < from.size(); ++k) {
    cf += from[k];
    ct += to[k];
  }
  cf /= static_cast<double>(from.size());
  ct /= static_cast<double>(from.size());
  double sxx = 0, sxy = 0;
  for (size_t k = 0; k < from.size(); ++k) {
    const cv::Point2d a = from[k] - cf, b = to[k] - ct;
    sxx += a.x * b.x + a.y * b.y;
    sxy += a.x * b.y - a.y * b.x;
  }
  Rigid2D r;
  r.angle = std::atan2(sxy, sxx);
  const double c = std::cos(r.angle), s = std::sin(r.angle);
  r.translation = ct - cv::Point2d(c * cf.x - s * cf.y, s * cf.x + c * cf.y);
  return r;
}

}  // namespace vellum
