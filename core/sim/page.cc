#include "core/sim/page.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace vellum {
namespace {

constexpr double kDeg = M_PI / 180.0;

// Walks a chain of constant-curvature segments from (0, 0) heading along +across; returns the
// point at arc length `sigma` (>= 0). Each segment is integrated in closed form.
cv::Vec2d Walk(const std::vector<std::pair<double, double>>& segs, double sigma) {
  double q = 0, z = 0, theta = 0;
  for (const auto& [length, kappa] : segs) {
    const double l = std::min(sigma, length);
    if (std::fabs(kappa) < 1e-12) {
      q += l * std::cos(theta);
      z += l * std::sin(theta);
    } else {
      const double theta1 = theta + kappa * l;
      q += (std::sin(theta1) - std::sin(theta)) / kappa;
      z -= (std::cos(theta1) - std::cos(theta)) / kappa;
      theta = theta1;
    }
    sigma -= l;
    if (sigma <= 0) return {q, z};
  }
  // Past the last segment: continue straight.
  return {q + sigma * std::cos(theta), z + sigma * std::sin(theta)};
}

}  // namespace

const char* ToString(PageShape shape) {
  switch (shape) {
    case PageShape::kFlat:
      return "flat";
    case PageShape::kCurl:
      return "curl";
    case PageShape::kFold:
      return "fold";
    case PageShape::kCone:
      return "cone";
    case PageShape::kBump:
      return "bump";
    case PageShape::kRipple:
      return "ripple";
    case PageShape::kGutter:
      return "gutter";
    case PageShape::kProfile:
      return "profile";
  }
  return "?";
}

bool ParsePageShape(const std::string& text, PageShape* shape) {
  for (PageShape s :
       {PageShape::kFlat, PageShape::kCurl, PageShape::kFold, PageShape::kCone, PageShape::kBump,
        PageShape::kRipple, PageShape::kGutter, PageShape::kProfile}) {
    if (text == ToString(s)) {
      *shape = s;
      return true;
    }
  }
  return false;
}

bool PageOptions::Check(std::string* why) const {
  auto angle = [](double deg, double below) { return deg >= 0 && deg < below; };
  if (!(size_mm.width > 0 && size_mm.height > 0) || !(curl_radius_mm > 0) ||
      !(curl_length_mm >= 0) || !(fold_radius_mm > 0) || !angle(fold_slope_deg, 90) ||
      !(cone_half_angle_deg > 0 && cone_half_angle_deg < 90) || !(cone_apex_distance_mm > 0) ||
      !(bump_sigma_mm > 0) || !(ripple_period_mm > 0) || !angle(ripple_slope_deg, 90) ||
      !(gutter_radius_mm > 0) || !angle(gutter_angle_deg, 180) || !(thickness_mm >= 0) ||
      !(burn_depth_mm >= 0) || holes < 0 || !(ridge_height_mm >= 0) || !(ridge_sigma_mm > 0)) {
    *why =
        "page: size_mm, curl_radius_mm, fold_radius_mm, cone_apex_distance_mm, bump_sigma_mm, "
        "ripple_period_mm, gutter_radius_mm and ridge_sigma_mm must be > 0, curl_length_mm, "
        "thickness_mm, burn_depth_mm, holes and ridge_height_mm >= 0, fold_slope_deg and "
        "ripple_slope_deg in [0, 90), cone_half_angle_deg in (0, 90), gutter_angle_deg in "
        "[0, 180)";
    return false;
  }
  return true;
}

