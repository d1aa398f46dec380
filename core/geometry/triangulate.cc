#include "core/geometry/triangulate.h"

#include <atomic>
#include <cmath>
#include <limits>

#include <opencv2/core/utility.hpp>

#include "core/common/check.h"

namespace vellum {
namespace {

// Ray parameter t of the point C + t d whose projection a + t b (projector pixel homogeneous
// coordinates) is closest to the measured projector pixel; `residual` gets the distance from
// the measurement to the ray's image (the epipolar line) when both coordinates are known.
double RayParameter(const cv::Vec3d& a, const cv::Vec3d& b, bool cols, bool rows, double mx,
                    double my, double* residual) {
  *residual = 0.0;
  if (cols && rows) {
    const cv::Vec3d l = a.cross(b);
    const double norm = std::sqrt(l[0] * l[0] + l[1] * l[1]);
    const double dist = (l[0] * mx + l[1] * my + l[2]) / norm;
    *residual = std::fabs(dist);
    // Foot of the perpendicular, then least squares of (a_i + t b_i) = f_i (a_z + t b_z).
    const double fx = mx - dist * l[0] / norm, fy = my - dist * l[1] / norm;
    const double ex = b[0] - fx * b[2], ey = b[1] - fy * b[2];
    const double gx = fx * a[2] - a[0], gy = fy * a[2] - a[1];
    return (ex * gx + ey * gy) / (ex * ex + ey * ey);
  }
  if (cols) return (mx * a[2] - a[0]) / (b[0] - mx * b[2]);
  return (my * a[2] - a[1]) / (b[1] - my * b[2]);
}

}  // namespace

bool TriangulateOptions::Check(std::string* why) const {
  if (!(max_epipolar_error_px > 0)) {
    *why = "max_epipolar_error_px must be positive";
    return false;
  }
  if (!(min_z_mm < max_z_mm)) {
    *why = "min_z_mm must be below max_z_mm";
    return false;
  }
  return true;
}

Triangulator::Triangulator(const Calibration& calibration) : calibration_(calibration) {
  std::string why;
  VELLUM_DEMAND(calibration_.Check(&why));
  const CameraModel& cam = calibration_.camera;
  rays_.create(cam.size, CV_32FC3);
  cv::parallel_for_(cv::Range(0, cam.size.height), [&](const cv::Range& range) {
    for (int v = range.start; v < range.end; ++v) {
      cv::Vec3f* row = rays_.ptr<cv::Vec3f>(v);
      for (int u = 0; u < cam.size.width; ++u) row[u] = cam.RayDirection(cv::Point2d(u, v));
    }
  });
}

PointMap Triangulator::Triangulate(const DecodeResult& decoded,
                                   const TriangulateOptions& options) const {
  PointMap out;
  Triangulate(decoded, options, &out);
  return out;
}

void Triangulator::Triangulate(const DecodeResult& decoded, const TriangulateOptions& options,
                               PointMap* result) const {
  PointMap& out = *result;
  out.status = Status::Error("triangulation not run");
  out.valid = out.rejected_epipolar = out.rejected_volume = 0;
  std::string why;
  if (!options.Check(&why)) {
    out.status = Status::Error("triangulation options: " + why);
    return;
  }
  if (!decoded.status.ok()) {
    out.status = Status::Error("cannot triangulate a failed decode: " + decoded.status.message());
    return;
  }
  const cv::Size size = decoded.valid.size();
  if (size != calibration_.camera.size) {
    out.status = Status::Error("the scan's camera images are " + std::to_string(size.width) + "x" +
                               std::to_string(size.height) + " but the calibration's camera is " +
                               std::to_string(calibration_.camera.size.width) + "x" +
                               std::to_string(calibration_.camera.size.height));
    return;
  }
  const CameraModel& prj = calibration_.projector;
  const bool cols = decoded.has_columns, rows = decoded.has_rows;
  // Everything in projector pixel homogeneous coordinates: the ray C + t d maps to a + t b.
  const cv::Vec3d c_world = calibration_.camera.Center();
  const cv::Matx33d kr = prj.matrix * prj.rotation;
  const cv::Vec3d a = prj.matrix * (prj.rotation * c_world + prj.translation);
  const bool undistort = prj.HasDistortion();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  out.points.create(size, CV_32FC3);
  out.residual.create(size, CV_32F);
  std::atomic<int> n_valid{0}, n_epi{0}, n_vol{0};
  cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& range) {
    int valid = 0, epi = 0, vol = 0;
    for (int v = range.start; v < range.end; ++v) {
      const uint8_t* ok = decoded.valid.ptr<uint8_t>(v);
      const float* px = decoded.projector_x.ptr<float>(v);
      const float* py = decoded.projector_y.ptr<float>(v);
      const cv::Vec3f* ray = rays_.ptr<cv::Vec3f>(v);
      cv::Vec3f* point = out.points.ptr<cv::Vec3f>(v);
      float* res = out.residual.ptr<float>(v);
      for (int u = 0; u < size.width; ++u) {
        point[u] = cv::Vec3f(NAN, NAN, NAN);
        res[u] = NAN;
        if (!ok[u]) continue;
        const cv::Vec3d d(ray[u][0], ray[u][1], ray[u][2]);
        const cv::Vec3d b = kr * d;
        const double raw_x = cols ? px[u] : nan, raw_y = rows ? py[u] : nan;
        double t = nan, r = 0.0;
        // Decoded coordinates are in the distorted projector image. With both, undistort once;
        // with one, the other comes from the current point (a few fixed-point rounds).
        double guess_x = prj.matrix(0, 2), guess_y = prj.matrix(1, 2);
        const int rounds = !undistort ? 1 : (cols && rows ? 1 : 4);
        for (int round = 0; round < rounds; ++round) {
          double mx = raw_x, my = raw_y;
          if (undistort) {
            const cv::Point2d n = prj.Normalize({cols ? raw_x : guess_x, rows ? raw_y : guess_y});
            mx = prj.matrix(0, 0) * n.x + prj.matrix(0, 1) * n.y + prj.matrix(0, 2);
            my = prj.matrix(1, 1) * n.y + prj.matrix(1, 2);
          }
          t = RayParameter(a, b, cols, rows, mx, my, &r);
          if (round + 1 < rounds) {
            const cv::Point2d p = prj.Project(c_world + t * d);
            guess_x = p.x;
            guess_y = p.y;
          }
        }
        if (r > options.max_epipolar_error_px) {
          ++epi;
          continue;
        }
        const cv::Vec3d m = c_world + t * d;
        if (!(t > 0) || !(m[2] >= options.min_z_mm && m[2] <= options.max_z_mm)) {
          ++vol;
          continue;
        }
        point[u] = cv::Vec3f(static_cast<float>(m[0]), static_cast<float>(m[1]),
                             static_cast<float>(m[2]));
        res[u] = static_cast<float>(r);
        ++valid;
      }
    }
    n_valid += valid;
    n_epi += epi;
    n_vol += vol;
  });
  out.valid = n_valid;
  out.rejected_epipolar = n_epi;
  out.rejected_volume = n_vol;
  out.status = Status::Ok();
}

}  // namespace vellum
