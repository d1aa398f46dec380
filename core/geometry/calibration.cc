#include "core/geometry/calibration.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/core/utility.hpp>
#include <vector>

namespace vellum {
namespace {

bool FiniteMatx(const double* v, int n) {
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(v[i])) return false;
  }
  return true;
}

// Applies OpenCV's distortion model to ideal normalised coordinates; with `jacobian`, also its
// derivatives there (d distorted / d (x, y): symmetric, both off-diagonal terms the same).
inline cv::Point2d Distort(const cv::Vec<double, 5>& d, double x, double y,
                           cv::Matx22d* jacobian = nullptr) {
  const double r2 = x * x + y * y;
  const double radial = 1 + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
  if (jacobian) {
    const double dradial = d[0] + r2 * (2 * d[1] + 3 * r2 * d[4]);  // d radial / d r2.
    const double jxy = 2 * x * y * dradial + 2 * d[2] * x + 2 * d[3] * y;
    *jacobian = cv::Matx22d(radial + 2 * x * x * dradial + 2 * d[2] * y + 6 * d[3] * x, jxy, jxy,
                            radial + 2 * y * y * dradial + 6 * d[2] * y + 2 * d[3] * x);
  }
  return {x * radial + 2 * d[2] * x * y + d[3] * (r2 + 2 * x * x),
          y * radial + d[2] * (r2 + 2 * y * y) + 2 * d[3] * x * y};
}

}  // namespace

bool CameraModel::Check(std::string* why) const {
  if (size.width <= 0 || size.height <= 0) {
    *why = "image size must be positive";
    return false;
  }
  if (!FiniteMatx(matrix.val, 9) || !FiniteMatx(distortion.val, 5) ||
      !FiniteMatx(rotation.val, 9) || !FiniteMatx(translation.val, 3)) {
    *why = "a matrix holds a NaN or infinity";
    return false;
  }
  if (!(matrix(0, 0) > 0 && matrix(1, 1) > 0) || matrix(1, 0) != 0 || matrix(2, 0) != 0 ||
      matrix(2, 1) != 0 || matrix(2, 2) != 1) {
    *why = "the intrinsic matrix must be [fx s cx; 0 fy cy; 0 0 1] with fx, fy > 0";
    return false;
  }
  // A plausible lens: a field of view across the image from half a degree (a long telephoto) to
  // 170 degrees (a fisheye), and pixels at most twice as tall as wide. A wild focal length
  // (fx = 1e300) fails here, named, rather than as an impossible restored size far downstream.
  for (int axis = 0; axis < 2; ++axis) {
    const double f = matrix(axis, axis), across = axis ? size.height : size.width;
    const double fov_deg = 2 * std::atan(across / (2 * f)) * 180 / M_PI;
    if (!(fov_deg >= 0.5 && fov_deg <= 170)) {
      char text[200];
      std::snprintf(text, sizeof text,
                    "%s = %g px gives a field of view of %.3g degrees across the image's %.0f px: "
                    "not a plausible lens (0.5 to 170 degrees)",
                    axis ? "fy" : "fx", f, fov_deg, across);
      *why = text;
      return false;
    }
  }
  if (!(matrix(0, 0) <= 2 * matrix(1, 1) && matrix(1, 1) <= 2 * matrix(0, 0))) {
    *why =
        "fx and fy differ more than twofold: not a plausible camera (pixels twice as tall as "
        "wide)";
    return false;
  }
  const cv::Matx33d should_be_identity = rotation * rotation.t() - cv::Matx33d::eye();
  if (cv::norm(should_be_identity) > 1e-6) {
    *why = "the rotation matrix is not orthonormal";
    return false;
  }
  if (cv::determinant(rotation) < 0) {
    *why = "the rotation matrix is a reflection (det = -1): a mirror left in the model";
    return false;
  }
  // A plausible lens: over the image (out to its farthest corner), radial distortion moves a
  // point by at most 30% of its distance from the centre and keeps the order of radii (a wrong
  // sign or a misplaced coefficient, k1 = 50, fails here rather than as a crumpled sheet).
  const double k1 = distortion[0], k2 = distortion[1], k3 = distortion[4];
  double r_max = 0;
  for (const cv::Point2d corner :
       {cv::Point2d(0, 0), cv::Point2d(size.width, 0), cv::Point2d(0, size.height),
        cv::Point2d(size.width, size.height)}) {
    r_max = std::max(r_max, std::hypot((corner.x - matrix(0, 2)) / matrix(0, 0),
                                       (corner.y - matrix(1, 2)) / matrix(1, 1)));
  }
  for (int i = 1; i <= 20; ++i) {
    const double r2 = std::pow(r_max * i / 20, 2);
    const double moved = k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2;
    const double slope = 1 + 3 * k1 * r2 + 5 * k2 * r2 * r2 + 7 * k3 * r2 * r2 * r2;
    if (std::fabs(moved) > 0.3 || slope <= 0) {
      char text[200];
      std::snprintf(text, sizeof text,
                    "the lens distortion (k1 %g, k2 %g, k3 %g) moves the image's edge by %.0f%% "
                    "of its distance from the centre: not a plausible lens",
                    k1, k2, k3, 100 * std::fabs(moved));
      *why = text;
      return false;
    }
  }
  return true;
}