Page::Page(const PageOptions& options) : options_(options) {
  if (std::string why; !options.Check(&why)) throw std::invalid_argument(why);
  const double w = options.size_mm.width, h = options.size_mm.height;
  if (options.shape == PageShape::kCurl) {
    // Flat from the left edge; the last curl_length_mm of the page roll up.
    across_dir_ = {1.0, 0.0};
    sigma_origin_ = 0.0;
    forward_ = {{w - options.curl_length_mm, 0.0}, {1e9, 1.0 / options.curl_radius_mm}};
  } else if (options.shape == PageShape::kFold) {
    const double a = options.fold_angle_deg * kDeg;
    across_dir_ = {-std::sin(a), std::cos(a)};  // Perpendicular to the fold line.
    sigma_origin_ = across_dir_.dot(cv::Vec2d(w / 2, h / 2));
    const double slope = options.fold_slope_deg * kDeg;
    const double half_arc = slope * options.fold_radius_mm;
    forward_ = {{half_arc, (options.fold_valley ? 1.0 : -1.0) / options.fold_radius_mm}};
    backward_ = forward_;
  } else if (options.shape == PageShape::kRipple) {
    // From the s = 0 edge: half an arc up, then arcs of alternating curvature, each turning
    // the slope from +max to -max or back: one ripple per ripple_period_mm across.
    const double slope = options.ripple_slope_deg * kDeg;
    const double kappa = 4 * std::sin(slope) / options.ripple_period_mm;
    const double arc = 2 * slope / kappa;
    across_dir_ = {1.0, 0.0};
    sigma_origin_ = 0.0;
    forward_ = {{arc / 2, kappa}};
    for (double done = arc / 2, sign = -1; done < w + arc; done += arc, sign = -sign) {
      forward_.push_back({arc, sign * kappa});
    }
  } else if (options.shape == PageShape::kGutter) {
    // Flat from the outer edge; the last stretch bends down into the gutter.
    const double bend = options.gutter_radius_mm * options.gutter_angle_deg * kDeg;
    if (options.gutter_left) {
      across_dir_ = {-1.0, 0.0};  // From s = w towards s = 0.
      sigma_origin_ = -w;
    } else {
      across_dir_ = {1.0, 0.0};
      sigma_origin_ = 0.0;
    }
    forward_ = {{w - bend, 0.0}, {1e9, -1.0 / options.gutter_radius_mm}};
  } else if (options.shape == PageShape::kProfile) {
    const double a = options.profile_angle_deg * kDeg;
    across_dir_ = {std::cos(a), std::sin(a)};
    sigma_origin_ =
        std::min({0.0, across_dir_[0] * w, across_dir_[1] * h, across_dir_.dot(cv::Vec2d(w, h))});
    for (const cv::Vec2d& segment : options.profile) forward_.push_back({segment[0], segment[1]});
  }
  if (options.shape == PageShape::kFold) {
    // A ridge rests on its edges (the corners are lowest), a valley on its fold line.
    double zmin = options.fold_valley ? ShapePoint(w / 2, h / 2)[2] : 0.0;
    for (double s : {0.0, w}) {
      for (double t : {0.0, h}) zmin = std::min(zmin, ShapePoint(s, t)[2]);
    }
    z_offset_ = -zmin;
  } else if (options.shape == PageShape::kRipple || options.shape == PageShape::kGutter) {
    // The lowest point across the page rests at z = 0 (the profile does not vary along t).
    double zmin = 0;
    for (int k = 0; k <= 1000; ++k) zmin = std::min(zmin, ShapePoint(w * k / 1000.0, 0)[2]);
    z_offset_ = -zmin;
  } else if (options.shape == PageShape::kProfile) {
    // The same at any angle: the lowest point of the profile over the page's extent across it,
    // sampled every 0.1 mm.
    double lo = 0, hi = 0;
    for (double s : {0.0, w}) {
      for (double t : {0.0, h}) {
        const double sigma = across_dir_.dot(cv::Vec2d(s, t)) - sigma_origin_;
        lo = std::min(lo, sigma), hi = std::max(hi, sigma);
      }
    }
    double zmin = std::numeric_limits<double>::infinity();
    const int n = std::max(1, static_cast<int>(std::ceil((hi - lo) / 0.1)));
    for (int k = 0; k <= n; ++k) zmin = std::min(zmin, Profile(lo + (hi - lo) * k / n)[1]);
    z_offset_ = -zmin;
  }
  if (options.outline == OutlineKind::kBurnt) {
    // Deterministic pseudo-random numbers from the seed (SplitMix64).
    uint64_t state = options.outline_seed * 0x9E3779B97F4A7C15ULL + 1;
    auto uniform = [&state] {
      uint64_t z = (state += 0x9E3779B97F4A7C15ULL);
      z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
      z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
      return static_cast<double>((z ^ (z >> 31)) >> 11) / 9007199254740992.0;
    };
    auto waves = [&](int count, double amplitude, double longest) {
      std::vector<Wave> out;
      for (int k = 0; k < count; ++k) {
        const double wavelength = longest / (1 + 2.5 * k * uniform() + k);
        out.push_back({amplitude * (0.4 + 0.6 * uniform()) / (1 + k), 2 * M_PI / wavelength,
                       2 * M_PI * uniform()});
      }
      return out;
    };
    for (int e = 0; e < 4; ++e) burn_[e] = waves(5, options.burn_depth_mm, 120.0);
    for (int k = 0; k < options.holes; ++k) {
      Hole hole;
      hole.centre = {w * (0.2 + 0.6 * uniform()), h * (0.2 + 0.6 * uniform())};
      hole.radius = 3.0 + 5.0 * uniform();
      hole.rim = waves(3, 0.3, 2 * M_PI);
      holes_.push_back(hole);
    }
  }
}

bool Page::Contains(double s, double t) const {
  const double w = options_.size_mm.width, h = options_.size_mm.height;
  if (!(s >= 0 && s <= w && t >= 0 && t <= h)) return false;
  if (options_.outline == OutlineKind::kRectangle) return true;
  auto depth = [](const std::vector<Wave>& waves, double x) {
    double d = 0;
    for (const Wave& wv : waves)
      d += wv.amplitude * (1 + std::sin(wv.frequency * x + wv.phase)) / 2;
    return d;
  };
  if (s < depth(burn_[0], t) || w - s < depth(burn_[1], t) || t < depth(burn_[2], s) ||
      h - t < depth(burn_[3], s)) {
    return false;
  }
  for (const Hole& hole : holes_) {
    const double ds = s - hole.centre[0], dt = t - hole.centre[1];
    const double angle = std::atan2(dt, ds);
    double r = 1;
    for (const Wave& wv : hole.rim) r += wv.amplitude * std::sin(wv.frequency * angle + wv.phase);
    if (std::hypot(ds, dt) < hole.radius * r) return false;
  }
  return true;
}

