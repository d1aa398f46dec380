#include "core/sim/gantry.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

namespace vellum {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr double kMeshStepMm = 1.0;  // Rasterisation mesh; Newton refinement makes it exact.

// Depth-buffer rasterisation of the pages' meshes into a device image (scaled by `scale`),
// storing the device-frame depth of the nearest surface and, when asked, its page coordinate
// and which page it is (1 + the index; 0 where no page is). Triangles off a leaf's outline
// (burnt edges, holes) are left out, so rays and light pass there.
void Rasterize(const CameraModel& device, double scale, const std::vector<Page>& pages,
               cv::Mat* depth, cv::Mat* page_coord, cv::Mat* page_index) {
  const cv::Size size(static_cast<int>(device.size.width * scale),
                      static_cast<int>(device.size.height * scale));
  depth->create(size, CV_32F);
  depth->setTo(std::numeric_limits<float>::infinity());
  if (page_coord) {
    page_coord->create(size, CV_32FC2);
    page_coord->setTo(cv::Scalar(kNaN, kNaN));
  }
  if (page_index) {
    page_index->create(size, CV_8U);
    page_index->setTo(0);
  }
  for (size_t index = 0; index < pages.size(); ++index) {
    const Page& page = pages[index];
    const double w = page.options().size_mm.width, h = page.options().size_mm.height;
    const int ns = static_cast<int>(std::ceil(w / kMeshStepMm)) + 1;
    const int nt = static_cast<int>(std::ceil(h / kMeshStepMm)) + 1;
    std::vector<cv::Vec3d> vert(static_cast<size_t>(ns) * nt);  // Image x, y, depth.
    std::vector<cv::Vec2d> st(vert.size());
    for (int j = 0; j < nt; ++j) {
      for (int i = 0; i < ns; ++i) {
        const double s = std::min(w, i * kMeshStepMm), t = std::min(h, j * kMeshStepMm);
        const cv::Vec3d x = page.Point(s, t);
        const cv::Point2d p = device.Project(x);
        const double z = (device.rotation * x + device.translation)[2];
        // Pixel centres of the scaled image sit at (i + 0.5) / scale - 0.5 device pixels.
        vert[j * ns + i] = {(p.x + 0.5) * scale - 0.5, (p.y + 0.5) * scale - 0.5, z};
        st[j * ns + i] = {s, t};
      }
    }
    auto raster = [&](int ia, int ib, int ic) {
      const cv::Vec3d &a = vert[ia], &b = vert[ib], &c = vert[ic];
      if (!std::isfinite(a[0]) || !std::isfinite(b[0]) || !std::isfinite(c[0])) return;
      const cv::Vec2d centroid = (st[ia] + st[ib] + st[ic]) / 3.0;
      if (!page.Contains(centroid[0], centroid[1])) return;
      const double area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
      if (std::fabs(area) < 1e-12) return;
      const int x0 = std::max(0, static_cast<int>(std::ceil(std::min({a[0], b[0], c[0]}))));
      const int x1 =
          std::min(size.width - 1, static_cast<int>(std::floor(std::max({a[0], b[0], c[0]}))));
      const int y0 = std::max(0, static_cast<int>(std::ceil(std::min({a[1], b[1], c[1]}))));
      const int y1 =
          std::min(size.height - 1, static_cast<int>(std::floor(std::max({a[1], b[1], c[1]}))));
      for (int y = y0; y <= y1; ++y) {
        for (int x = x0; x <= x1; ++x) {
          const double wa = ((b[0] - x) * (c[1] - y) - (b[1] - y) * (c[0] - x)) / area;
          const double wb = ((c[0] - x) * (a[1] - y) - (c[1] - y) * (a[0] - x)) / area;
          const double wc = 1.0 - wa - wb;
          if (wa < -1e-9 || wb < -1e-9 || wc < -1e-9) continue;
          const float z = static_cast<float>(wa * a[2] + wb * b[2] + wc * c[2]);
          float& zb = depth->at<float>(y, x);
          if (z < zb) {
            zb = z;
            if (page_coord) {
              const cv::Vec2d p = wa * st[ia] + wb * st[ib] + wc * st[ic];
              page_coord->at<cv::Vec2f>(y, x) =
                  cv::Vec2f(static_cast<float>(p[0]), static_cast<float>(p[1]));
            }
            if (page_index) page_index->at<uint8_t>(y, x) = static_cast<uint8_t>(index + 1);
          }
        }
      }
    };
    for (int j = 0; j + 1 < nt; ++j) {
      for (int i = 0; i + 1 < ns; ++i) {
        const int q = j * ns + i;
        raster(q, q + 1, q + ns + 1);
        raster(q, q + ns + 1, q + ns);
      }
    }
  }
}

}  // namespace

