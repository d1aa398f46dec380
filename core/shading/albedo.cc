#include "core/shading/albedo.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <opencv2/core/utility.hpp>
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
  cv::parallel_for_(cv::Range(0, points.rows), [&](const cv::Range& range) {
    for (int v = range.start; v < range.end; ++v) {
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
  });
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

// What an estimate made of a page pixel with a measured point and normal.
enum class Mark { kEstimated, kDim, kOutside };

// Calls `estimate(pixel, x, n, albedo)` for every pixel of `page` (CV_8U, nonzero on it; empty:
// every pixel) with a measured point x and a normal n (Normals), in parallel, over the page's
// bounding box alone (grown by the normals' window, which never reaches past the page: on a
// leaf filling a third of the view, a third of the work); `albedo` points at the pixel's
// `channels` values in out->albedo. Fills out->albedo (CV_32FC(channels), 0 where marked),
// out->valid and the counts: not measured (shadowed), the rim, and what `estimate` marked (dim
// or grazing light; outside what was calibrated).
template <class Estimate>
void ForEachPagePixel(const cv::Mat& points, const cv::Mat& page, int channels,
                      const Calibration& calibration, const AlbedoOptions& options,
                      AlbedoResult* out, Estimate estimate) {
  out->albedo = cv::Mat::zeros(points.size(), CV_32FC(channels));
  out->valid = cv::Mat::zeros(points.size(), CV_8U);
  cv::Rect box(0, 0, points.cols, points.rows);
  if (!page.empty()) {
    const int w = options.normal_window_px + 1;
    const cv::Rect r = cv::boundingRect(page);
    box &= cv::Rect(r.x - w, r.y - w, r.width + 2 * w, r.height + 2 * w);
  }
  const cv::Mat points_in = points(box), page_in = page.empty() ? cv::Mat() : page(box);
  const cv::Mat normals =
      Normals(points_in, page_in, options.normal_window_px, calibration.camera.Center());
  std::atomic<int> estimated{0}, shadowed{0}, rim{0}, dim{0}, outside{0};
  cv::parallel_for_(cv::Range(0, box.height), [&](const cv::Range& range) {
    int n_estimated = 0, n_shadowed = 0, n_rim = 0, n_dim = 0, n_outside = 0;
    for (int v = range.start; v < range.end; ++v) {
      const cv::Vec3f* p = points_in.ptr<cv::Vec3f>(v);
      const cv::Vec3f* nv = normals.ptr<cv::Vec3f>(v);
      const uint8_t* in = page_in.empty() ? nullptr : page_in.ptr<uint8_t>(v);
      float* albedo = out->albedo.ptr<float>(v + box.y) + box.x * channels;
      uint8_t* ok = out->valid.ptr<uint8_t>(v + box.y) + box.x;
      for (int u = 0; u < box.width; ++u) {
        if (in && !in[u]) continue;
        if (!std::isfinite(p[u][2])) {
          ++n_shadowed;  // Not measured: the projector's shadow, or a pixel it could not decode.
          continue;
        }
        if (!std::isfinite(nv[u][0])) {
          ++n_rim;
          continue;
        }
        switch (estimate(cv::Point(u + box.x, v + box.y), cv::Vec3d(p[u]), cv::Vec3d(nv[u]),
                         albedo + u * channels)) {
          case Mark::kEstimated:
            ok[u] = 255;
            ++n_estimated;
            break;
          case Mark::kDim:
            ++n_dim;
            break;
          case Mark::kOutside:
            ++n_outside;
            break;
        }
      }
    }
    estimated += n_estimated;
    shadowed += n_shadowed;
    rim += n_rim;
    dim += n_dim;
    outside += n_outside;
  });
  out->estimated = estimated;
  out->shadowed = shadowed;
  out->rim = rim;
  out->grazing = dim;
  out->outside_flat_field = outside;
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

bool FlatFieldOptions::Check(std::string* why) const {
  if (!(target_albedo > 0 && target_albedo <= 1) || cell_px < 1 || min_samples < 1) {
    *why = "flat field: target_albedo must be in (0, 1], cell_px and min_samples >= 1";
    return false;
  }
  return true;
}

bool AlbedoOptions::Check(std::string* why) const {
  if (!(min_cos > 0 && min_cos < 1) || normal_window_px < 1) {
    *why = "albedo: min_cos must be in (0, 1), normal_window_px >= 1";
    return false;
  }
  return true;
}

FlatField MeasureFlatField(const cv::Mat& amplitude, const cv::Mat& points,
                           const Calibration& calibration, const FlatFieldOptions& options,
                           Status* status) {
  FlatField out;
  if (std::string why; !options.Check(&why)) {
    *status = Status::Error(why);
    return out;
  }
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
  if (std::string why; !options.Check(&why)) {
    out.status = Status::Error(why);
    return out;
  }
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
  const double d0 = flat_field.reference_mm;
  ForEachPagePixel(points, page, 1, calibration, options, &out,
                   [&](cv::Point pixel, const cv::Vec3d& x, const cv::Vec3d& n, float* albedo) {
                     const cv::Vec3d to = centre - x;
                     if (!(n.dot(to) / cv::norm(to) >= options.min_cos)) return Mark::kDim;
                     const double g = flat_field.At(projector.Project(x));
                     if (!(g > 0)) return Mark::kOutside;
                     *albedo = static_cast<float>(2.0 * amplitude.at<float>(pixel) /
                                                  (g * Geometry(x, n, centre, d0)));
                     return Mark::kEstimated;
                   });
  out.status = out.estimated > 0 ? Status::Ok()
                                 : Status::Error(
                                       "albedo: no pixel where the model holds (lit, not "
                                       "grazing, inside the flat field)");
  return out;
}

cv::Mat MarkedAsNaN(const AlbedoResult& a) {
  cv::Mat out = a.albedo.clone();
  out.setTo(cv::Scalar::all(std::nan("")), a.valid == 0);
  return out;
}

double LampLight(const std::vector<cv::Vec3d>& lamps, const cv::Vec3d& x, const cv::Vec3d& n) {
  auto sum = [&](const cv::Vec3d& at, const cv::Vec3d& normal) {
    double e = 0;
    for (const cv::Vec3d& lamp : lamps) {
      const cv::Vec3d to = lamp - at;
      const double d2 = to.dot(to);
      e += std::max(0.0, normal.dot(to)) / (d2 * std::sqrt(d2));
    }
    return e;
  };
  const double reference = sum(cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 1));
  return reference > 0 ? sum(x, n) / reference : 0.0;
}

cv::Vec3d StudioField::At(const cv::Point2d& p) const {
  const double nan = std::nan("");
  if (gain.empty()) return {nan, nan, nan};
  const double x = (p.x + 0.5) / cell_px - 0.5, y = (p.y + 0.5) / cell_px - 0.5;
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  const double fx = x - x0, fy = y - y0;
  const int channels = gain.channels();
  cv::Vec3d sum(0, 0, 0);
  double weight = 0;
  for (int j = 0; j < 2; ++j) {
    for (int i = 0; i < 2; ++i) {
      const int cx = std::clamp(x0 + i, 0, gain.cols - 1),
                cy = std::clamp(y0 + j, 0, gain.rows - 1);
      const float* g = gain.ptr<float>(cy) + cx * channels;
      const double w = (i ? fx : 1 - fx) * (j ? fy : 1 - fy);
      if (!std::isfinite(g[0])) {
        if (w > 1e-9) return {nan, nan, nan};
        continue;
      }
      for (int c = 0; c < channels; ++c) sum[c] += w * g[c];
      weight += w;
    }
  }
  if (!(weight > 0)) return {nan, nan, nan};
  return sum / weight;
}

namespace {

// A texture as shares of its full scale, float, its channels kept.
cv::Mat Levels(const cv::Mat& texture) {
  cv::Mat out;
  texture.convertTo(out, CV_32F, texture.depth() == CV_16U ? 1.0 / 65535 : 1.0 / 255);
  return out;
}

bool TextureKind(const cv::Mat& t) {
  return !t.empty() && (t.depth() == CV_8U || t.depth() == CV_16U) &&
         (t.channels() == 1 || t.channels() == 3);
}

}  // namespace

StudioField MeasureStudioField(const cv::Mat& texture, const CameraModel& camera,
                               const std::vector<cv::Vec3d>& lamps, double target_albedo,
                               Status* status, int cell_px) {
  StudioField out;
  if (!TextureKind(texture) || texture.size() != camera.size) {
    *status = Status::Error(
        "studio field: the target's texture must be an 8 or 16 bit gray or "
        "colour image of the camera's size (" +
        SizeText(camera.size) + ")");
    return out;
  }
  if (lamps.empty() || !(target_albedo > 0) || cell_px < 1) {
    *status = Status::Error(
        "studio field: needs the lamps' places, the target's albedo and a "
        "cell size");
    return out;
  }
  const int channels = texture.channels();
  const cv::Mat level = Levels(texture);
  const cv::Size cells((camera.size.width + cell_px - 1) / cell_px,
                       (camera.size.height + cell_px - 1) / cell_px);
  cv::Mat sum = cv::Mat::zeros(cells, CV_64FC(channels)), count = cv::Mat::zeros(cells, CV_32S);
  const cv::Vec3d eye = camera.Center(), up(0, 0, 1);
  const cv::Matx33d back = camera.rotation.t();
  for (int v = 0; v < level.rows; ++v) {
    const float* l = level.ptr<float>(v);
    for (int u = 0; u < level.cols; ++u) {
      // Where the pixel's ray meets the table.
      const cv::Point2d m = camera.Normalize(cv::Point2d(u, v));
      const cv::Vec3d ray = back * cv::Vec3d(m.x, m.y, 1.0);
      if (!(ray[2] < 0)) continue;
      const cv::Vec3d x = eye - (eye[2] / ray[2]) * ray;
      const double e = LampLight(lamps, x, up);
      if (!(e > 0.05)) continue;
      const bool clipped = [&] {
        for (int c = 0; c < channels; ++c)
          if (l[u * channels + c] >= 0.995f) return true;
        return false;
      }();
      if (clipped) continue;
      double* s = sum.ptr<double>(v / cell_px) + (u / cell_px) * channels;
      for (int c = 0; c < channels; ++c) s[c] += l[u * channels + c] / (target_albedo * e);
      ++count.at<int>(v / cell_px, u / cell_px);
    }
  }
  out.gain.create(cells, CV_32FC(channels));
  const int least = std::max(1, cell_px * cell_px / 2);
  int measured = 0;
  for (int j = 0; j < cells.height; ++j) {
    for (int i = 0; i < cells.width; ++i) {
      const int n = count.at<int>(j, i);
      float* g = out.gain.ptr<float>(j) + i * channels;
      const double* s = sum.ptr<double>(j) + i * channels;
      for (int c = 0; c < channels; ++c) g[c] = n >= least ? static_cast<float>(s[c] / n) : kNaN;
      measured += n >= least;
    }
  }
  if (measured == 0) {
    out = StudioField();
    *status = Status::Error(
        "studio field: the target was not seen anywhere (too dark or "
        "clipped under the lamps)");
    return out;
  }
  out.cell_px = cell_px;
  out.camera_size = camera.size;
  out.lamps = lamps;
  *status = Status::Ok();
  return out;
}

AlbedoResult CorrectTexture(const cv::Mat& texture, const cv::Mat& points, const cv::Mat& page,
                            const Calibration& calibration, const StudioField& field,
                            const AlbedoOptions& options) {
  AlbedoResult out;
  if (std::string why; !options.Check(&why)) {
    out.status = Status::Error(why);
    return out;
  }
  if (!TextureKind(texture) || points.type() != CV_32FC3 || texture.size() != points.size()) {
    out.status = Status::Error(
        "reflectance: the texture (8 or 16 bit) and the point map must be "
        "of one size");
    return out;
  }
  if (!page.empty() && (page.type() != CV_8U || page.size() != points.size())) {
    out.status = Status::Error("reflectance: the page mask must be CV_8U of the point map's size");
    return out;
  }
  if (field.empty() || field.camera_size != calibration.camera.size ||
      field.gain.channels() != texture.channels()) {
    out.status = Status::Error(
        "reflectance: the studio field is for a " + SizeText(field.camera_size) + " camera of " +
        std::to_string(field.gain.channels()) + " channel(s); the texture is " +
        SizeText(texture.size()) + " with " + std::to_string(texture.channels()));
    return out;
  }
  const int channels = texture.channels();
  const cv::Mat level = Levels(texture);
  ForEachPagePixel(points, page, channels, calibration, options, &out,
                   [&](cv::Point pixel, const cv::Vec3d& x, const cv::Vec3d& n, float* albedo) {
                     const double e = LampLight(field.lamps, x, n);
                     if (!(e >= 0.2)) return Mark::kDim;
                     const cv::Vec3d k = field.At(pixel);
                     if (!(k[0] > 0)) return Mark::kOutside;
                     const float* l = level.ptr<float>(pixel.y) + pixel.x * channels;
                     for (int c = 0; c < channels; ++c)
                       albedo[c] = static_cast<float>(l[c] / (k[c] * e));
                     return Mark::kEstimated;
                   });
  out.status = out.estimated > 0 ? Status::Ok()
                                 : Status::Error("reflectance: no pixel where the model holds");
  return out;
}

}  // namespace vellum