cv::Vec2d Page::Profile(double sigma) const {
  std::vector<std::pair<double, double>> segs;
  const auto& src = sigma >= 0 ? forward_ : backward_;
  for (const Segment& s : src) segs.emplace_back(s.length, s.curvature);
  cv::Vec2d p = Walk(segs, std::fabs(sigma));
  if (sigma < 0) p[0] = -p[0];
  return p;
}

cv::Matx33d PoseRotation(double rx_deg, double ry_deg, double rz_deg) {
  const double a = rx_deg * kDeg, b = ry_deg * kDeg, c = rz_deg * kDeg;
  const cv::Matx33d x(1, 0, 0, 0, std::cos(a), -std::sin(a), 0, std::sin(a), std::cos(a));
  const cv::Matx33d y(std::cos(b), 0, std::sin(b), 0, 1, 0, -std::sin(b), 0, std::cos(b));
  const cv::Matx33d z(std::cos(c), -std::sin(c), 0, std::sin(c), std::cos(c), 0, 0, 0, 1);
  return z * y * x;
}

cv::Vec3d Page::Point(double s, double t) const {
  return options_.pose_rotation * ShapePoint(s, t) + options_.pose_translation +
         cv::Vec3d(0, 0, options_.base_mm + options_.thickness_mm);
}

cv::Vec3d Page::ShapePoint(double s, double t) const {
  const PageOptions& o = options_;
  const double w = o.size_mm.width, h = o.size_mm.height;
  const double cx = o.centre_mm[0], cy = o.centre_mm[1];
  switch (o.shape) {
    case PageShape::kFlat:
      return {cx + s - w / 2, cy + t - h / 2, 0.0};
    case PageShape::kBump: {
      const double ds = s - w / 2, dt = t - h / 2;
      const double z = o.bump_height_mm *
                       std::exp(-(ds * ds + dt * dt) / (2 * o.bump_sigma_mm * o.bump_sigma_mm));
      return {cx + ds, cy + dt, z};
    }
    case PageShape::kCurl:
    case PageShape::kFold:
    case PageShape::kRipple:
    case PageShape::kGutter:
    case PageShape::kProfile: {
      const cv::Vec2d st(s, t);
      const double sigma = across_dir_.dot(st) - sigma_origin_;
      const cv::Vec2d along(-across_dir_[1], across_dir_[0]);
      const double tau = along.dot(st);
      const cv::Vec2d prof = Profile(sigma);
      // Page point = origin + across * profile.q + along * tau, lifted by profile.z.
      const cv::Vec2d origin = across_dir_ * sigma_origin_;
      const cv::Vec2d flat = origin + across_dir_ * prof[0] + along * tau;
      return {cx + flat[0] - w / 2, cy + flat[1] - h / 2, prof[1] + z_offset_};
    }
    case PageShape::kCone: {
      // Apex below the t = 0 edge on the page's centre line; the generator along +t rests
      // on the table. Unrolling: page angle phi maps to cone azimuth phi / sin(beta).
      const double beta = o.cone_half_angle_deg * kDeg;
      const double sa = w / 2, ta = -o.cone_apex_distance_mm;
      const double ds = s - sa, dt = t - ta;
      const double rho = std::hypot(ds, dt);
      const double psi = std::atan2(ds, dt) / std::sin(beta);
      const double sb = std::sin(beta), cb = std::cos(beta);
      const cv::Vec3d g(sb * std::sin(psi), cb * cb + sb * sb * std::cos(psi),
                        cb * sb * (1 - std::cos(psi)));
      const cv::Vec3d apex(cx + sa - w / 2, cy + ta - h / 2, 0.0);
      return apex + rho * g;
    }
  }
  return {0, 0, 0};
}

cv::Vec3d Page::Normal(double s, double t, bool relief) const {
  const double e = 1e-3;
  const cv::Vec3d ds = Point(s + e, t) - Point(s - e, t);
  const cv::Vec3d dt = Point(s, t + e) - Point(s, t - e);
  cv::Vec3d n = cv::normalize(ds.cross(dt));
  if (n[2] < 0) n = -n;
  const PageOptions& o = options_;
  if (relief && o.ridge_height_mm != 0 && o.ridge_sigma_mm > 0) {
    // The shape is an isometry of the flat page, so dt / (2e) is the unit tangent along t: the
    // relief h(t) tilts the normal against it by its slope h'(t).
    const double d = (t - o.ridge_t_mm) / o.ridge_sigma_mm;
    const double slope = -o.ridge_height_mm * d / o.ridge_sigma_mm * std::exp(-0.5 * d * d);
    n = cv::normalize(n - slope * cv::normalize(dt));
  }
  return n;
}

}  // namespace vellum