Calibration DefaultRig() {
  Calibration rig;
  CameraModel& cam = rig.camera;
  cam.size = {1600, 1200};
  cam.matrix = cv::Matx33d(2400, 0, 799.5, 0, 2400, 599.5, 0, 0, 1);
  cam.distortion = cv::Vec<double, 5>(-0.02, 0.01, 0, 0, 0);
  const cv::Vec3d cam_eye(0, 0, 600);
  cam.rotation = LookAt(cam_eye, {0, 0, 0}, {1, 0, 0});
  cam.translation = -(cam.rotation * cam_eye);
  CameraModel& prj = rig.projector;
  prj.size = {1024, 768};
  prj.matrix = cv::Matx33d(1800, 0, 511.5, 0, 1800, 383.5, 0, 0, 1);
  const cv::Vec3d prj_eye(-225, 0, 650);
  prj.rotation = LookAt(prj_eye, {0, 0, 0}, {1, 0, 0});
  prj.translation = -(prj.rotation * prj_eye);
  return rig;
}

Calibration QuickRig() {
  Calibration rig = DefaultRig();
  rig.camera.size = {400, 300};
  rig.camera.matrix = cv::Matx33d(600, 0, 199.5, 0, 600, 149.5, 0, 0, 1);
  rig.projector.size = {320, 200};
  rig.projector.matrix = cv::Matx33d(560, 0, 159.5, 0, 560, 99.5, 0, 0, 1);
  return rig;
}

bool LightOptions::Check(std::string* why) const {
  auto share = [](double x) { return x >= 0 && x <= 1; };
  if (!(ambient >= 0) || !(projector_gain >= 0) || !(studio_light >= 0) ||
      !(defocus_sigma_px >= 0) || !(noise_dn >= 0) || !share(table_albedo) || !share(grain) ||
      !(shadow_bias_mm > 0) || albedo_supersampling < 1 || !(camera_blur_px >= 0) ||
      !(shot_noise_dn >= 0) || (texture_bits != 8 && texture_bits != 16) ||
      !(projector_vignetting >= 0 && projector_vignetting < 1)) {
    *why =
        "light: ambient, projector_gain, studio_light, defocus_sigma_px, noise_dn, camera_blur_px "
        "and shot_noise_dn must be >= 0, table_albedo and grain in [0, 1], shadow_bias_mm > 0, "
        "albedo_supersampling >= 1, texture_bits 8 or 16, projector_vignetting in [0, 1)";
    return false;
  }
  return true;
}

bool SceneOptions::Check(std::string* why) const {
  auto share = [](double x) { return x >= 0 && x <= 1; };
  if (!(support_mm.width > 0 && support_mm.height > 0) || !(support_height_mm >= 0) ||
      !share(support_albedo) || !(frame_mm.width > 0 && frame_mm.height > 0) ||
      !(frame_window_margin_mm >= 0) || !(frame_thickness_mm >= 0) || !share(frame_albedo) ||
      !(spread_gap_mm >= 0)) {
    *why =
        "scene: support_mm and frame_mm must have a size > 0, support_height_mm, "
        "frame_window_margin_mm, frame_thickness_mm and spread_gap_mm >= 0, support_albedo and "
        "frame_albedo in [0, 1]";
    return false;
  }
  return true;
}