bool CameraModel::HasDistortion() const {
  for (int i = 0; i < 5; ++i) {
    if (distortion[i] != 0) return true;
  }
  return false;
}

cv::Vec3d CameraModel::Center() const { return -(rotation.t() * translation); }

cv::Point2d CameraModel::Project(const cv::Vec3d& world) const {
  const cv::Vec3d p = rotation * world + translation;
  if (!(p[2] > 0)) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    return {nan, nan};
  }
  const cv::Point2d d = Distort(distortion, p[0] / p[2], p[1] / p[2]);
  return {matrix(0, 0) * d.x + matrix(0, 1) * d.y + matrix(0, 2),
          matrix(1, 1) * d.y + matrix(1, 2)};
}

cv::Point2d CameraModel::Normalize(const cv::Point2d& pixel) const {
  cv::Point2d shift(0, 0);
  return Normalize(pixel, &shift);
}

cv::Point2d CameraModel::Normalize(const cv::Point2d& pixel, cv::Point2d* shift) const {
  const double yd = (pixel.y - matrix(1, 2)) / matrix(1, 1);
  const double xd = (pixel.x - matrix(0, 2) - matrix(0, 1) * yd) / matrix(0, 0);
  if (!HasDistortion()) return {xd, yd};
  // Newton's inversion of the distortion, refined until it reproduces the pixel: three or four
  // rounds from the distorted point where the fixed-point iteration x -= D(x) - xd took ten or
  // more at a wide lens's corners; fewer from a neighbour's shift (the ray table of every camera
  // pixel is made this way for each triangulation). A start that does not reproduce the pixel
  // gives way to the distorted point.
  auto invert = [&](double x, double y, cv::Point2d* ideal) {
    for (int i = 0; i < 20; ++i) {
      cv::Matx22d j;
      const cv::Point2d d = Distort(distortion, x, y, &j);
      const double ex = d.x - xd, ey = d.y - yd;
      if (ex * ex + ey * ey < 1e-24) {
        *ideal = cv::Point2d(x, y);
        return true;
      }
      const double det = j(0, 0) * j(1, 1) - j(0, 1) * j(1, 0);
      if (!(std::fabs(det) > 1e-12)) {  // Past the model's fold: the plain step.
        x -= ex;
        y -= ey;
        continue;
      }
      x -= (j(1, 1) * ex - j(0, 1) * ey) / det;
      y -= (j(0, 0) * ey - j(1, 0) * ex) / det;
    }
    *ideal = cv::Point2d(x, y);
    return false;
  };
  cv::Point2d ideal;
  const bool warm = shift->x != 0 || shift->y != 0;
  if ((warm && invert(xd + shift->x, yd + shift->y, &ideal)) || invert(xd, yd, &ideal)) {
    *shift = ideal - cv::Point2d(xd, yd);
  } else {
    *shift = cv::Point2d(0, 0);  // Not reproduced: the next starts from its distorted point.
  }
  return ideal;
}

cv::Vec3d CameraModel::RayDirection(const cv::Point2d& pixel) const {
  cv::Point2d shift(0, 0);
  return RayDirection(pixel, &shift);
}

cv::Vec3d CameraModel::RayDirection(const cv::Point2d& pixel, cv::Point2d* shift) const {
  const cv::Point2d n = Normalize(pixel, shift);
  return cv::normalize(rotation.t() * cv::Vec3d(n.x, n.y, 1.0));
}

