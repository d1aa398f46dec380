#include "core/restore/restore.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>

namespace vellum {
namespace {

constexpr int kBandRows = 32;  // Output rows per parallel band.

// One destination triangle with the affine map from destination to source pixels.
struct Triangle {
  cv::Point2d d[3];  // Destination (output) pixels.
  cv::Matx23d source_from_dest;
  int samples = 1;  // Supersampling per pixel side (footprint of one output pixel).
  double ppi = 0;   // The camera's true sampling over the triangle.
};

// The smallest and largest stretch of a 2x2 linear map (its singular values).
void Stretches(const cv::Matx22d& j, double* smallest, double* largest) {
  const cv::Matx22d jtj = j.t() * j;
  const double tr = jtj(0, 0) + jtj(1, 1), det = cv::determinant(jtj);
  const double root = std::sqrt(std::max(0.0, tr * tr - 4 * det));
  *smallest = std::sqrt(std::max(0.0, 0.5 * (tr - root)));
  *largest = std::sqrt(0.5 * (tr + root));
}

// The sheet's triangles, as node triples, in the order they are rendered.
std::vector<cv::Vec3i> SheetTriangles(const Mesh& mesh) {
  std::vector<cv::Vec3i> out;
  out.reserve(mesh.quads.size() * 2);
  for (const cv::Vec4i& q : mesh.quads) {
    out.emplace_back(q[0], q[1], q[2]);
    out.emplace_back(q[0], q[2], q[3]);
  }
  return out;
}

// The camera's true sampling over a triangle of the sheet, ppi (0 if it is degenerate), and its
// flat area, mm^2: from its flat-page millimetres to its camera pixels.
double TrianglePpi(const cv::Vec3i& t, const Mesh& mesh, const std::vector<cv::Point2d>& flat,
                   double* area_mm2) {
  const cv::Point2d f0 = flat[t[0]], f1 = flat[t[1]], f2 = flat[t[2]];
  const cv::Matx22d fm(f1.x - f0.x, f2.x - f0.x, f1.y - f0.y, f2.y - f0.y);
  const double det = cv::determinant(fm);
  *area_mm2 = 0.5 * std::fabs(det);
  if (std::fabs(det) < 1e-12) return 0;
  const cv::Point2d s0 = mesh.pixel[t[0]], s1 = mesh.pixel[t[1]], s2 = mesh.pixel[t[2]];
  const cv::Matx22d sm(s1.x - s0.x, s2.x - s0.x, s1.y - s0.y, s2.y - s0.y);
  double smallest, largest;
  Stretches(sm * fm.inv(), &smallest, &largest);
  return 25.4 * smallest;
}

constexpr int kMaxFused = 4;  // Images of one type rendered in one pass over the triangles.

// Bilinear, clamped to the image; pixel centres at integers: the `count` images' values at
// (x, y) (all of one size) added to out[k * C + c]. The weights are found once for all of them.
template <typename T, int C>
void Sample(const cv::Mat* const* src, int count, double x, double y, double* out) {
  const cv::Mat& first = *src[0];
  x = std::clamp(x, 0.0, first.cols - 1.0);
  y = std::clamp(y, 0.0, first.rows - 1.0);
  const int x0 = std::min(static_cast<int>(x), first.cols - 2 < 0 ? 0 : first.cols - 2);
  const int y0 = std::min(static_cast<int>(y), first.rows - 2 < 0 ? 0 : first.rows - 2);
  const int x1 = std::min(x0 + 1, first.cols - 1), y1 = std::min(y0 + 1, first.rows - 1);
  const double fx = x - x0, fy = y - y0;
  const double w00 = (1 - fy) * (1 - fx), w01 = (1 - fy) * fx, w10 = fy * (1 - fx), w11 = fy * fx;
  for (int k = 0; k < count; ++k) {
    const T* r0 = src[k]->ptr<T>(y0);
    const T* r1 = src[k]->ptr<T>(y1);
    double* o = out + k * C;
    for (int c = 0; c < C; ++c) {
      o[c] +=
          w00 * r0[x0 * C + c] + w01 * r0[x1 * C + c] + w10 * r1[x0 * C + c] + w11 * r1[x1 * C + c];
    }
  }
}

// Each pixel of `dst[k]` inside a triangle from `src[k]` (k < count <= kMaxFused, all of one
// type and size) through the triangle's map, with its own supersampling but at most
// `max_samples` per pixel side. The images share the pass: its geometry is found once.
template <typename T, int C>
void Render(const cv::Mat* const* src, cv::Mat* const* dst, int count,
            const std::vector<Triangle>& tris, int max_samples = std::numeric_limits<int>::max()) {
  const cv::Size size = dst[0]->size();
  const int bands = (size.height + kBandRows - 1) / kBandRows;
  cv::parallel_for_(
      cv::Range(0, bands),
      [&](const cv::Range& range) {
        for (int band = range.start; band < range.end; ++band) {
          const int y_lo = band * kBandRows, y_hi = std::min(size.height, y_lo + kBandRows);
          // Triangles in a fixed order, each pixel from the last triangle covering it: the result
          // does not depend on the threads.
          for (const Triangle& t : tris) {
            const double min_y = std::min({t.d[0].y, t.d[1].y, t.d[2].y});
            const double max_y = std::max({t.d[0].y, t.d[1].y, t.d[2].y});
            const int ya = std::max(y_lo, static_cast<int>(std::ceil(min_y)));
            const int yb = std::min(y_hi - 1, static_cast<int>(std::floor(max_y)));
            if (ya > yb) continue;
            const double min_x = std::min({t.d[0].x, t.d[1].x, t.d[2].x});
            const double max_x = std::max({t.d[0].x, t.d[1].x, t.d[2].x});
            const int xa = std::max(0, static_cast<int>(std::ceil(min_x)));
            const int xb = std::min(size.width - 1, static_cast<int>(std::floor(max_x)));
            const cv::Point2d &a = t.d[0], &b = t.d[1], &c = t.d[2];
            const double area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
            if (std::fabs(area) < 1e-12) continue;
            const double inv_area = 1.0 / area;
            const cv::Matx23d& m = t.source_from_dest;
            const int n = std::min(t.samples, max_samples);
            const double inv_n2 = 1.0 / (n * n);
            for (int y = ya; y <= yb; ++y) {
              T* rows[kMaxFused];
              for (int k = 0; k < count; ++k) rows[k] = dst[k]->ptr<T>(y);
              // The barycentric weights are affine in x along the row: w = w(xa) + k * dw.
              const double w0a = ((b.x - xa) * (c.y - y) - (b.y - y) * (c.x - xa)) * inv_area;
              const double w1a = ((c.x - xa) * (a.y - y) - (c.y - y) * (a.x - xa)) * inv_area;
              const double dw0 = -(c.y - y) * inv_area + (b.y - y) * inv_area;
              const double dw1 = -(a.y - y) * inv_area + (c.y - y) * inv_area;
              for (int x = xa; x <= xb; ++x) {
                const double w0 = w0a + (x - xa) * dw0, w1 = w1a + (x - xa) * dw1;
                if (w0 < -1e-9 || w1 < -1e-9 || 1.0 - w0 - w1 < -1e-9) continue;
                double acc[kMaxFused * C] = {0};
                for (int sy = 0; sy < n; ++sy) {
                  const double py = y + (sy + 0.5) / n - 0.5;
                  for (int sx = 0; sx < n; ++sx) {
                    const double px = x + (sx + 0.5) / n - 0.5;
                    Sample<T, C>(src, count, m(0, 0) * px + m(0, 1) * py + m(0, 2),
                                 m(1, 0) * px + m(1, 1) * py + m(1, 2), acc);
                  }
                }
                for (int k = 0; k < count; ++k) {
                  for (int ch = 0; ch < C; ++ch)
                    rows[k][x * C + ch] = cv::saturate_cast<T>(acc[k * C + ch] * inv_n2);
                }
              }
            }
          }
        }
      },
      bands);
}

// Each image through the triangles into a `size` image of its own type, `outside` off them:
// those of one type (and size) share a pass, kMaxFused at a time.
void RenderImages(const std::vector<const cv::Mat*>& src, const std::vector<Triangle>& tris,
                  cv::Size size, std::vector<cv::Mat>* dst, double outside = 0) {
  dst->assign(src.size(), cv::Mat());
  std::vector<bool> done(src.size(), false);
  for (size_t k = 0; k < src.size(); ++k) {
    if (done[k]) continue;
    const cv::Mat* group[kMaxFused];
    cv::Mat* out[kMaxFused];
    int count = 0;
    for (size_t j = k; j < src.size() && count < kMaxFused; ++j) {
      if (done[j] || src[j]->type() != src[k]->type() || src[j]->size() != src[k]->size()) continue;
      done[j] = true;
      (*dst)[j] = cv::Mat(size, src[j]->type(), cv::Scalar::all(outside));
      group[count] = src[j];
      out[count++] = &(*dst)[j];
    }
    switch (src[k]->type()) {
      case CV_8UC1:
        Render<uint8_t, 1>(group, out, count, tris);
        break;
      case CV_8UC3:
        Render<uint8_t, 3>(group, out, count, tris);
        break;
      case CV_16UC1:
        Render<uint16_t, 1>(group, out, count, tris);
        break;
      case CV_16UC3:
        Render<uint16_t, 3>(group, out, count, tris);
        break;
      case CV_32FC1:
        Render<float, 1>(group, out, count, tris);
        break;
      case CV_32FC3:
        Render<float, 3>(group, out, count, tris);
        break;
    }
  }
}

// What Restore takes as an extra image.
bool ExtraKind(const cv::Mat& e) {
  return !e.empty() && (e.depth() == CV_8U || e.depth() == CV_16U || e.depth() == CV_32F) &&
         (e.channels() == 1 || e.channels() == 3);
}

}  // namespace

struct RestorePlan {
  std::vector<Triangle> tris;
  cv::Size source;  // The texture's size.
  cv::Size size;    // The whole sheet's image, before the crop.
  cv::Rect crop;    // The part kept.
};

const char* ToString(RestoreView view) {
  return view == RestoreView::kOrthographic ? "orthographic" : "camera";
}

bool ParseRestoreView(const std::string& text, RestoreView* view) {
  if (text == "orthographic") {
    *view = RestoreView::kOrthographic;
  } else if (text == "camera") {
    *view = RestoreView::kCamera;
  } else {
    return false;
  }
  return true;
}

bool RestoreOptions::Check(std::string* why) const {
  if (dpi < 0 || dpi > 4800 || margin_mm < 0 || max_supersampling < 1 || max_supersampling > 32) {
    *why = "dpi must lie in [0, 4800] (0: native), margin_mm >= 0, max_supersampling in [1, 32]";
    return false;
  }
  return true;
}

double NativeDpi(const CameraModel& camera) {
  const cv::Point2d c(camera.matrix(0, 2), camera.matrix(1, 2));
  const cv::Vec3d o = camera.Center();
  auto on_table = [&](cv::Point2d p) {
    const cv::Vec3d d = camera.RayDirection(p);
    return o - (o[2] / d[2]) * d;
  };
  const double mm_per_px =
      0.5 * (cv::norm(on_table(c + cv::Point2d(1, 0)) - on_table(c - cv::Point2d(1, 0))));
  return std::max(1.0, std::round(25.4 / mm_per_px));
}

SamplingSummary SummarizeSampling(const cv::Mat& sampling) {
  SamplingSummary out;
  if (sampling.empty() || sampling.type() != CV_32F) return out;
  std::vector<float> values;
  values.reserve(sampling.total());
  for (int y = 0; y < sampling.rows; ++y) {
    const float* row = sampling.ptr<float>(y);
    for (int x = 0; x < sampling.cols; ++x)
      if (row[x] > 0) values.push_back(row[x]);
  }
  if (values.empty()) return out;
  auto at = [&](double q) {
    const size_t k = std::min(values.size() - 1, static_cast<size_t>(q * values.size()));
    std::nth_element(values.begin(), values.begin() + k, values.end());
    return static_cast<double>(values[k]);
  };
  out.median_ppi = at(0.5);
  out.p5_ppi = at(0.05);
  out.p95_ppi = at(0.95);
  auto share = [&](double ppi) {
    return static_cast<double>(
               std::count_if(values.begin(), values.end(), [&](float v) { return v >= ppi; })) /
           values.size();
  };
  out.share_400 = share(400);
  out.share_300 = share(300);
  out.share_200 = share(200);
  return out;
}

namespace {
// An angle, degrees, into [-45, 45].
double Wrap90(double angle) { return angle - 90.0 * std::round(angle / 90.0); }
}  // namespace

double UprightAngle(const cv::Mat& mask) {
  // How far (degrees) the straight stretches' direction may stray from a rectangle's sides.
  constexpr double kStray = 0.5;
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(mask.clone(), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  if (contours.empty()) return 0;
  const auto& outline = *std::max_element(
      contours.begin(), contours.end(),
      [](const auto& a, const auto& b) { return cv::contourArea(a) < cv::contourArea(b); });
  // A rectangle (it fills its smallest enclosing rectangle to 97%): the mean direction of its
  // four sides, each a line fitted to the outline's points along it (the rectangle's own angle
  // snaps to its pixel staircase's hull).
  const cv::RotatedRect box = cv::minAreaRect(outline);
  double sides = std::numeric_limits<double>::quiet_NaN();
  if (box.size.area() > 0 && cv::contourArea(outline) >= 0.97 * box.size.area()) {
    cv::Point2f corner[4];
    box.points(corner);
    double sum = 0, total = 0;
    for (int k = 0; k < 4; ++k) {
      const cv::Point2f a = corner[k], b = corner[(k + 1) % 4];
      const double length = cv::norm(b - a);
      if (length < 10) continue;
      const cv::Point2f along = (b - a) / static_cast<float>(length);
      // The points within 3 pixels of this side, away from its corners (a tenth of it each end).
      std::vector<cv::Point2f> side;
      for (const cv::Point& p : outline) {
        const cv::Point2f d = cv::Point2f(p) - a;
        const double t = d.dot(along), off = std::fabs(d.x * along.y - d.y * along.x);
        if (off <= 3 && t > 0.1 * length && t < 0.9 * length) side.push_back(p);
      }
      if (side.size() < 10) continue;
      cv::Vec4f line;
      cv::fitLine(side, line, cv::DIST_HUBER, 0, 0.01, 0.01);
      // Off the rectangle's own angle.
      const double angle = Wrap90(std::atan2(line[1], line[0]) * 180 / M_PI - box.angle);
      sum += angle * side.size();
      total += side.size();
    }
    sides = Wrap90(box.angle + (total > 0 ? sum / total : 0));
  }
  // The outline's segments, their directions folded into [0, 90) degrees, weighted by length.
  std::vector<cv::Point> poly;
  cv::approxPolyDP(outline, poly, 1.5, true);
  constexpr int kBins = 180;  // Half-degree bins.
  std::vector<double> weight(kBins, 0);
  double perimeter = 0;
  std::vector<std::pair<double, double>> segments;  // (direction, length)
  for (size_t k = 0; k < poly.size(); ++k) {
    const cv::Point d = poly[(k + 1) % poly.size()] - poly[k];
    const double length = std::hypot(d.x, d.y);
    double angle = std::atan2(d.y, d.x) * 180 / M_PI;
    angle = std::fmod(angle + 360.0, 90.0);
    segments.emplace_back(angle, length);
    weight[std::min(kBins - 1, static_cast<int>(angle * 2))] += length;
    perimeter += length;
  }
  // The strongest direction, within 2 degrees (a circular window over the folded angles).
  int best = 0;
  double best_weight = -1;
  for (int b = 0; b < kBins; ++b) {
    double w = 0;
    for (int k = -4; k <= 4; ++k) w += weight[(b + k + kBins) % kBins];
    if (w > best_weight) best_weight = w, best = b;
  }
  double angle;
  if (best_weight >= 0.5 * perimeter) {
    // Straight edges: their length-weighted mean direction within 2 degrees, moved to that mean
    // until it settles (mean shift). The window found first is only the lowest of those that
    // hold the edges: its centre may lie up to 2 degrees off them, and a mean taken about it
    // alone leaves out the edges on its far side (a leaf turned 12 degrees came out 1.85 off).
    double peak = (best + 0.5) / 2;
    for (int pass = 0; pass < 8; ++pass) {
      double sum = 0, total = 0;
      for (const auto& [a, l] : segments) {
        const double d = Wrap90(a - peak);
        if (std::fabs(d) <= 2.0) sum += d * l, total += l;
      }
      const double shift = total > 0 ? sum / total : 0;
      peak += shift;
      if (std::fabs(shift) < 1e-3) break;
    }
    angle = peak;
    // A rectangle's fitted sides, where the straight stretches found above stray from them (a
    // curled leaf's sides bow: approximated as segments, they lean off its turn).
    if (std::isfinite(sides) && std::fabs(Wrap90(angle - sides)) > kStray) angle = sides;
  } else {
    angle = std::isfinite(sides) ? sides : box.angle;
  }
  return Wrap90(angle);
}

Status RestoreMore(const RestoreResult& restored, const std::vector<cv::Mat>& images,
                   std::vector<cv::Mat>* out, double outside) {
  if (!restored.status.ok() || !restored.plan) {
    return Status::Error("RestoreMore needs a restoration that succeeded");
  }
  const RestorePlan& plan = *restored.plan;
  out->assign(images.size(), cv::Mat());
  for (size_t k = 0; k < images.size(); ++k) {
    if (!ExtraKind(images[k]) || images[k].size() != plan.source) {
      return Status::Error("image " + std::to_string(k) +
                           " must be an 8, 16 or 32-bit float gray or three-channel image of the "
                           "texture's size");
    }
  }
  std::vector<const cv::Mat*> sources;
  for (const cv::Mat& image : images) sources.push_back(&image);
  std::vector<cv::Mat> whole;
  RenderImages(sources, plan.tris, plan.size, &whole, outside);
  for (size_t k = 0; k < images.size(); ++k) {
    (*out)[k] = plan.crop.size() == plan.size ? whole[k] : whole[k](plan.crop).clone();
  }
  return Status::Ok();
}

namespace {

// What Restore refuses, by name: bad options, a texture or extra image it cannot restore, no
// built mesh, a leaf mask of another size.
Status CheckRestoreInputs(const cv::Mat& texture, const Mesh& mesh,
                          const std::vector<cv::Point2d>& flat, const RestoreOptions& options,
                          const cv::Mat& leaf, const std::vector<cv::Mat>& extras) {
  std::string why;
  if (!options.Check(&why)) return Status::Error("restore options: " + why);
  auto restorable = [](const cv::Mat& image) {
    return !image.empty() && (image.depth() == CV_8U || image.depth() == CV_16U) &&
           (image.channels() == 1 || image.channels() == 3);
  };
  if (!restorable(texture)) {
    return Status::Error("the texture must be an 8 or 16 bit gray or colour image");
  }
  for (size_t k = 0; k < extras.size(); ++k) {
    const cv::Mat& e = extras[k];
    if (!ExtraKind(e) || e.size() != texture.size()) {
      return Status::Error("extra image " + std::to_string(k) +
                           " must be an 8, 16 or 32-bit float gray or three-channel "
                           "image of the texture's size");
    }
  }
  if (!mesh.status.ok() || mesh.quads.empty() || flat.size() != mesh.kind.size()) {
    return Status::Error("restore needs a built mesh and its flattened positions");
  }
  if (!leaf.empty() && (leaf.type() != CV_8U || leaf.size() != texture.size())) {
    return Status::Error("the leaf mask must be CV_8U of the texture's size");
  }
  return Status::Ok();
}

// The camera's true sampling over each of the sheet's `triangles` (ppi, TrianglePpi), and the
// sheet's finest by flat area (the 95th percentile) in *finest_ppi.
std::vector<double> TriangleSampling(const std::vector<cv::Vec3i>& triangles, const Mesh& mesh,
                                     const std::vector<cv::Point2d>& flat, double* finest_ppi) {
  std::vector<double> tri_ppi(triangles.size());
  std::vector<std::pair<double, double>> by_ppi;  // (ppi, flat area)
  double total = 0;
  for (size_t k = 0; k < triangles.size(); ++k) {
    double area = 0;
    tri_ppi[k] = TrianglePpi(triangles[k], mesh, flat, &area);
    if (tri_ppi[k] > 0) by_ppi.emplace_back(tri_ppi[k], area), total += area;
  }
  std::sort(by_ppi.begin(), by_ppi.end());
  double below = 0;
  for (const auto& [ppi, area] : by_ppi) {
    below += area;
    if (below >= 0.95 * total) {
      *finest_ppi = ppi;
      break;
    }
  }
  return tri_ppi;
}

// Where each node lands in the restored image (`dest`) and the image's size: orthographic, at
// result->dpi (the options', else the page's finest sampling), turned upright (deskew) and laid
// out with the margin (result->pixel_from_flat); or as the camera would see the page flat.
Status LayOut(const Mesh& mesh, const std::vector<cv::Point2d>& flat, const CameraModel& camera,
              const RestoreOptions& options, const cv::Mat& leaf, RestoreResult* out,
              std::vector<cv::Point2d>* dest, cv::Size* size_out) {
  RestoreResult& result = *out;
  cv::Size& size = *size_out;
  if (options.view == RestoreView::kOrthographic) {
    result.dpi = options.dpi > 0            ? options.dpi
                 : result.finest_ppi >= 0.5 ? std::round(result.finest_ppi)
                                            : NativeDpi(camera);
    const double s = result.dpi / 25.4;  // Pixels per mm.
    if (options.deskew && !leaf.empty()) {
      // The leaf's outline, flat: its mask restored alone at 2 pixels per mm (cheap), turned
      // upright. In that image rows run along -y, so a turn of theta there is -theta flat.
      RestoreOptions probe;
      probe.dpi = 50.8;
      probe.margin_mm = 2;
      const RestoreResult low = Restore(leaf, mesh, flat, camera, probe);
      if (low.status.ok()) result.rotation_deg = UprightAngle(low.image > 127);
    }
    // The flat page turned by rotation_deg (counter-clockwise), then laid out.
    const double r = result.rotation_deg * M_PI / 180, c = std::cos(r), n = std::sin(r);
    auto turned = [&](const cv::Point2d& p) {
      return cv::Point2d(c * p.x - n * p.y, n * p.x + c * p.y);
    };
    double x0 = 1e300, x1 = -1e300, y0 = 1e300, y1 = -1e300;
    for (size_t k = 0; k < flat.size(); ++k) {
      if (!mesh.Active(static_cast<int>(k))) continue;
      const cv::Point2d p = turned(flat[k]);
      x0 = std::min(x0, p.x);
      x1 = std::max(x1, p.x);
      y0 = std::min(y0, p.y);
      y1 = std::max(y1, p.y);
    }
    // Columns along +x, rows along -y: the camera's view from above, never mirrored.
    const double m = options.margin_mm;
    result.pixel_from_flat = cv::Matx23d(s * c, -s * n, s * (m - x0), -s * n, -s * c, s * (y1 + m));
    size = cv::Size(static_cast<int>(std::ceil(s * (x1 - x0 + 2 * m))) + 1,
                    static_cast<int>(std::ceil(s * (y1 - y0 + 2 * m))) + 1);
    if (static_cast<double>(size.width) * size.height > 400e6) {
      return Status::Error("the restored image would exceed 400 megapixels at " +
                           std::to_string(result.dpi) + " dpi");
    }
    for (size_t k = 0; k < flat.size(); ++k) {
      const cv::Matx23d& a = result.pixel_from_flat;
      (*dest)[k] = cv::Point2d(a(0, 0) * flat[k].x + a(0, 1) * flat[k].y + a(0, 2),
                               a(1, 0) * flat[k].x + a(1, 1) * flat[k].y + a(1, 2));
    }
  } else {
    size = camera.size;
    for (size_t k = 0; k < flat.size(); ++k) {
      if (mesh.Active(static_cast<int>(k)))
        (*dest)[k] = camera.Project(cv::Vec3d(flat[k].x, flat[k].y, 0));
    }
  }
  return Status::Ok();
}

// The triangles as the renderer takes them: each with its destination corners, its map back to
// the source pixels and its supersampling (from its largest stretch).
std::vector<Triangle> RenderTriangles(const std::vector<cv::Vec3i>& triangles, const Mesh& mesh,
                                      const std::vector<double>& tri_ppi,
                                      const std::vector<cv::Point2d>& dest,
                                      const RestoreOptions& options) {
  std::vector<Triangle> tris;
  tris.reserve(triangles.size());
  for (size_t k = 0; k < triangles.size(); ++k) {
    const cv::Vec3i& t = triangles[k];
    Triangle tri;
    tri.ppi = tri_ppi[k];
    for (int c = 0; c < 3; ++c) tri.d[c] = dest[t[c]];
    const cv::Matx22d dm(tri.d[1].x - tri.d[0].x, tri.d[2].x - tri.d[0].x, tri.d[1].y - tri.d[0].y,
                         tri.d[2].y - tri.d[0].y);
    const cv::Point2d s0 = mesh.pixel[t[0]], s1 = mesh.pixel[t[1]], s2 = mesh.pixel[t[2]];
    const cv::Matx22d sm(s1.x - s0.x, s2.x - s0.x, s1.y - s0.y, s2.y - s0.y);
    if (std::fabs(cv::determinant(dm)) < 1e-12) continue;
    const cv::Matx22d j = sm * dm.inv();  // Source pixels per destination pixel.
    const cv::Point2d off = s0 - cv::Point2d(j(0, 0) * tri.d[0].x + j(0, 1) * tri.d[0].y,
                                             j(1, 0) * tri.d[0].x + j(1, 1) * tri.d[0].y);
    tri.source_from_dest = cv::Matx23d(j(0, 0), j(0, 1), off.x, j(1, 0), j(1, 1), off.y);
    // Largest stretch of one output pixel in the source (the Jacobian's spectral norm), and from
    // it the supersampling. At the page's own sampling (a footprint just over 1) this takes 2 x 2
    // samples: rounding instead (1 sample up to 1.5) restores a 24 MP page in 638 ms, not 836,
    // but the ripple leaf's corners then move by 0.003 px more than its bar allows.
    double shortest, footprint;
    Stretches(j, &shortest, &footprint);
    tri.samples =
        std::clamp(static_cast<int>(std::ceil(footprint - 1e-6)), 1, options.max_supersampling);
    tris.push_back(tri);
  }
  return tris;
}

// The leaf's mask, the texture and the extras through the triangles, then (orthographic) the
// sampling map, and the crop to the leaf with its margin (*crop: the part of the whole image
// kept).
void RenderAndCrop(const cv::Mat& texture, const cv::Mat& leaf, const std::vector<cv::Mat>& extras,
                   const std::vector<Triangle>& tris, cv::Size size, const RestoreOptions& options,
                   RestoreResult* out, cv::Rect* crop_out) {
  RestoreResult& result = *out;
  if (!leaf.empty()) {
    // The mask is thresholded at half: one bilinear sample per pixel decides it (supersampling
    // would only smooth what the threshold takes away).
    cv::Mat restored_leaf = cv::Mat::zeros(size, CV_8U);
    const cv::Mat leaf255 = leaf != 0;
    const cv::Mat* source = &leaf255;
    cv::Mat* target = &restored_leaf;
    Render<uint8_t, 1>(&source, &target, 1, tris, 1);
    result.mask = restored_leaf >= 128;
  }
  std::vector<const cv::Mat*> sources = {&texture};
  for (const cv::Mat& extra : extras) sources.push_back(&extra);
  RenderImages(sources, tris, size, &result.extras);
  result.image = result.extras.front();
  result.extras.erase(result.extras.begin());
  cv::Rect& crop = *crop_out;
  crop = cv::Rect(0, 0, size.width, size.height);
  if (options.view == RestoreView::kOrthographic) {
    // The sampling map: each triangle filled with its true sampling, in the renderer's order (the
    // last triangle covering a pixel gives it), subpixel corners (4 fractional bits).
    result.sampling = cv::Mat::zeros(size, CV_32F);
    for (const Triangle& t : tris) {
      cv::Point corners[3];
      for (int c = 0; c < 3; ++c)
        corners[c] = cv::Point(cvRound(t.d[c].x * 16), cvRound(t.d[c].y * 16));
      cv::fillConvexPoly(result.sampling, corners, 3, cv::Scalar(t.ppi), cv::LINE_8, 4);
    }
    if (!result.mask.empty()) result.sampling.setTo(0, result.mask == 0);
  }
  if (options.crop_to_leaf && options.view == RestoreView::kOrthographic && !result.mask.empty() &&
      cv::countNonZero(result.mask) > 0) {
    // The leaf plus the margin: the map to pixels moves with the crop.
    const int m = static_cast<int>(std::ceil(options.margin_mm * result.dpi / 25.4));
    cv::Rect box = cv::boundingRect(result.mask);
    box = cv::Rect(box.x - m, box.y - m, box.width + 2 * m, box.height + 2 * m) &
          cv::Rect(0, 0, size.width, size.height);
    crop = box;
    result.image = result.image(box).clone();
    for (cv::Mat& extra : result.extras) extra = extra(box).clone();
    result.mask = result.mask(box).clone();
    result.sampling = result.sampling(box).clone();
    result.pixel_from_flat(0, 2) -= box.x;
    result.pixel_from_flat(1, 2) -= box.y;
  }
}

}  // namespace

RestoreResult Restore(const cv::Mat& texture, const Mesh& mesh,
                      const std::vector<cv::Point2d>& flat, const CameraModel& camera,
                      const RestoreOptions& options, const cv::Mat& leaf,
                      const std::vector<cv::Mat>& extras) {
  RestoreResult result;
  result.status = CheckRestoreInputs(texture, mesh, flat, options, leaf, extras);
  if (!result.status.ok()) return result;
  result.view = options.view;
  const std::vector<cv::Vec3i> triangles = SheetTriangles(mesh);
  const std::vector<double> tri_ppi = TriangleSampling(triangles, mesh, flat, &result.finest_ppi);
  // Destination pixel of every node.
  std::vector<cv::Point2d> dest(flat.size());
  cv::Size size;
  result.status = LayOut(mesh, flat, camera, options, leaf, &result, &dest, &size);
  if (!result.status.ok()) return result;
  std::vector<Triangle> tris = RenderTriangles(triangles, mesh, tri_ppi, dest, options);
  cv::Rect crop;
  RenderAndCrop(texture, leaf, extras, tris, size, options, &result, &crop);
  auto plan = std::make_shared<RestorePlan>();
  plan->tris = std::move(tris);
  plan->source = texture.size();
  plan->size = size;
  plan->crop = crop;
  result.plan = std::move(plan);
  result.status = Status::Ok();
  return result;
}

SheetFrame RestoredSheetFrame(const Mesh& mesh, const std::vector<cv::Point2d>& flat,
                              const RestoreResult& restored) {
  SheetFrame frame;
  const cv::Size size = restored.image.size();
  frame.right = cv::Mat::zeros(size, CV_32FC3);
  frame.up = cv::Mat::zeros(size, CV_32FC3);
  frame.normal = cv::Mat::zeros(size, CV_32FC3);
  if (restored.view != RestoreView::kOrthographic || flat.size() != mesh.point.size()) return frame;
  const cv::Matx23d& a = restored.pixel_from_flat;
  auto pixel = [&](int k) {
    return cv::Point2d(a(0, 0) * flat[k].x + a(0, 1) * flat[k].y + a(0, 2),
                       a(1, 0) * flat[k].x + a(1, 1) * flat[k].y + a(1, 2));
  };
  double area_sum = 0;
  int area_count = 0;
  for (const cv::Vec3i& t : SheetTriangles(mesh)) {
    const cv::Point2d d0 = pixel(t[0]), d1 = pixel(t[1]), d2 = pixel(t[2]);
    const cv::Matx22d dm(d1.x - d0.x, d2.x - d0.x, d1.y - d0.y, d2.y - d0.y);
    if (std::fabs(cv::determinant(dm)) < 1e-12) continue;
    area_sum += std::fabs(cv::determinant(dm));  // Twice the triangle's: one cell of the grid.
    ++area_count;
    const cv::Vec3d e1 = mesh.point[t[1]] - mesh.point[t[0]];
    const cv::Vec3d e2 = mesh.point[t[2]] - mesh.point[t[0]];
    const cv::Matx32d edges(e1[0], e2[0], e1[1], e2[1], e1[2], e2[2]);
    const cv::Matx32d j = edges * dm.inv();  // World mm per restored pixel, along x and y.
    const cv::Vec3d right = cv::normalize(cv::Vec3d(j(0, 0), j(1, 0), j(2, 0)));
    cv::Vec3d up(-j(0, 1), -j(1, 1), -j(2, 1));  // Rows run down the page.
    up = cv::normalize(up - up.dot(right) * right);
    const cv::Vec3d normal = right.cross(up);
    cv::Point corners[3];
    const cv::Point2d d[3] = {d0, d1, d2};
    for (int c = 0; c < 3; ++c) corners[c] = cv::Point(cvRound(d[c].x * 16), cvRound(d[c].y * 16));
    cv::fillConvexPoly(frame.right, corners, 3, cv::Scalar(right[0], right[1], right[2]),
                       cv::LINE_8, 4);
    cv::fillConvexPoly(frame.up, corners, 3, cv::Scalar(up[0], up[1], up[2]), cv::LINE_8, 4);
    cv::fillConvexPoly(frame.normal, corners, 3, cv::Scalar(normal[0], normal[1], normal[2]),
                       cv::LINE_8, 4);
  }
  if (area_count == 0) return frame;
  // Smoothed over about a cell of the grid (normalised within the sheet), so the frame turns
  // evenly from facet to facet instead of in steps at their edges; then made orthonormal again.
  const double sigma = 0.5 * std::sqrt(area_sum / area_count);
  cv::Mat weight;
  cv::extractChannel(frame.normal, weight, 2);
  weight = weight != 0;
  weight.convertTo(weight, CV_32F, 1.0 / 255);
  cv::Mat spread;
  cv::GaussianBlur(weight, spread, cv::Size(), sigma);
  cv::max(spread, 1e-6, spread);
  cv::Mat spread3;
  cv::merge(std::vector<cv::Mat>{spread, spread, spread}, spread3);
  for (cv::Mat* m : {&frame.right, &frame.normal}) {
    cv::GaussianBlur(*m, *m, cv::Size(), sigma);
    cv::divide(*m, spread3, *m);
  }
  for (int v = 0; v < size.height; ++v) {
    const float* w = weight.ptr<float>(v);
    cv::Vec3f* r = frame.right.ptr<cv::Vec3f>(v);
    cv::Vec3f* p = frame.up.ptr<cv::Vec3f>(v);
    cv::Vec3f* n = frame.normal.ptr<cv::Vec3f>(v);
    for (int u = 0; u < size.width; ++u) {
      if (w[u] == 0) {
        r[u] = p[u] = n[u] = cv::Vec3f(0, 0, 0);
        continue;
      }
      n[u] = cv::normalize(n[u]);
      r[u] = cv::normalize(r[u] - r[u].dot(n[u]) * n[u]);
      p[u] = n[u].cross(r[u]);
    }
  }
  return frame;
}

}  // namespace vellum