VirtualGantry::VirtualGantry(const Calibration& rig, const PageOptions& page_options,
                             const TextureOptions& texture_options, const LightOptions& light,
                             const SceneOptions& scene)
    : rig_(rig), light_(light), scene_(scene) {
  if (std::string why; !light.Check(&why) || !scene.Check(&why)) {
    throw std::invalid_argument("virtual gantry: " + why);
  }
  if (light.grain > 0) {
    // Eight waves of random direction, wavelength 2 to 40 mm and phase.
    cv::RNG rng(light.grain_seed);
    for (int k = 0; k < 8; ++k) {
      const double angle = rng.uniform(0.0, M_PI), length = rng.uniform(2.0, 40.0);
      grain_waves_.emplace_back(2 * M_PI * std::cos(angle) / length,
                                2 * M_PI * std::sin(angle) / length, rng.uniform(0.0, 2 * M_PI));
    }
  }
  PageOptions base = page_options;
  base.base_mm = scene.support ? scene.support_height_mm : 0.0;
  if (scene.spread) {
    // An open book: two pages bending down into a gutter along y at x = 0, left and right of
    // it as the camera sees them (the camera's image x runs along world x).
    for (bool left : {true, false}) {
      PageOptions o = base;
      o.shape = PageShape::kGutter;
      o.gutter_left = !left;  // The left page's gutter is its s = w edge.
      o.centre_mm = {0.0, base.centre_mm[1]};
      const double gutter_x = Page(o).Point(left ? o.size_mm.width : 0.0, 0)[0];
      o.centre_mm[0] = (left ? -1 : 1) * scene.spread_gap_mm / 2 - gutter_x;
      pages_.emplace_back(o);
    }
  } else {
    pages_.emplace_back(base);
  }
  std::vector<PageTexture> textures;
  for (size_t k = 0; k < pages_.size(); ++k) {
    TextureOptions t = texture_options;
    t.seed = texture_options.seed + k;
    textures.emplace_back(t, pages_[k].options().size_mm);
  }
  TraceCamera();
  ShadeSetup(textures);
}

cv::Vec3d VirtualGantry::Background(const cv::Vec3d& centre, const cv::Vec3d& ray,
                                    double* albedo) const {
  if (!(ray[2] < 0)) return cv::Vec3d(kNaN, kNaN, kNaN);
  auto at = [&](double z) { return centre + ((z - centre[2]) / ray[2]) * ray; };
  auto inside = [](const cv::Rect2d& r, const cv::Vec3d& x) {
    return x[0] >= r.x && x[0] <= r.x + r.width && x[1] >= r.y && x[1] <= r.y + r.height;
  };
  const double base = scene_.support ? scene_.support_height_mm : 0.0;
  cv::Vec3d x = at(0.0);
  *albedo = light_.table_albedo;
  const cv::Vec3d on_frame = at(base + scene_.frame_thickness_mm);
  const cv::Vec3d on_support = at(scene_.support_height_mm);
  if (scene_.frame && inside(scene_.frame_mm, on_frame) && !inside(FrameWindow(), on_frame)) {
    *albedo = scene_.frame_albedo;
    x = on_frame;
  } else if (scene_.support && inside(scene_.support_mm, on_support)) {
    *albedo = scene_.support_albedo;
    x = on_support;
  }
  if (!grain_waves_.empty()) {
    double sum = 0;
    for (const cv::Vec3d& w : grain_waves_) sum += std::sin(w[0] * x[0] + w[1] * x[1] + w[2]);
    *albedo *= 1 + light_.grain * sum / grain_waves_.size();
  }
  return x;
}

cv::Rect2d VirtualGantry::FrameWindow() const {
  const PageOptions& o = pages_.front().options();
  const double m = scene_.frame_window_margin_mm;
  return {o.centre_mm[0] - o.size_mm.width / 2 - m, o.centre_mm[1] - o.size_mm.height / 2 - m,
          o.size_mm.width + 2 * m, o.size_mm.height + 2 * m};
}