cv::Mat CameraModel::RayTable() const {
  const int step = kRayTableStep;
  // Nodes to the last pixel or past, at least one cell across and down.
  const int cols = std::max(2, (size.width - 1 + step - 1) / step + 1);
  const int rows = std::max(2, (size.height - 1 + step - 1) / step + 1);
  // The ideal coordinates at every node, each row's inversion started from its left neighbour.
  cv::Mat nodes(rows, cols, CV_64FC2);
  cv::parallel_for_(cv::Range(0, rows), [&](const cv::Range& range) {
    for (int j = range.start; j < range.end; ++j) {
      cv::Point2d shift(0, 0);
      auto* row = nodes.ptr<cv::Point2d>(j);
      for (int i = 0; i < cols; ++i) row[i] = Normalize(cv::Point2d(i * step, j * step), &shift);
    }
  });
  const cv::Matx33d to_world = rotation.t();
  const double fx = matrix(0, 0), skew = matrix(0, 1), cx = matrix(0, 2);
  const double fy = matrix(1, 1), cy = matrix(1, 2);
  const double near = kRayTableStartPx / std::max(fx, fy);
  cv::Mat rays(size, CV_32FC3);
  const int width = size.width;
  cv::parallel_for_(cv::Range(0, rows - 1), [&](const cv::Range& range) {
    std::vector<double> left_x(cols), left_y(cols), xs(width), ys(width);
    std::vector<uint8_t> near_enough(cols);
    for (int j = range.start; j < range.end; ++j) {
      const cv::Point2d* top = nodes.ptr<cv::Point2d>(j);
      const cv::Point2d* bottom = nodes.ptr<cv::Point2d>(j + 1);
      const int v0 = j * step, v1 = std::min(size.height, v0 + step);
      // A cell whose bilinear start strays at its centre (where a bilinear's error is largest)
      // beyond kRayTableStartPx is inverted pixel by pixel.
      for (int i = 0; i + 1 < cols; ++i) {
        const cv::Point2d centre = 0.25 * (top[i] + top[i + 1] + bottom[i] + bottom[i + 1]);
        const cv::Point2d exact = Normalize(cv::Point2d((i + 0.5) * step, (j + 0.5) * step));
        near_enough[i] = cv::norm(centre - exact) <= near;
      }
      for (int v = v0; v < v1; ++v) {
        const double t = double(v - v0) / step;
        for (int i = 0; i < cols; ++i) {
          left_x[i] = (1 - t) * top[i].x + t * bottom[i].x;
          left_y[i] = (1 - t) * top[i].y + t * bottom[i].y;
        }
        const double yd = (v - cy) / fy;
        // Branch-free passes over the row, so that each vectorises: the starts, one Newton
        // round, the rays.
        for (int u = 0; u < width; ++u) {
          const int i = u / step;
          const double s = double(u - i * step) / step;
          xs[u] = (1 - s) * left_x[i] + s * left_x[i + 1];
          ys[u] = (1 - s) * left_y[i] + s * left_y[i + 1];
        }
        for (int u = 0; u < width; ++u) {
          const double x = xs[u], y = ys[u];
          cv::Matx22d jac;
          const cv::Point2d d = Distort(distortion, x, y, &jac);
          const double ex = d.x - (u - cx - skew * yd) / fx, ey = d.y - yd;
          const double inv_det = 1.0 / (jac(0, 0) * jac(1, 1) - jac(0, 1) * jac(1, 0));
          xs[u] = x - (jac(1, 1) * ex - jac(0, 1) * ey) * inv_det;
          ys[u] = y - (jac(0, 0) * ey - jac(1, 0) * ex) * inv_det;
        }
        auto* out = rays.ptr<cv::Vec3f>(v);
        for (int u = 0; u < width; ++u) {
          const cv::Vec3d r = to_world * cv::Vec3d(xs[u], ys[u], 1.0);
          const double inv = 1.0 / std::sqrt(r.dot(r));
          out[u] = cv::Vec3f(static_cast<float>(r[0] * inv), static_cast<float>(r[1] * inv),
                             static_cast<float>(r[2] * inv));
        }
        for (int i = 0; i + 1 < cols; ++i) {
          if (near_enough[i]) continue;
          cv::Point2d shift(0, 0);
          for (int u = i * step; u < std::min(width, (i + 1) * step); ++u) {
            out[u] = RayDirection(cv::Point2d(u, v), &shift);
          }
        }
      }
    }
  });
  return rays;
}

bool Calibration::Check(std::string* why) const {
  std::string sub;
  if (!camera.Check(&sub)) {
    *why = "camera: " + sub;
    return false;
  }
  if (!projector.Check(&sub)) {
    *why = "projector: " + sub;
    return false;
  }
  if (cv::norm(camera.Center() - projector.Center()) < 1e-6) {
    *why = "camera and projector share one centre: no baseline to triangulate";
    return false;
  }
  // Both look at the table: where the camera's optical axis meets it (z = 0) lies in front of
  // the camera and of the projector.
  const cv::Vec3d centre = camera.Center();
  const cv::Vec3d axis = camera.rotation.t() * cv::Vec3d(0, 0, 1);
  const double t = std::fabs(axis[2]) > 1e-9 ? -centre[2] / axis[2] : -1;
  if (!(t > 0)) {
    *why = "the camera does not look at the table (z = 0 is not in front of it)";
    return false;
  }
  const cv::Vec3d on_table = centre + t * axis;
  if (!((projector.rotation * on_table + projector.translation)[2] > 0)) {
    *why = "the projector does not face the table the camera sees (it lies behind the projector)";
    return false;
  }
  if (!(min_z_mm < max_z_mm) || !std::isfinite(min_z_mm) || !std::isfinite(max_z_mm)) {
    *why = "working_volume_z: the lower height must be below the upper";
    return false;
  }
  return true;
}

cv::Matx33d LookAt(const cv::Vec3d& eye, const cv::Vec3d& target, const cv::Vec3d& right) {
  const cv::Vec3d z = cv::normalize(target - eye);
  cv::Vec3d x = right - z * z.dot(right);
  x = cv::normalize(x);
  const cv::Vec3d y = z.cross(x);
  return cv::Matx33d(x[0], x[1], x[2], y[0], y[1], y[2], z[0], z[1], z[2]);
}

}  // namespace vellum
