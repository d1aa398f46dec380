#include "core/shading/albedo.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "core/common/text.h"

namespace vellum {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// Unit normals of the point map (CV_32FC3, NaN where unset) within `page` (CV_8U, nonzero on the
// page; empty: everywhere): the page's points averaged over a (2w + 1)^2 window, then the cross
// product of their differences w pixels either way along the rows and the columns; turned to
// face the camera at `eye`. NaN where any of the four windows holds fewer than half its pixels
// (the page's rim, where a window would reach past it).
cv::Mat Normals(const cv::Mat& points, const cv::Mat& page, int w, const cv::Vec3d& eye) {
  cv::Mat valid(points.size(), CV_32F), filled(points.size(), CV_32FC3);
  for (int v = 0; v < points.rows; ++v) {
    const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
    float* m = valid.ptr<float>(v);
    cv::Vec3f* f = filled.ptr<cv::Vec3f>(v);
    const uint8_t* in = page.empty() ? nullptr : page.ptr<uint8_t>(v);
    for (int u = 0; u < points.cols; ++u) {
      const bool ok = std::isfinite(p[u][2]) && (!in || in[u]);
      m[u] = ok ? 1.0f : 0.0f;
      f[u] = ok ? p[u] : cv::Vec3f(0, 0, 0);
    }
  }
  const cv::Size box(2 * w + 1, 2 * w + 1);
  cv::Mat sum, count;
  cv::boxFilter(filled, sum, CV_32F, box, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
  cv::boxFilter(valid, count, CV_32F, box, cv::Point(-1, -1), false, cv::BORDER_CONSTANT);
  const float least = 0.5f * static_cast<float>(box.area());
  cv::Mat normals(points.size(), CV_32FC3, cv::Scalar::all(kNaN));
  auto mean = [&](int u, int v, cv::Vec3d* out) {
    if (u < 0 || v < 0 || u >= points.cols || v >= points.rows) return false;
    const float c = count.at<float>(v, u);
    if (c < least) return false;
    *out = cv::Vec3d(sum.at<cv::Vec3f>(v, u)) / c;
    return true;
  };
  cv::parallel_for_(cv::Range(0, points.rows), [&](const cv::Range& range) {
    for (int v = range.start; v < range.end; ++v) {
      for (int u = 0; u < points.cols; ++u) {
        if (!(valid.at<float>(v, u) > 0)) continue;
        cv::Vec3d l, r, t, b;
        if (!mean(u - w, v, &l) || !mean(u + w, v, &r) || !mean(u, v - w, &t) ||
            !mean(u, v + w, &b)) {
          continue;
        }
        cv::Vec3d n = (r - l).cross(b - t);
        const double length = cv::norm(n);
        if (!(length > 0)) continue;
        n /= length;
        if (n.dot(eye - cv::Vec3d(points.at<cv::Vec3f>(v, u))) < 0) n = -n;
        normals.at<cv::Vec3f>(v, u) = cv::Vec3f(n);
      }
    }
  });
  return normals;
}

// The projector's light on a point x with normal n, bar G: cos(i) (d0 / d)^2; 0 when the point
// faces away from the projector.
double Geometry(const cv::Vec3d& x, const cv::Vec3d& n, const cv::Vec3d& projector, double d0) {
  const cv::Vec3d to = projector - x;
  const double d = cv::norm(to);
  return std::max(0.0, n.dot(to) / d) * (d0 * d0) / (d * d);
}

}  // namespace

double FlatField::At(const cv::Point2d& p) const {
  if (gain.empty()) return std::nan("");
  // Cell coordinates of p, cell centres at integers.
  const double x = (p.x + 0.5) / cell_px - 0.5, y = (p.y + 0.5) / cell_px - 0.5;
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  const double fx = x - x0, fy = y - y0;
  double sum = 0, weight = 0;
  for (int j = 0; j < 2; ++j) {
    for (int i = 0; i < 2; ++i) {
      const int cx = std::clamp(x0 + i, 0, gain.cols - 1),
                cy = std::clamp(y0 + j, 0, gain.rows - 1);
      const float g = gain.at<float>(cy, cx);
      const double w = (i ? fx : 1 - fx) * (j ? fy : 1 - fy);
      if (!std::isfinite(g)) {
        if (w > 1e-9) return std::nan("");  // A corner the target never reached.
        continue;
      }
      sum += w * g;
      weight += w;
    }
  }
  return weight > 0 ? sum / weight : std::nan("");
}

FlatField MeasureFlatField(const cv::Mat& amplitude, const cv::Mat& points,
                           const Calibration& calibration, const FlatFieldOptions& options,
                           Status* status) {
  FlatField out;
  if (amplitude.type() != CV_32F || points.type() != CV_32FC3 ||
      amplitude.size() != points.size()) {
    *status = Status::Error(
        "flat field: the amplitude (CV_32F) and the point map (CV_32FC3) must "
        "be of one size, got " +
        SizeText(amplitude.size()) + " and " + SizeText(points.size()));
    return out;
  }
  if (!(options.target_albedo > 0 && options.target_albedo <= 1) || options.cell_px < 1) {
    *status = Status::Error("flat field: the target's albedo must be in (0, 1] and a cell >= 1 px");
    return out;
  }
  const CameraModel& projector = calibration.projector;
  const cv::Vec3d centre = projector.Center();
  out.cell_px = options.cell_px;
  out.reference_mm = cv::norm(centre);
  out.projector_size = projector.size;
  const cv::Size cells((projector.size.width + options.cell_px - 1) / options.cell_px,
                       (projector.size.height + options.cell_px - 1) / options.cell_px);
  cv::Mat sum = cv::Mat::zeros(cells, CV_64F), count = cv::Mat::zeros(cells, CV_32S);
  const cv::Vec3d up(0, 0, 1);  // The target lies on the table.
  for (int v = 0; v < points.rows; ++v) {
    for (int u = 0; u < points.cols; ++u) {
      const cv::Vec3f pf = points.at<cv::Vec3f>(v, u);
      const float a = amplitude.at<float>(v, u);
      if (!std::isfinite(pf[2]) || !(a > 0)) continue;
      // The measured point put on the table (z = 0): the target lies there, and its measured
      // height is 0 up to its noise.
      const cv::Vec3d x(pf[0], pf[1], 0.0);
      const cv::Point2d p = projector.Project(x);
      const int cx = static_cast<int>(std::floor((p.x + 0.5) / options.cell_px));
      const int cy = static_cast<int>(std::floor((p.y + 0.5) / options.cell_px));
      if (cx < 0 || cy < 0 || cx >= cells.width || cy >= cells.height) continue;
      const double geometry = Geometry(x, up, centre, out.reference_mm);
      if (!(geometry > 0)) continue;
      sum.at<double>(cy, cx) += 2.0 * a / (options.target_albedo * geometry);
      ++count.at<int>(cy, cx);
    }
  }
  out.gain.create(cells, CV_32F);
  int measured = 0;
  for (int j = 0; j < cells.height; ++j) {
    for (int i = 0; i < cells.width; ++i) {
      const int n = count.at<int>(j, i);
      const bool ok = n >= options.min_samples;
      out.gain.at<float>(j, i) = ok ? static_cast<float>(sum.at<double>(j, i) / n) : kNaN;
      measured += ok;
    }
  }
  if (measured == 0) {
    out.gain.release();
    *status = Status::Error(
        "flat field: the white target was not measured anywhere (no decoded "
        "pixel lit by the projector)");
    return out;
  }
  *status = Status::Ok();
  return out;
}

AlbedoResult EstimateAlbedo(const cv::Mat& amplitude, const cv::Mat& points, const cv::Mat& page,
                            const Calibration& calibration, const FlatField& flat_field,
                            const AlbedoOptions& options) {
  AlbedoResult out;
  if (amplitude.type() != CV_32F || points.type() != CV_32FC3 ||
      amplitude.size() != points.size()) {
    out.status = Status::Error(
        "albedo: the amplitude (CV_32F) and the point map (CV_32FC3) must "
        "be of one size, got " +
        SizeText(amplitude.size()) + " and " + SizeText(points.size()));
    return out;
  }
  if (!page.empty() && (page.type() != CV_8U || page.size() != points.size())) {
    out.status = Status::Error("albedo: the page mask must be CV_8U of the point map's size");
    return out;
  }
  if (flat_field.empty() || flat_field.projector_size != calibration.projector.size) {
    out.status =
        Status::Error("albedo: the flat field is for a " + SizeText(flat_field.projector_size) +
                      " projector, the calibration's is " + SizeText(calibration.projector.size));
    return out;
  }
  const CameraModel& projector = calibration.projector;
  const cv::Vec3d centre = projector.Center();
  const cv::Mat normals =
      Normals(points, page, options.normal_window_px, calibration.camera.Center());
  out.albedo = cv::Mat::zeros(points.size(), CV_32F);
  out.valid = cv::Mat::zeros(points.size(), CV_8U);
  std::atomic<int> estimated{0}, shadowed{0}, rim{0}, grazing{0}, outside{0};
  cv::parallel_for_(cv::Range(0, points.rows), [&](const cv::Range& range) {
    int n_estimated = 0, n_shadowed = 0, n_rim = 0, n_grazing = 0, n_outside = 0;
    for (int v = range.start; v < range.end; ++v) {
      const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
      const cv::Vec3f* nv = normals.ptr<cv::Vec3f>(v);
      const float* amp = amplitude.ptr<float>(v);
      const uint8_t* in = page.empty() ? nullptr : page.ptr<uint8_t>(v);
      float* albedo = out.albedo.ptr<float>(v);
      uint8_t* ok = out.valid.ptr<uint8_t>(v);
      for (int u = 0; u < points.cols; ++u) {
        if (in && !in[u]) continue;
        if (!std::isfinite(p[u][2])) {
          ++n_shadowed;  // Not measured: the projector's shadow, or a pixel it could not decode.
          continue;
        }
        if (!std::isfinite(nv[u][0])) {
          ++n_rim;
          continue;
        }
        const cv::Vec3d x(p[u][0], p[u][1], p[u][2]), n(nv[u]);
        const cv::Vec3d to = centre - x;
        const double d = cv::norm(to);
        const double cos_in = n.dot(to) / d;
        if (!(cos_in >= options.min_cos)) {
          ++n_grazing;
          continue;
        }
        const double g = flat_field.At(projector.Project(x));
        if (!(g > 0)) {
          ++n_outside;
          continue;
        }
        albedo[u] = static_cast<float>(2.0 * amp[u] /
                                       (g * Geometry(x, n, centre, flat_field.reference_mm)));
        ok[u] = 255;
        ++n_estimated;
      }
    }
    estimated += n_estimated;
    shadowed += n_shadowed;
    rim += n_rim;
    grazing += n_grazing;
    outside += n_outside;
  });
  out.estimated = estimated;
  out.shadowed = shadowed;
  out.rim = rim;
  out.grazing = grazing;
  out.outside_flat_field = outside;
  out.status = estimated > 0 ? Status::Ok()
                             : Status::Error(
                                   "albedo: no pixel where the model holds (lit, not "
                                   "grazing, inside the flat field)");
  return out;
}

}  // namespace vellum