void VirtualGantry::TraceCamera() {
  const CameraModel& cam = rig_.camera;
  const cv::Size size = cam.size;
  cv::Mat depth, guess, index;
  Rasterize(cam, 1.0, pages_, &depth, &guess, &index);
  truth_.points.create(size, CV_32FC3);
  truth_.page.create(size, CV_32FC2);
  truth_.on_page.create(size, CV_8U);
  truth_.page_index.create(size, CV_8U);
  background_albedo_.create(size, CV_32F);
  const cv::Vec3d centre = cam.Center();
  cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& range) {
    for (int v = range.start; v < range.end; ++v) {
      for (int u = 0; u < size.width; ++u) {
        const cv::Point2d pixel(u, v);
        cv::Vec2f& pc = truth_.page.at<cv::Vec2f>(v, u);
        const cv::Vec2f g = guess.at<cv::Vec2f>(v, u);
        const int k = index.at<uint8_t>(v, u);
        bool hit = false;
        cv::Vec3d x;
        if (k > 0 && !std::isnan(g[0])) {
          const Page& page = pages_[k - 1];
          // Newton on Project(Page(s, t)) = pixel, from the mesh's guess.
          double s = g[0], t = g[1];
          for (int it = 0; it < 6; ++it) {
            const cv::Point2d p = cam.Project(page.Point(s, t));
            const cv::Point2d r = p - pixel;
            const double e = 1e-4;
            const cv::Point2d ps = (cam.Project(page.Point(s + e, t)) - p) / e;
            const cv::Point2d pt = (cam.Project(page.Point(s, t + e)) - p) / e;
            const double det = ps.x * pt.y - ps.y * pt.x;
            if (std::fabs(det) < 1e-12) break;
            const double ds = (r.x * pt.y - r.y * pt.x) / det;
            const double dt = (ps.x * r.y - ps.y * r.x) / det;
            s -= ds;
            t -= dt;
            if (ds * ds + dt * dt < 1e-16) break;
          }
          const cv::Point2d p = cam.Project(page.Point(s, t));
          hit = page.Contains(s, t) && cv::norm(p - pixel) < 1e-6;
          if (hit) {
            x = page.Point(s, t);
            pc = cv::Vec2f(static_cast<float>(s), static_cast<float>(t));
          }
        }
        double albedo = 0;
        if (!hit) {
          x = Background(centre, cam.RayDirection(pixel), &albedo);
          pc = cv::Vec2f(kNaN, kNaN);
        }
        truth_.points.at<cv::Vec3f>(v, u) =
            cv::Vec3f(static_cast<float>(x[0]), static_cast<float>(x[1]), static_cast<float>(x[2]));
        truth_.on_page.at<uint8_t>(v, u) = hit ? 255 : 0;
        truth_.page_index.at<uint8_t>(v, u) = hit ? static_cast<uint8_t>(k) : 0;
        background_albedo_.at<float>(v, u) = static_cast<float>(albedo);
      }
    }
  });
}

