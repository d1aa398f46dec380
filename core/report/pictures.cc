#include "core/report/pictures.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <unordered_map>

#include "core/common/depth.h"

namespace vellum {
namespace {

// A vertical colour bar beside a picture of `height` pixels: its `title` (what and in which
// unit) on top, then the ramp for [lo, hi] labelled at its ends and middle, each label beside
// its own level (the ramp is inset so that no label is cut at the picture's edge). The
// picture's colours span exactly [lo, hi]: nothing is clipped.
cv::Mat ColourBar(int height, double lo, double hi, const char* format, const char* title) {
  const int bar_w = 24, width = 130, head = 22, foot = 8;
  cv::Mat bar(std::max(height, head + foot + 16), width, CV_8UC3, cv::Scalar::all(255));
  cv::putText(bar, title, cv::Point(4, 14), cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar::all(0), 1,
              cv::LINE_AA);
  const int ramp_h = bar.rows - head - foot;
  cv::Mat ramp(ramp_h, 1, CV_8U);
  for (int y = 0; y < ramp_h; ++y)
    ramp.at<uint8_t>(y) =
        cv::saturate_cast<uint8_t>(255.0 * (ramp_h - 1 - y) / std::max(1, ramp_h - 1));
  cv::Mat colours;
  cv::applyColorMap(ramp, colours, cv::COLORMAP_TURBO);
  cv::resize(colours, colours, cv::Size(bar_w, ramp_h), 0, 0, cv::INTER_NEAREST);
  colours.copyTo(bar(cv::Rect(6, head, bar_w, ramp_h)));
  for (double f : {0.0, 0.5, 1.0}) {
    char text[48];
    std::snprintf(text, sizeof(text), format, lo + f * (hi - lo));
    const int y = head + static_cast<int>(std::lround((1 - f) * (ramp_h - 1)));
    cv::line(bar, cv::Point(6 + bar_w, y), cv::Point(bar_w + 12, y), cv::Scalar::all(0), 1);
    cv::putText(bar, text, cv::Point(bar_w + 14, y + 4), cv::FONT_HERSHEY_SIMPLEX, 0.4,
                cv::Scalar::all(0), 1, cv::LINE_AA);
  }
  return bar;
}

cv::Mat WithBar(const cv::Mat& picture, double lo, double hi, const char* format,
                const char* title) {
  cv::Mat bar = ColourBar(picture.rows, lo, hi, format, title);
  cv::Mat left = picture;
  if (bar.rows > left.rows) {  // A picture lower than the bar's labels: padded below.
    cv::copyMakeBorder(left, left, 0, bar.rows - left.rows, 0, 0, cv::BORDER_CONSTANT,
                       cv::Scalar::all(255));
  }
  cv::Mat out;
  cv::hconcat(left, bar, out);
  return out;
}

}  // namespace

cv::Mat ValidMask(const cv::Mat& points) {
  CV_Assert(points.type() == CV_32FC3);
  cv::Mat mask(points.size(), CV_8U);
  for (int v = 0; v < points.rows; ++v) {
    const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
    uint8_t* out = mask.ptr<uint8_t>(v);
    for (int u = 0; u < points.cols; ++u) out[u] = std::isnan(p[u][2]) ? 0 : 255;
  }
  return mask;
}

cv::Mat DepthPicture(const cv::Mat& points, double* z_min_mm, double* z_max_mm) {
  CV_Assert(points.type() == CV_32FC3);
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (int v = 0; v < points.rows; ++v) {
    const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
    for (int u = 0; u < points.cols; ++u) {
      const float z = p[u][2];
      if (std::isnan(z)) continue;
      lo = std::min(lo, z);
      hi = std::max(hi, z);
    }
  }
  *z_min_mm = lo <= hi ? lo : 0.0;
  *z_max_mm = lo <= hi ? hi : 1.0;
  // As convertTo to 8 bits (rounded, saturated) and then the turbo colour map.
  const double range = std::max(*z_max_mm - *z_min_mm, 1e-3);
  const double scale = 255.0 / range, shift = -*z_min_mm * 255.0 / range;
  cv::Mat levels(1, 256, CV_8U), turbo;
  for (int k = 0; k < 256; ++k) levels.at<uint8_t>(k) = static_cast<uint8_t>(k);
  cv::applyColorMap(levels, turbo, cv::COLORMAP_TURBO);
  const cv::Vec3b* colour = turbo.ptr<cv::Vec3b>(0);
  cv::Mat out(points.size(), CV_8UC3);
  for (int v = 0; v < points.rows; ++v) {
    const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
    cv::Vec3b* o = out.ptr<cv::Vec3b>(v);
    for (int u = 0; u < points.cols; ++u) {
      const float z = p[u][2];
      o[u] = std::isnan(z) ? cv::Vec3b(0, 0, 0)
                           : colour[cv::saturate_cast<uint8_t>(z * scale + shift)];
    }
  }
  return out;
}

cv::Mat WithHeightBar(const cv::Mat& depth, double z_min_mm, double z_max_mm) {
  const double range = std::max(z_max_mm - z_min_mm, 1e-3);
  return WithBar(depth, z_min_mm, z_min_mm + range, "%.1f", "height, mm");
}

std::function<cv::Point2d(const cv::Point2d&)> RestoredPixel(const RestoreResult& restored,
                                                             const CameraModel& camera) {
  if (restored.view == RestoreView::kOrthographic) {
    const cv::Matx23d a = restored.pixel_from_flat;
    return [a](const cv::Point2d& p) {
      return cv::Point2d(a(0, 0) * p.x + a(0, 1) * p.y + a(0, 2),
                         a(1, 0) * p.x + a(1, 1) * p.y + a(1, 2));
    };
  }
  return [camera](const cv::Point2d& p) { return camera.Project(cv::Vec3d(p.x, p.y, 0)); };
}

cv::Mat StrainPicture(const Mesh& mesh, const std::vector<cv::Point2d>& flat,
                      const RestoreResult& restored, const CameraModel& camera) {
  const auto to_pixel = RestoredPixel(restored, camera);
  // Strain per spring against its own rest length (measured along the surface where the leaf
  // bends: the chord between the nodes would show every crease as strain), then per quad (the
  // springs among its corners).
  const int64_t nodes = static_cast<int64_t>(mesh.point.size());
  std::unordered_map<int64_t, double> rest;
  rest.reserve(mesh.springs.size());
  for (const Spring& s : mesh.springs) {
    rest[std::min(s.a, s.b) * nodes + std::max(s.a, s.b)] = s.rest_mm;
  }
  std::vector<double> sum(mesh.quads.size(), 0.0);
  std::vector<int> count(mesh.quads.size(), 0);
  double max_strain = 0;
  for (size_t q = 0; q < mesh.quads.size(); ++q) {
    const cv::Vec4i& c = mesh.quads[q];
    for (auto [i, j] : {std::pair{0, 1}, {1, 2}, {2, 3}, {3, 0}, {0, 2}, {1, 3}}) {
      const auto it = rest.find(std::min(c[i], c[j]) * nodes + std::max(c[i], c[j]));
      if (it == rest.end() || !(it->second > 0)) continue;
      sum[q] += std::fabs(cv::norm(flat[c[i]] - flat[c[j]]) / it->second - 1.0);
      ++count[q];
    }
    if (count[q]) max_strain = std::max(max_strain, sum[q] / count[q]);
  }
  max_strain = std::max(max_strain, 1e-6);
  cv::Mat picture(restored.image.size(), CV_8UC3, cv::Scalar::all(255));
  // The colour map's 256 colours once (a colour map per quad cost half a second on a fine sheet).
  cv::Mat levels(1, 256, CV_8U), colours;
  for (int k = 0; k < 256; ++k) levels.at<uint8_t>(k) = static_cast<uint8_t>(k);
  cv::applyColorMap(levels, colours, cv::COLORMAP_TURBO);
  std::vector<cv::Point> corners(4);
  for (size_t q = 0; q < mesh.quads.size(); ++q) {
    for (int k = 0; k < 4; ++k) {
      const cv::Point2d p = to_pixel(flat[mesh.quads[q][k]]);
      corners[k] = cv::Point(cvRound(p.x), cvRound(p.y));
    }
    const double mean = count[q] ? sum[q] / count[q] : 0.0;
    const int level = cv::saturate_cast<uint8_t>(255.0 * mean / max_strain);
    const cv::Vec3b c = colours.at<cv::Vec3b>(level);
    cv::fillConvexPoly(picture, corners, cv::Scalar(c[0], c[1], c[2]), cv::LINE_AA);
  }
  return WithBar(picture, 0, max_strain, "%.1e", "strain (quad mean)");
}

cv::Mat SamplingPicture(const cv::Mat& sampling) {
  struct Band {
    double from;
    cv::Scalar colour;  // BGR
    const char* label;
  };
  const Band bands[] = {{400, cv::Scalar(60, 140, 30), ">= 400 ppi"},
                        {300, cv::Scalar(120, 210, 140), "300-400 ppi"},
                        {200, cv::Scalar(40, 170, 250), "200-300 ppi"},
                        {1e-6, cv::Scalar(50, 50, 210), "< 200 ppi"}};
  cv::Mat picture(sampling.size(), CV_8UC3, cv::Scalar::all(255));
  cv::Mat taken = cv::Mat::zeros(sampling.size(), CV_8U);
  for (const Band& b : bands) {
    const cv::Mat in = (sampling >= b.from) & ~taken;
    picture.setTo(b.colour, in);
    taken |= in;
  }
  // The legend on the right: a swatch and its band per line.
  const int width = 130, line = 20;
  cv::Mat legend(std::max(picture.rows, 4 * line + 8), width, CV_8UC3, cv::Scalar::all(255));
  for (int k = 0; k < 4; ++k) {
    const int y = 6 + k * line;
    cv::rectangle(legend, cv::Rect(6, y, 16, 14), bands[k].colour, cv::FILLED);
    cv::putText(legend, bands[k].label, cv::Point(28, y + 12), cv::FONT_HERSHEY_SIMPLEX, 0.4,
                cv::Scalar::all(0), 1, cv::LINE_AA);
  }
  if (legend.rows > picture.rows) {
    cv::copyMakeBorder(picture, picture, 0, legend.rows - picture.rows, 0, 0, cv::BORDER_CONSTANT,
                       cv::Scalar::all(255));
  }
  cv::Mat out;
  cv::hconcat(picture, legend, out);
  return out;
}

cv::Mat GridOverPage(const Mesh& mesh, const std::vector<cv::Point2d>& flat,
                     const RestoreResult& restored, const CameraModel& camera, int step) {
  const auto to_pixel = RestoredPixel(restored, camera);
  cv::Mat picture = EightBitBgr(restored.image).clone();
  const int thickness = std::max(1, picture.cols / 600);
  auto line = [&](int a, int b) {
    if (!mesh.Active(a) || !mesh.Active(b)) return;
    const cv::Point2d p = to_pixel(flat[a]), q = to_pixel(flat[b]);
    cv::line(picture, cv::Point(cvRound(p.x), cvRound(p.y)), cv::Point(cvRound(q.x), cvRound(q.y)),
             cv::Scalar(40, 200, 40), thickness, cv::LINE_AA);
  };
  for (int j = 0; j < mesh.rows; ++j) {
    for (int i = 0; i < mesh.cols; ++i) {
      if (j % step == 0 && i + 1 < mesh.cols) line(mesh.Index(i, j), mesh.Index(i + 1, j));
      if (i % step == 0 && j + 1 < mesh.rows) line(mesh.Index(i, j), mesh.Index(i, j + 1));
    }
  }
  return picture;
}

cv::Mat RestoredWithScaleBar(const RestoreResult& restored, int max_width, double* bar_mm) {
  cv::Mat page = EightBitBgr(restored.image);
  double scale = 1;
  if (page.cols > max_width) {
    scale = static_cast<double>(max_width) / page.cols;
    cv::resize(page, page, cv::Size(), scale, scale, cv::INTER_AREA);
  } else {
    page = page.clone();
  }
  *bar_mm = 0;
  if (restored.view != RestoreView::kOrthographic || restored.dpi <= 0) return page;
  const double px_per_mm = scale * restored.dpi / 25.4;
  const double width_mm = page.cols / px_per_mm;
  for (double mm : {1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0}) {
    if (mm <= 0.3 * width_mm) *bar_mm = mm;
  }
  if (*bar_mm == 0) return page;
  const int length = static_cast<int>(std::lround(*bar_mm * px_per_mm));
  const int thick = std::max(6, page.cols / 120), margin = std::max(8, page.cols / 60);
  const cv::Point origin(margin, page.rows - margin - thick);
  char label[32];
  std::snprintf(label, sizeof(label), "%g mm", *bar_mm);
  const double font = std::max(0.4, page.cols / 1400.0);
  int baseline = 0;
  const cv::Size text = cv::getTextSize(label, cv::FONT_HERSHEY_SIMPLEX, font, 1, &baseline);
  // A white ground, then five black and white segments, outlined.
  cv::rectangle(page,
                cv::Rect(origin.x - 4, origin.y - text.height - 10,
                         std::max(length, text.width) + 8, text.height + thick + 14),
                cv::Scalar::all(255), cv::FILLED);
  for (int k = 0; k < 5; ++k) {
    const int x0 = origin.x + length * k / 5, x1 = origin.x + length * (k + 1) / 5;
    cv::rectangle(page, cv::Rect(x0, origin.y, x1 - x0, thick),
                  k % 2 == 0 ? cv::Scalar::all(0) : cv::Scalar::all(255), cv::FILLED);
  }
  cv::rectangle(page, cv::Rect(origin.x, origin.y, length, thick), cv::Scalar::all(0), 1);
  cv::putText(page, label, cv::Point(origin.x, origin.y - 5), cv::FONT_HERSHEY_SIMPLEX, font,
              cv::Scalar::all(0), 1, cv::LINE_AA);
  return page;
}

cv::Mat BeforeAfter(const cv::Mat& texture, const Mesh& mesh, const std::vector<cv::Point2d>& flat,
                    const RestoreResult& restored, const CameraModel& camera, double size_mm) {
  // The active node nearest the sheet's centre.
  int centre = -1;
  double best = 1e300;
  for (int k = 0; k < static_cast<int>(mesh.kind.size()); ++k) {
    if (!mesh.Active(k)) continue;
    const double d =
        std::hypot(k % mesh.cols - 0.5 * (mesh.cols - 1), k / mesh.cols - 0.5 * (mesh.rows - 1));
    if (d < best) best = d, centre = k;
  }
  cv::Mat before = EightBitBgr(texture), after = EightBitBgr(restored.image);
  if (centre < 0) return before;
  const auto to_pixel = RestoredPixel(restored, camera);
  // Window sizes in pixels from the local scale of each image (pixels per mm).
  const int right = centre % mesh.cols + 1 < mesh.cols ? centre + 1 : centre - 1;
  const double mm = std::max(cv::norm(mesh.point[centre] - mesh.point[right]), 1e-6);
  const double before_scale = cv::norm(mesh.pixel[centre] - mesh.pixel[right]) / mm;
  const double after_scale = cv::norm(to_pixel(flat[centre]) - to_pixel(flat[right])) / mm;
  auto crop = [&](const cv::Mat& image, cv::Point2d c, double scale) {
    const int half = std::max(8, static_cast<int>(std::lround(0.5 * size_mm * scale)));
    cv::Rect r(cvRound(c.x) - half, cvRound(c.y) - half, 2 * half, 2 * half);
    r &= cv::Rect(0, 0, image.cols, image.rows);
    cv::Mat out;
    cv::resize(image(r), out, cv::Size(320, std::max(1, 320 * r.height / std::max(1, r.width))), 0,
               0, cv::INTER_AREA);
    return out;
  };
  cv::Mat a = crop(before, mesh.pixel[centre], before_scale);
  cv::Mat b = crop(after, to_pixel(flat[centre]), after_scale);
  const int h = std::max(a.rows, b.rows);
  cv::Mat out(h, a.cols + b.cols + 8, CV_8UC3, cv::Scalar::all(255));
  a.copyTo(out(cv::Rect(0, 0, a.cols, a.rows)));
  b.copyTo(out(cv::Rect(a.cols + 8, 0, b.cols, b.rows)));
  return out;
}

cv::Mat ReliefPicture(const cv::Mat& normals) {
  CV_Assert(normals.type() == CV_32FC3);
  const double e = 30 * M_PI / 180;
  const cv::Vec3f light(static_cast<float>(-std::cos(e) * M_SQRT1_2),
                        static_cast<float>(std::cos(e) * M_SQRT1_2),
                        static_cast<float>(std::sin(e)));
  // A flat page shows mid-gray; a slope facing the light up to white.
  const float flat = light[2];
  cv::Mat out = cv::Mat::zeros(normals.size(), CV_8U);
  for (int v = 0; v < normals.rows; ++v) {
    const cv::Vec3f* n = normals.ptr<cv::Vec3f>(v);
    uint8_t* o = out.ptr<uint8_t>(v);
    for (int u = 0; u < normals.cols; ++u) {
      if (n[u].dot(n[u]) < 0.25f) continue;
      o[u] = cv::saturate_cast<uint8_t>(128.0f + 127.0f * (n[u].dot(light) - flat) / (1 - flat));
    }
  }
  return out;
}

}  // namespace vellum
