#include "core/geometry/triangulate.h"

#include <atomic>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/core/utility.hpp>

#include "core/common/check.h"
#include "core/geometry/flying.h"

namespace vellum {
namespace {

// Ray parameter t of the point C + t d whose projection a + t b (projector pixel homogeneous
// coordinates) is closest to the measured projector pixel (mx, my); `residual` gets the
// distance from the measurement to the ray's image, the epipolar line l = a x b. Branch-free,
// so the loop that calls it vectorises.
inline double RayParameterBoth(double a0, double a1, double a2, double b0, double b1, double b2,
                               double mx, double my, double* residual) {
  const double l0 = a1 * b2 - a2 * b1, l1 = a2 * b0 - a0 * b2, l2 = a0 * b1 - a1 * b0;
  const double inv_norm = 1.0 / std::sqrt(l0 * l0 + l1 * l1);
  const double dist = (l0 * mx + l1 * my + l2) * inv_norm;
  *residual = std::fabs(dist);
  // Foot of the perpendicular, then least squares of (a_i + t b_i) = f_i (a_z + t b_z).
  const double fx = mx - dist * l0 * inv_norm, fy = my - dist * l1 * inv_norm;
  const double ex = b0 - fx * b2, ey = b1 - fy * b2;
  const double gx = fx * a2 - a0, gy = fy * a2 - a1;
  return (ex * gx + ey * gy) / (ex * ex + ey * ey);
}

// The same with one coordinate (a column or a row plane): exact, no residual.
double RayParameter(const cv::Vec3d& a, const cv::Vec3d& b, bool cols, bool rows, double mx,
                    double my, double* residual) {
  if (cols && rows) return RayParameterBoth(a[0], a[1], a[2], b[0], b[1], b[2], mx, my, residual);
  *residual = 0.0;
  if (cols) return (mx * a[2] - a[0]) / (b[0] - mx * b[2]);
  return (my * a[2] - a[1]) / (b[1] - my * b[2]);
}

}  // namespace

bool TriangulateOptions::Check(std::string* why) const {
  if (!(max_epipolar_error_px > 0)) {
    *why = "max_epipolar_error_px must be positive";
    return false;
  }
  if (std::isnan(min_z_mm) != std::isnan(max_z_mm) || min_z_mm >= max_z_mm) {
    *why = "the working volume needs a lower height below the upper";
    return false;
  }
  if (!(max_flying_mm >= 0) || flying_reach_px < 1 || flying_reach_px > 32) {
    *why = "max_flying_mm must be >= 0 and flying_reach_px in [1, 32]";
    return false;
  }
  return true;
}

Triangulator::Triangulator(const Calibration& calibration) : calibration_(calibration) {
  std::string why;
  VELLUM_DEMAND(calibration_.Check(&why));
  const CameraModel& cam = calibration_.camera;
  rays_ = cam.RayTable();
}

PointMap Triangulator::Triangulate(const DecodeResult& decoded,
                                   const TriangulateOptions& options) const {
  PointMap out;
  Triangulate(decoded, options, &out);
  return out;
}

namespace {

// The camera's rays as they meet the projector: in projector pixel homogeneous coordinates the
// ray C + t d maps to a + t b, b = kr d; and what makes a point good.
struct Meeting {
  const CameraModel* projector;
  cv::Matx33d kr;
  cv::Vec3d a, c_world;
  bool undistort, cols, rows;
  double max_epipolar;  // Projector pixels from the epipolar line.
  double low, high;     // The working volume's heights, mm.
};

struct Counts {
  int valid = 0, epi = 0, vol = 0, below = 0;
};

// One row of the common case (an ideal projector, both axes) without branches, so it vectorises.
inline void TriangulateRowBoth(const Meeting& m, int width, const uint8_t* ok, const float* px,
                               const float* py, const cv::Vec3f* ray, cv::Vec3f* point, float* res,
                               Counts* counts) {
  // The common case (an ideal projector, both axes) without branches, so it vectorises.
  const float* rf = reinterpret_cast<const float*>(ray);
  float* pf = reinterpret_cast<float*>(point);
  // Invariants as locals, so the compiler keeps them in registers.
  const double max_r = m.max_epipolar;
  const double zmin = m.low, zmax = m.high;
  const cv::Matx33d& kr = m.kr;
  const double k00 = kr(0, 0), k01 = kr(0, 1), k02 = kr(0, 2), k10 = kr(1, 0), k11 = kr(1, 1),
               k12 = kr(1, 2), k20 = kr(2, 0), k21 = kr(2, 1), k22 = kr(2, 2);
  const double a0 = m.a[0], a1 = m.a[1], a2 = m.a[2];
  const double cx = m.c_world[0], cy = m.c_world[1], cz = m.c_world[2];
  int n_valid = 0, n_epi = 0, n_vol = 0, n_low = 0;
  for (int u = 0; u < width; ++u) {
    const double dx = rf[3 * u], dy = rf[3 * u + 1], dz = rf[3 * u + 2];
    const double b0 = k00 * dx + k01 * dy + k02 * dz;
    const double b1 = k10 * dx + k11 * dy + k12 * dz;
    const double b2 = k20 * dx + k21 * dy + k22 * dz;
    double dist;
    const double t = RayParameterBoth(a0, a1, a2, b0, b1, b2, px[u], py[u], &dist);
    const double x = cx + t * dx, y = cy + t * dy, z = cz + t * dz;
    const int decoded_ok = ok[u] != 0;
    const int on_line = dist <= max_r;
    const int in_volume = (t > 0) & (z >= zmin) & (z <= zmax);
    const int good = decoded_ok & on_line & in_volume;
    n_epi += decoded_ok & (1 - on_line);
    n_vol += decoded_ok & on_line & (1 - in_volume);
    n_low += decoded_ok & on_line & (t > 0) & (z < zmin);
    n_valid += good;
    pf[3 * u] = good ? static_cast<float>(x) : NAN;
    pf[3 * u + 1] = good ? static_cast<float>(y) : NAN;
    pf[3 * u + 2] = good ? static_cast<float>(z) : NAN;
    res[u] = good ? static_cast<float>(dist) : NAN;
  }
  counts->valid += n_valid;
  counts->epi += n_epi;
  counts->vol += n_vol;
  counts->below += n_low;
}

// One row, any projector: decoded coordinates are in the distorted projector image; with both
// axes undistorted once, with one the other comes from the current point (a few fixed-point
// rounds).
inline void TriangulateRow(const Meeting& m, int width, const uint8_t* ok, const float* px,
                           const float* py, const cv::Vec3f* ray, cv::Vec3f* point, float* res,
                           Counts* counts) {
  const CameraModel& prj = *m.projector;
  const bool cols = m.cols, rows = m.rows, undistort = m.undistort;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  cv::Point2d shift(0, 0);  // The last inversion's, the start of the next (a nearby point).
  for (int u = 0; u < width; ++u) {
    point[u] = cv::Vec3f(NAN, NAN, NAN);
    res[u] = NAN;
    if (!ok[u]) continue;
    const cv::Vec3d d(ray[u][0], ray[u][1], ray[u][2]);
    const cv::Vec3d b = m.kr * d;
    const double raw_x = cols ? px[u] : nan, raw_y = rows ? py[u] : nan;
    double t = nan, r = 0.0;
    // Decoded coordinates are in the distorted projector image. With both, undistort once;
    // with one, the other comes from the current point (a few fixed-point rounds).
    double guess_x = prj.matrix(0, 2), guess_y = prj.matrix(1, 2);
    const int rounds = !undistort ? 1 : (cols && rows ? 1 : 4);
    for (int round = 0; round < rounds; ++round) {
      double mx = raw_x, my = raw_y;
      if (undistort) {
        const cv::Point2d n =
            prj.Normalize({cols ? raw_x : guess_x, rows ? raw_y : guess_y}, &shift);
        mx = prj.matrix(0, 0) * n.x + prj.matrix(0, 1) * n.y + prj.matrix(0, 2);
        my = prj.matrix(1, 1) * n.y + prj.matrix(1, 2);
      }
      t = RayParameter(m.a, b, cols, rows, mx, my, &r);
      if (round + 1 < rounds) {
        const cv::Point2d p = prj.Project(m.c_world + t * d);
        guess_x = p.x;
        guess_y = p.y;
      }
    }
    if (r > m.max_epipolar) {
      ++counts->epi;
      continue;
    }
    const cv::Vec3d x = m.c_world + t * d;
    if (!(t > 0) || !(x[2] >= m.low && x[2] <= m.high)) {
      ++counts->vol;
      counts->below += t > 0 && x[2] < m.low;
      continue;
    }
    point[u] =
        cv::Vec3f(static_cast<float>(x[0]), static_cast<float>(x[1]), static_cast<float>(x[2]));
    res[u] = static_cast<float>(r);
    ++counts->valid;
  }
}

}  // namespace

void Triangulator::Triangulate(const DecodeResult& decoded, const TriangulateOptions& options,
                               PointMap* result) const {
  PointMap& out = *result;
  out.status = Status::Error("triangulation not run");
  out.valid = out.rejected_epipolar = out.rejected_volume = out.rejected_below = 0;
  out.rejected_flying = 0;
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
  // A Gray code alone that left out its finest bits steps by its stripe: a coordinate may lie
  // half a stripe (less the half pixel a full code has) further from its epipolar line.
  const double max_epipolar =
      options.max_epipolar_error_px + 0.5 * std::max(0, decoded.stats.step_px - 1);
  const double low = std::isnan(options.min_z_mm) ? calibration_.min_z_mm : options.min_z_mm;
  const double high = std::isnan(options.max_z_mm) ? calibration_.max_z_mm : options.max_z_mm;
  const Meeting meeting{&prj, kr, a, c_world, undistort, cols, rows, max_epipolar, low, high};
  std::atomic<int> n_valid{0}, n_epi{0}, n_vol{0}, n_below{0};
  cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& range) {
    Counts counts;
    for (int v = range.start; v < range.end; ++v) {
      const uint8_t* ok = decoded.valid.ptr<uint8_t>(v);
      const float* px = decoded.projector_x.ptr<float>(v);
      const float* py = decoded.projector_y.ptr<float>(v);
      const cv::Vec3f* ray = rays_.ptr<cv::Vec3f>(v);
      cv::Vec3f* point = out.points.ptr<cv::Vec3f>(v);
      float* res = out.residual.ptr<float>(v);
      if (!undistort && cols && rows) {
        TriangulateRowBoth(meeting, size.width, ok, px, py, ray, point, res, &counts);
      } else {
        TriangulateRow(meeting, size.width, ok, px, py, ray, point, res, &counts);
      }
    }
    n_valid += counts.valid;
    n_epi += counts.epi;
    n_vol += counts.vol;
    n_below += counts.below;
  });
  out.valid = n_valid;
  out.rejected_epipolar = n_epi;
  out.rejected_volume = n_vol;
  out.rejected_below = n_below;
  if (out.valid == 0 && out.rejected_volume > 0) {
    char text[320];
    std::snprintf(text, sizeof text,
                  "all %d triangulated points fall outside the working volume (heights %g to %g "
                  "mm above the table): %d below it, %d above; check the calibration's table "
                  "plane, or the volume (--volume, or working_volume_z in the calibration)",
                  out.rejected_volume, low, high, out.rejected_below,
                  out.rejected_volume - out.rejected_below);
    out.status = Status::Error(text);
    return;
  }
  if (options.max_flying_mm > 0) {
    out.rejected_flying =
        RejectFlyingPoints(&out.points, options.max_flying_mm, options.flying_reach_px);
    cv::Mat z;
    cv::extractChannel(out.points, z, 2);
    out.residual.setTo(nan, z != z);
    out.valid -= out.rejected_flying;
  }
  out.status = Status::Ok();
}

}  // namespace vellum