void VirtualGantry::ShadeSetup(const std::vector<PageTexture>& textures) {
  const CameraModel& prj = rig_.projector;
  const cv::Size size = rig_.camera.size;
  constexpr double kShadowScale = 2.0;
  cv::Mat shadow_depth;
  Rasterize(prj, kShadowScale, pages_, &shadow_depth, nullptr, nullptr);
  projector_map_.create(size, CV_32FC2);
  gain_.create(size, CV_32F);
  offset_.create(size, CV_32F);
  albedo_.create(size, CV_32F);
  studio_.create(size, CV_32F);
  normal_.create(size, CV_32FC3);
  const bool coloured = std::any_of(textures.begin(), textures.end(),
                                    [](const PageTexture& t) { return t.coloured(); });
  if (coloured) colour_albedo_.create(size, CV_32FC3);
  truth_.lit.create(size, CV_8U);
  const cv::Vec3d prj_centre = prj.Center();
  const int ss = std::max(1, light_.albedo_supersampling);
  // The projector's fall-off (LightOptions::projector_falloff) and the studio lamps' light.
  const double d0 = cv::norm(prj_centre);
  const cv::Point2d prj_middle(prj.matrix(0, 2), prj.matrix(1, 2));
  const double half_diagonal = 0.5 * std::hypot(prj.size.width, prj.size.height);
  auto lamps_at = [&](const cv::Vec3d& x, const cv::Vec3d& n) {
    double sum = 0;
    for (const cv::Vec3d& lamp : light_.studio_lamps) {
      const cv::Vec3d to = lamp - x;
      const double d2 = to.dot(to);
      sum += std::max(0.0, n.dot(to) / std::sqrt(d2)) / d2;
    }
    return sum;
  };
  const double lamps_at_origin = lamps_at(cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 1));
  cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& range) {
    for (int v = range.start; v < range.end; ++v) {
      for (int u = 0; u < size.width; ++u) {
        const cv::Vec3f xf = truth_.points.at<cv::Vec3f>(v, u);
        const cv::Vec3d x(xf[0], xf[1], xf[2]);
        const int k = truth_.page_index.at<uint8_t>(v, u);
        const cv::Vec2f st = truth_.page.at<cv::Vec2f>(v, u);
        double albedo = background_albedo_.at<float>(v, u);
        cv::Vec3d normal(0, 0, 1);
        if (k > 0) {
          normal = pages_[k - 1].Normal(st[0], st[1]);
          // Area-average the albedo over the pixel using the local page-from-pixel Jacobian.
          auto page_at = [&](int uu, int vv, cv::Vec2f* out) {
            if (uu < 0 || vv < 0 || uu >= size.width || vv >= size.height) return false;
            if (truth_.page_index.at<uint8_t>(vv, uu) != k) return false;
            *out = truth_.page.at<cv::Vec2f>(vv, uu);
            return true;
          };
          cv::Vec2f a, b;
          cv::Vec2d du(0, 0), dv(0, 0);
          if (page_at(u + 1, v, &a) && page_at(u - 1, v, &b)) du = cv::Vec2d(a - b) * 0.5;
          if (page_at(u, v + 1, &a) && page_at(u, v - 1, &b)) dv = cv::Vec2d(a - b) * 0.5;
          double sum = 0;
          for (int j = 0; j < ss; ++j) {
            for (int i = 0; i < ss; ++i) {
              const double ou = (i + 0.5) / ss - 0.5, ov = (j + 0.5) / ss - 0.5;
              const cv::Vec2d p = cv::Vec2d(st[0], st[1]) + ou * du + ov * dv;
              sum += textures[k - 1].Albedo(p[0], p[1]);
            }
          }
          albedo = sum / (ss * ss);
        }
        if (coloured) {
          colour_albedo_.at<cv::Vec3f>(v, u) =
              static_cast<float>(albedo) *
              (k > 0 ? cv::Vec3f(textures[k - 1].Tint(st[0], st[1])) : cv::Vec3f(1, 1, 1));
        }
        const cv::Point2d p = prj.Project(x);
        const double depth = (prj.rotation * x + prj.translation)[2];
        const double cos_in = normal.dot(cv::normalize(prj_centre - x));
        bool lit = std::isfinite(p.x) && p.x > -0.5 && p.y > -0.5 && p.x < prj.size.width - 0.5 &&
                   p.y < prj.size.height - 0.5 && cos_in > 0;
        if (lit) {
          const int sx = static_cast<int>((p.x + 0.5) * kShadowScale);
          const int sy = static_cast<int>((p.y + 0.5) * kShadowScale);
          const float occluder = shadow_depth.at<float>(std::min(sy, shadow_depth.rows - 1),
                                                        std::min(sx, shadow_depth.cols - 1));
          lit = depth <= occluder + light_.shadow_bias_mm;
        }
        projector_map_.at<cv::Vec2f>(v, u) =
            cv::Vec2f(static_cast<float>(p.x), static_cast<float>(p.y));
        albedo_.at<float>(v, u) = static_cast<float>(albedo);
        double falloff = 1;
        if (light_.projector_falloff && lit) {
          const double d = cv::norm(x - prj_centre);
          const double r = cv::norm(p - prj_middle) / half_diagonal;
          falloff = (d0 * d0) / (d * d) * (1 - light_.projector_vignetting * r * r);
        }
        gain_.at<float>(v, u) =
            lit ? static_cast<float>(255.0 * albedo * light_.projector_gain * cos_in * falloff)
                : 0.0f;
        studio_.at<float>(v, u) = light_.studio_lamps.empty() || !(lamps_at_origin > 0)
                                      ? 1.0f
                                      : static_cast<float>(lamps_at(x, normal) / lamps_at_origin);
        offset_.at<float>(v, u) = static_cast<float>(255.0 * albedo * light_.ambient);
        truth_.lit.at<uint8_t>(v, u) = lit ? 255 : 0;
        normal_.at<cv::Vec3f>(v, u) = cv::Vec3f(normal);
      }
    }
  });
}

