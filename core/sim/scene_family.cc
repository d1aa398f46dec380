#include "core/sim/scene_family.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>
#include <vector>

namespace vellum {
namespace {

// A page image in colour: tinted paper (parchment to white), lines of brown or black text, a
// red or blue initial and a coloured block (a miniature), at 4 px per mm.
cv::Mat ColourPage(cv::Size2d page_mm, cv::RNG& rng) {
  constexpr double kPxPerMm = 4.0;
  const cv::Size size(static_cast<int>(page_mm.width * kPxPerMm),
                      static_cast<int>(page_mm.height * kPxPerMm));
  const cv::Scalar paper(rng.uniform(150, 235), rng.uniform(185, 240), rng.uniform(205, 245));
  cv::Mat image(size, CV_8UC3, paper);
  const cv::Scalar ink = rng.uniform(0, 2) ? cv::Scalar(20, 25, 30) : cv::Scalar(25, 45, 80);
  const cv::Scalar colours[] = {cv::Scalar(40, 40, 180), cv::Scalar(170, 80, 30),
                                cv::Scalar(40, 140, 60), cv::Scalar(30, 160, 200)};
  const int margin = static_cast<int>(rng.uniform(10.0, 20.0) * kPxPerMm);
  const int line = static_cast<int>(rng.uniform(5.0, 9.0) * kPxPerMm);
  const std::string letters = "abcdefghijklmnopqrstuvwxyz";
  for (int y = margin + line; y < size.height - margin; y += line) {
    for (int x = margin; x < size.width - margin;) {
      std::string word;
      for (int i = rng.uniform(2, 9); i > 0; --i) word += letters[rng.uniform(0, 26)];
      int baseline = 0;
      const cv::Size text = cv::getTextSize(word, cv::FONT_HERSHEY_COMPLEX, 0.8, 2, &baseline);
      if (x + text.width > size.width - margin) break;
      cv::putText(image, word, cv::Point(x, y), cv::FONT_HERSHEY_COMPLEX, 0.8, ink, 2, cv::LINE_AA);
      x += text.width + text.height / 2;
    }
  }
  const cv::Rect initial(margin, margin, 3 * line, 3 * line);
  cv::rectangle(image, initial, colours[rng.uniform(0, 2)], cv::FILLED);
  const int bw = size.width / 3, bh = size.height / 4;
  const cv::Rect block(
      rng.uniform(margin, std::max(margin + 1, size.width - margin - bw)),
      rng.uniform(size.height / 3, std::max(size.height / 3 + 1, size.height - margin - bh)), bw,
      bh);
  cv::rectangle(image, block, colours[rng.uniform(0, 4)], cv::FILLED);
  cv::circle(image, (block.tl() + block.br()) / 2, std::min(bw, bh) / 3, colours[rng.uniform(0, 4)],
             cv::FILLED, cv::LINE_AA);
  return image;
}

// A random smooth developable sheet: a profile of 2 to 5 arcs and straight stretches, its slope
// kept within 65 degrees, from the page's edge across it at a random angle.
void RandomProfile(PageOptions* page, cv::RNG& rng) {
  page->shape = PageShape::kProfile;
  page->profile_angle_deg = rng.uniform(0.0, 360.0);
  page->profile.clear();
  const double limit = 65 * M_PI / 180;
  double theta = 0;
  for (int k = rng.uniform(2, 6); k > 0; --k) {
    const double length = rng.uniform(20.0, 80.0);
    double curvature =
        rng.uniform(0, 10) < 3 ? 0.0 : (rng.uniform(0, 2) ? 1 : -1) / rng.uniform(25.0, 200.0);
    // Keep the slope within the limit at the arc's end.
    const double end = theta + curvature * length;
    if (std::fabs(end) > limit) curvature = ((end > 0 ? limit : -limit) - theta) / length;
    theta += curvature * length;
    page->profile.emplace_back(length, curvature);
  }
}

// How far the page's outline (and each page's of a spread) lies inside each side of the default
// rig's view: left, right, top, bottom, in camera pixels (negative: it runs past that side).
cv::Vec4d ViewMargins(const FamilyScene& s) {
  const Calibration rig = DefaultRig();
  std::vector<PageOptions> pages{s.page};
  if (s.scene.spread) {
    // As the gantry places them (VirtualGantry): each gutter edge half the gap from x = 0.
    pages.clear();
    for (bool left : {true, false}) {
      PageOptions o = s.page;
      o.shape = PageShape::kGutter;
      o.gutter_left = !left;
      o.centre_mm = {0.0, s.page.centre_mm[1]};
      const double gutter_x = Page(o).Point(left ? o.size_mm.width : 0.0, 0)[0];
      o.centre_mm[0] = (left ? -1 : 1) * s.scene.spread_gap_mm / 2 - gutter_x;
      pages.push_back(o);
    }
  }
  const cv::Size view = rig.camera.size;
  cv::Vec4d margins(1e9, 1e9, 1e9, 1e9);
  for (const PageOptions& o : pages) {
    const Page page(o);
    const double w = o.size_mm.width, h = o.size_mm.height;
    for (double f = 0; f <= 1.0; f += 0.01) {
      for (const cv::Vec2d& st :
           {cv::Vec2d(f * w, 0), cv::Vec2d(f * w, h), cv::Vec2d(0, f * h), cv::Vec2d(w, f * h)}) {
        const cv::Point2d p = rig.camera.Project(page.Point(st[0], st[1]));
        const cv::Vec4d here(p.x, view.width - 1 - p.x, p.y, view.height - 1 - p.y);
        for (int k = 0; k < 4; ++k) margins[k] = std::min(margins[k], here[k]);
      }
    }
  }
  return margins;
}

// Whether every point of the page's outline lies inside the view with `margin_px` to spare.
bool InView(const FamilyScene& s, double margin_px) {
  const cv::Vec4d m = ViewMargins(s);
  return std::min({m[0], m[1], m[2], m[3]}) >= margin_px;
}

}  // namespace

namespace {

bool Chance(cv::RNG& rng, double p) { return rng.uniform(0.0, 1.0) < p; }

// The shape, by its weight among the family's, and its size and parameters.
void DrawShape(cv::RNG& rng, FamilyScene* out) {
  FamilyScene& s = *out;
  const struct {
    const char* name;
    double weight;
  } shapes[] = {{"flat", 8},   {"curl", 14},   {"fold", 12},        {"wave", 10},  {"cone", 10},
                {"ripple", 6}, {"crease", 12}, {"developable", 14}, {"spread", 14}};
  double total = 0;
  for (const auto& shape : shapes) total += shape.weight;
  double pick = rng.uniform(0.0, total);
  for (const auto& shape : shapes) {
    s.shape = shape.name;
    if ((pick -= shape.weight) < 0) break;
  }
  PageOptions& page = s.page;
  const bool spread = s.shape == "spread";
  page.size_mm = spread ? cv::Size2d(rng.uniform(130.0, 180.0), rng.uniform(180.0, 235.0))
                        : cv::Size2d(rng.uniform(110.0, 200.0), rng.uniform(140.0, 250.0));
  if (s.shape == "curl") {
    page.shape = PageShape::kCurl;
    page.curl_radius_mm = rng.uniform(25.0, 80.0);
    page.curl_length_mm = rng.uniform(30.0, std::min(90.0, 0.5 * page.size_mm.width));
  } else if (s.shape == "fold" || s.shape == "crease") {
    page.shape = PageShape::kFold;
    page.fold_angle_deg = rng.uniform(0.0, 180.0);
    const bool crease = s.shape == "crease";
    page.fold_radius_mm = crease ? rng.uniform(0.5, 2.5) : rng.uniform(8.0, 25.0);
    page.fold_slope_deg = crease ? rng.uniform(10.0, 40.0) : rng.uniform(5.0, 20.0);
    page.fold_valley = crease && Chance(rng, 0.5);
  } else if (s.shape == "wave" || s.shape == "ripple") {
    page.shape = PageShape::kRipple;
    const bool wave = s.shape == "wave";
    page.ripple_slope_deg = wave ? rng.uniform(8.0, 25.0) : rng.uniform(25.0, 50.0);
    page.ripple_period_mm = wave ? rng.uniform(50.0, 120.0) : rng.uniform(40.0, 80.0);
  } else if (s.shape == "cone") {
    page.shape = PageShape::kCone;
    page.cone_half_angle_deg = rng.uniform(20.0, 50.0);
    page.cone_apex_distance_mm = rng.uniform(150.0, 400.0);
  } else if (s.shape == "developable") {
    RandomProfile(&page, rng);
  }
}

// What it rests on (a table, support or frame, or a spread's other page), how high its rim
// stands above that, and a burnt outline.
void DrawSurround(uint64_t seed, cv::RNG& rng, FamilyScene* out) {
  FamilyScene& s = *out;
  PageOptions& page = s.page;
  const bool spread = s.shape == "spread";
  page.thickness_mm = Chance(rng, 0.3) ? std::vector<double>{0.0, 0.05, 0.1}[rng.uniform(0, 3)]
                                       : rng.uniform(0.0, 0.5);
  SceneOptions& scene = s.scene;
  scene.spread = spread;
  if (spread) {
    page.gutter_angle_deg = rng.uniform(20.0, 85.0);
    page.gutter_radius_mm = rng.uniform(20.0, 60.0);
    scene.spread_gap_mm = Chance(rng, 0.3) ? 0.0 : rng.uniform(0.5, 4.0);
  } else {
    const double surround = rng.uniform(0.0, 1.0);
    scene.frame = surround < 0.15;
    scene.support = surround >= 0.15 && surround < 0.4;
  }
  if (!spread && Chance(rng, 0.25)) {
    page.outline = OutlineKind::kBurnt;
    page.outline_seed = seed;
    page.burn_depth_mm = rng.uniform(4.0, 15.0);
    page.holes = rng.uniform(0, 5);
  }
}

// What is on the page.
void DrawTexture(uint64_t seed, cv::RNG& rng, FamilyScene* out) {
  FamilyScene& s = *out;
  const PageOptions& page = s.page;
  TextureOptions& texture = s.texture;
  const double kind = rng.uniform(0.0, 1.0);
  texture.kind = kind < 0.35  ? TextureKind::kText
                 : kind < 0.7 ? TextureKind::kCheckerboard
                 : kind < 0.8 ? TextureKind::kPlain
                              : TextureKind::kImage;
  texture.paper_albedo = rng.uniform(0.6, 0.92);
  texture.ink_albedo = rng.uniform(0.04, 0.4);
  texture.square_mm = rng.uniform(8.0, 14.0);
  texture.margin_mm = rng.uniform(6.0, 14.0);
  texture.seed = seed;
  if (texture.kind == TextureKind::kImage) texture.image = ColourPage(page.size_mm, rng);
}

// The renderer: the light, the camera's noise and blur, and the surround's albedos.
void DrawLight(uint64_t seed, cv::RNG& rng, FamilyScene* out) {
  FamilyScene& s = *out;
  SceneOptions& scene = s.scene;
  LightOptions& light = s.light;
  light.noise_dn = rng.uniform(0.5, 3.0);
  light.shot_noise_dn = Chance(rng, 0.5) ? rng.uniform(0.5, 3.0) : 0.0;
  light.camera_blur_px = Chance(rng, 0.6) ? rng.uniform(0.2, 1.0) : 0.0;
  light.defocus_sigma_px = rng.uniform(0.4, 1.4);
  light.ambient = rng.uniform(0.02, 0.15);
  light.projector_gain = rng.uniform(0.7, 0.98 - light.ambient);
  light.studio_light = rng.uniform(0.75, 0.95);
  light.table_albedo = rng.uniform(0.05, 0.9);
  light.grain = Chance(rng, 0.4) ? rng.uniform(0.02, 0.15) : 0.0;
  light.grain_seed = seed + 7;
  scene.support_albedo = rng.uniform(0.05, 0.9);
  scene.frame_albedo = rng.uniform(0.05, 0.9);
  scene.support_height_mm = rng.uniform(2.0, 20.0);
  scene.frame_thickness_mm = rng.uniform(0.3, 1.5);
  scene.frame_window_margin_mm = Chance(rng, 0.5) ? 0.0 : rng.uniform(1.0, 15.0);
}

// Where it lies and how it is turned (a frame's window stays square to the view): drawn until
// the leaf lies inside the view, smaller each time it does not.
void PlaceInView(cv::RNG& rng, FamilyScene* out) {
  FamilyScene& s = *out;
  PageOptions& page = s.page;
  const bool spread = s.shape == "spread";
  const SceneOptions& scene = s.scene;
  const double turn_limit = scene.frame ? 0.0 : spread ? 8.0 : 180.0;
  for (int attempt = 0;; ++attempt) {
    const double turn = rng.uniform(-turn_limit, turn_limit + 1e-9);
    page.centre_mm = {rng.uniform(-60.0, 60.0), rng.uniform(-40.0, 40.0)};
    const cv::Vec3d centre(page.centre_mm[0], page.centre_mm[1], 0);
    page.pose_rotation = PoseRotation(0, 0, turn);
    page.pose_translation = centre - page.pose_rotation * centre;
    if (InView(s, 12)) break;
    if (attempt % 8 == 7) page.size_mm *= 0.92;
  }
}

// The page moved on the table by `by` (mm): a leaf's centre, or a spread's pose (the gantry
// places a spread's pages about x = 0 whatever its centre).
void Shift(FamilyScene* s, const cv::Vec2d& by) {
  PageOptions& page = s->page;
  if (s->scene.spread) {
    page.pose_translation += cv::Vec3d(by[0], by[1], 0);
    return;
  }
  page.centre_mm += by;
  const cv::Vec3d centre(page.centre_mm[0], page.centre_mm[1], 0);
  page.pose_translation = centre - page.pose_rotation * centre;
}

// Placed inside the view, then moved square to one side of it until the page's outline lies
// `edge_margin_px` inside that side (negative: past it), to a pixel: Newton's steps on the
// margin's slope, measured for a 1 mm move.
void PlaceAtEdge(cv::RNG& rng, FamilyScene* out) {
  FamilyScene& s = *out;
  PlaceInView(rng, &s);
  // A spread's pages are placed about the gutter at x = 0 (VirtualGantry): it moves up or down.
  s.edge_side = s.scene.spread ? rng.uniform(2, 4) : rng.uniform(0, 4);
  // Half run off the view by 2 to 40 mm (8 to 160 px of the default rig's 0.25 mm), half lie
  // 2 to 15 mm inside it: near enough that a careless test of the border would cry wolf.
  s.edge_margin_px = Chance(rng, 0.5) ? -rng.uniform(8.0, 160.0) : rng.uniform(8.0, 60.0);
  const cv::Vec2d unit = s.edge_side < 2 ? cv::Vec2d(1, 0) : cv::Vec2d(0, 1);
  for (int step = 0; step < 8; ++step) {
    const double margin = ViewMargins(s)[s.edge_side];
    if (std::fabs(margin - s.edge_margin_px) < 0.5) break;
    Shift(&s, unit);
    const double slope = ViewMargins(s)[s.edge_side] - margin;  // Pixels per mm.
    Shift(&s, -unit);
    if (std::fabs(slope) < 0.5) break;  // Not a move this side follows (a camera pixel is 0.25 mm).
    Shift(&s, unit * std::clamp((s.edge_margin_px - margin) / slope, -200.0, 200.0));
  }
  s.edge_margin_px = ViewMargins(s)[s.edge_side];
}

// The support and the frame around the leaf where it came to lie.
void DrawSupportAndFrame(cv::RNG& rng, FamilyScene* out) {
  FamilyScene& s = *out;
  PageOptions& page = s.page;
  SceneOptions& scene = s.scene;
  const double reach = 0.5 * std::hypot(page.size_mm.width, page.size_mm.height);
  auto around = [&](double least, double most) {
    const double l = rng.uniform(least, most), r = rng.uniform(least, most),
                 b = rng.uniform(least, most), t = rng.uniform(least, most);
    return cv::Rect2d(page.centre_mm[0] - reach - l, page.centre_mm[1] - reach - b,
                      2 * reach + l + r, 2 * reach + b + t);
  };
  scene.support_mm = around(5.0, 80.0);
  if (scene.frame) {
    const double m = scene.frame_window_margin_mm;
    const cv::Rect2d window(page.centre_mm[0] - page.size_mm.width / 2 - m,
                            page.centre_mm[1] - page.size_mm.height / 2 - m,
                            page.size_mm.width + 2 * m, page.size_mm.height + 2 * m);
    const double l = rng.uniform(15.0, 80.0), r = rng.uniform(15.0, 80.0),
                 b = rng.uniform(15.0, 80.0), t = rng.uniform(15.0, 80.0);
    scene.frame_mm =
        cv::Rect2d(window.x - l, window.y - b, window.width + l + r, window.height + b + t);
  }
}

FamilyScene Draw(uint64_t seed, bool at_edge) {
  FamilyScene s;
  s.seed = seed;
  // One generator drawn from in a fixed order: the same seed gives the same scene.
  cv::RNG rng(0x9E3779B97F4A7C15ULL ^ (seed * 0xBF58476D1CE4E5B9ULL + 12345));
  DrawShape(rng, &s);
  DrawSurround(seed, rng, &s);
  DrawTexture(seed, rng, &s);
  DrawLight(seed, rng, &s);
  if (at_edge) {
    PlaceAtEdge(rng, &s);
  } else {
    PlaceInView(rng, &s);
  }
  DrawSupportAndFrame(rng, &s);
  // What the operator says it is: half the time, nothing (auto).
  const bool spread = s.shape == "spread";
  s.said = Chance(rng, 0.5) ? ObjectKind::kAuto : spread ? ObjectKind::kBook : ObjectKind::kLeaf;
  return s;
}

}  // namespace

FamilyScene DrawFamilyScene(uint64_t seed) { return Draw(seed, false); }

FamilyScene DrawEdgeScene(uint64_t seed) { return Draw(seed, true); }

std::string FamilyScene::Describe() const {
  char text[512];
  const char* surround = scene.frame ? "frame" : scene.support ? "support" : "table";
  const double surround_albedo = scene.frame     ? scene.frame_albedo
                                 : scene.support ? scene.support_albedo
                                                 : light.table_albedo;
  std::snprintf(text, sizeof(text),
                "seed %llu: %s%s, %.0fx%.0f mm, rim %.2f mm, on a %s (albedo %.2f), %s page "
                "(paper %.2f, ink %.2f), noise %.1f+%.1f DN, blur %.1f px, said %s",
                static_cast<unsigned long long>(seed), shape.c_str(),
                page.outline == OutlineKind::kBurnt ? " burnt" : "", page.size_mm.width,
                page.size_mm.height, page.thickness_mm, surround, surround_albedo,
                ToString(texture.kind), texture.paper_albedo, texture.ink_albedo, light.noise_dn,
                light.shot_noise_dn, light.camera_blur_px, ToString(said));
  std::string out = text;
  if (scene.spread) {
    std::snprintf(text, sizeof(text), "; gutter %.0f deg, radius %.0f mm, gap %.1f mm",
                  page.gutter_angle_deg, page.gutter_radius_mm, scene.spread_gap_mm);
    out += text;
  }
  if (edge_side >= 0) {
    const char* sides[] = {"left", "right", "top", "bottom"};
    std::snprintf(text, sizeof(text), "; %.0f px %s the view's %s side", std::fabs(edge_margin_px),
                  edge_margin_px < 0 ? "past" : "inside", sides[edge_side]);
    out += text;
  }
  return out;
}

}  // namespace vellum