cv::Mat VirtualGantry::RenderFrame(const cv::Mat& projector_image, uint64_t seed) const {
  CV_Assert(projector_image.type() == CV_8U && projector_image.size() == rig_.projector.size);
  cv::Mat pattern;
  projector_image.convertTo(pattern, CV_32F, 1.0 / 255.0);
  if (light_.defocus_sigma_px > 0) {
    cv::GaussianBlur(pattern, pattern, cv::Size(0, 0), light_.defocus_sigma_px, 0,
                     cv::BORDER_CONSTANT);
  }
  cv::Mat noise(rig_.camera.size, CV_32F);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::NORMAL, 0.0, light_.noise_dn);
  cv::Mat frame(rig_.camera.size, CV_8U);
  const bool plain = light_.camera_blur_px <= 0 && light_.shot_noise_dn <= 0;
  cv::Mat clean;  // The light before the camera's lens and noise, where those are modelled.
  if (!plain) clean.create(rig_.camera.size, CV_32F);
  const int pw = pattern.cols, ph = pattern.rows;
  cv::parallel_for_(cv::Range(0, frame.rows), [&](const cv::Range& range) {
    for (int v = range.start; v < range.end; ++v) {
      const cv::Vec2f* map = projector_map_.ptr<cv::Vec2f>(v);
      const float* gain = gain_.ptr<float>(v);
      const float* offset = offset_.ptr<float>(v);
      const float* n = noise.ptr<float>(v);
      uint8_t* out = frame.ptr<uint8_t>(v);
      for (int u = 0; u < frame.cols; ++u) {
        float light = 0.0f;
        if (gain[u] > 0) {
          // Exact bilinear sample (cv::remap quantises positions to 1/32 pixel).
          const float x = std::clamp(map[u][0], 0.0f, pw - 1.0f);
          const float y = std::clamp(map[u][1], 0.0f, ph - 1.0f);
          const int x0 = std::min(static_cast<int>(x), pw - 2);
          const int y0 = std::min(static_cast<int>(y), ph - 2);
          const float fx = x - x0, fy = y - y0;
          const float* r0 = pattern.ptr<float>(y0);
          const float* r1 = pattern.ptr<float>(y0 + 1);
          light = (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x0 + 1]) +
                  fy * ((1 - fx) * r1[x0] + fx * r1[x0 + 1]);
        }
        if (plain) {
          out[u] = cv::saturate_cast<uint8_t>(std::lround(offset[u] + gain[u] * light + n[u]));
        } else {
          clean.at<float>(v, u) = offset[u] + gain[u] * light;
        }
      }
    }
  });
  if (!plain) {
    Camera(&clean, noise, seed);
    clean.convertTo(frame, CV_8U);  // Rounds and saturates.
  }
  return frame;
}

void VirtualGantry::Camera(cv::Mat* clean, const cv::Mat& noise, uint64_t seed) const {
  if (light_.camera_blur_px > 0) {
    cv::GaussianBlur(*clean, *clean, cv::Size(0, 0), light_.camera_blur_px, 0,
                     cv::BORDER_REPLICATE);
  }
  if (light_.shot_noise_dn > 0) {
    cv::Mat shot(clean->size(), clean->type()), level;
    cv::RNG rng(seed ^ 0x5eed5eed5eedULL);
    rng.fill(shot, cv::RNG::NORMAL, 0.0, light_.shot_noise_dn);
    cv::sqrt(cv::max(*clean, 0.0) / 255.0, level);
    *clean += shot.mul(level);
  }
  *clean += noise;
}

std::vector<SceneLight> RakingLights(int count, double elevation_deg, double azimuth_deg) {
  std::vector<SceneLight> lights;
  const double e = elevation_deg * M_PI / 180;
  for (int k = 0; k < count; ++k) {
    const double a_deg = std::fmod(azimuth_deg + 360.0 * k / count + 360.0, 360.0);
    const double a = a_deg * M_PI / 180;
    SceneLight light;
    const std::string degrees = std::to_string(static_cast<int>(std::lround(a_deg)) % 360);
    light.name = "raking-" + std::string(3 - std::min<size_t>(3, degrees.size()), '0') + degrees;
    light.direction = cv::Vec3d(std::cos(e) * std::cos(a), std::cos(e) * std::sin(a), std::sin(e));
    for (double& c : light.direction.val) c = std::round(c * 1e12) / 1e12;  // sin(pi) is 0.
    lights.push_back(light);
  }
  return lights;
}

SceneLight UvLight() {
  SceneLight light;
  light.name = "uv";
  light.kind = SceneLight::Kind::kFluorescence;
  light.intensity = 0.6;
  return light;
}

cv::Mat VirtualGantry::RenderLight(const SceneLight& light, uint64_t seed) const {
  cv::Mat level(rig_.camera.size, CV_32F);
  const cv::Vec3f l(cv::normalize(light.direction));
  for (int v = 0; v < level.rows; ++v) {
    const float* albedo = albedo_.ptr<float>(v);
    const cv::Vec3f* n = normal_.ptr<cv::Vec3f>(v);
    float* out = level.ptr<float>(v);
    for (int u = 0; u < level.cols; ++u) {
      const float shade =
          light.kind == SceneLight::Kind::kDistant ? std::max(0.0f, n[u].dot(l)) : 1.0f;
      out[u] = static_cast<float>(255.0 * light.intensity) * albedo[u] * shade;
    }
  }
  cv::Mat noise(level.size(), CV_32F);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::NORMAL, 0.0, light_.noise_dn);
  Camera(&level, noise, seed);
  cv::Mat frame;
  if (light_.texture_bits == 16) {
    level.convertTo(frame, CV_16U, 65535.0 / 255.0);
  } else {
    level.convertTo(frame, CV_8U);
  }
  return frame;
}

cv::Mat VirtualGantry::RenderTexture(uint64_t seed) const {
  // Gray unless a page is coloured; then each channel has its own albedo and noise.
  const cv::Mat& albedo = colour_albedo_.empty() ? albedo_ : colour_albedo_;
  cv::Mat noise(rig_.camera.size, albedo.type());
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::NORMAL, 0.0, light_.noise_dn);
  cv::Mat frame;
  cv::Mat lit = albedo.clone();
  if (!light_.studio_lamps.empty()) {
    if (lit.channels() == 1) {
      lit = lit.mul(studio_);
    } else {
      cv::Mat studio3;
      cv::merge(std::vector<cv::Mat>{studio_, studio_, studio_}, studio3);
      lit = lit.mul(studio3);
    }
  }
  cv::Mat light;
  if (light_.camera_blur_px <= 0 && light_.shot_noise_dn <= 0) {
    light = lit * (255.0 * light_.studio_light) + noise;
  } else {
    light = lit * (255.0 * light_.studio_light);
    Camera(&light, noise, seed);
  }
  if (light_.texture_bits == 16) {
    light.convertTo(frame, CV_16U, 65535.0 / 255.0);  // Rounds and saturates.
  } else {
    light.convertTo(frame, CV_8U);
  }
  return frame;
}

}  // namespace vellum
