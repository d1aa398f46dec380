#include "flags/options.h"

#include <cmath>
#include <cstdio>
#include <opencv2/imgcodecs.hpp>

namespace vellum {

std::vector<Flags::Spec> Join(std::vector<Flags::Spec> a, const std::vector<Flags::Spec>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

std::vector<Flags::Spec> PatternFlagSpecs() {
  return {
      {"phase-steps", "N", "phase shifts per axis; 0 = Gray code only", "8"},
      {"period", "PX", "sinusoid period, projector pixels", "16"},
  };
}

PatternOptions PatternOptionsFromFlags(const Flags& flags, cv::Size projector) {
  PatternOptions o;
  o.projector_size = projector;
  o.phase_steps = flags.GetInt("phase-steps", 0, 64);
  o.phase_period_px = flags.GetInt("period", 4, 4096);
  std::string why;
  if (!o.Check(&why)) throw UsageError(why);
  return o;
}

std::vector<Flags::Spec> SimFlagSpecs(const std::string& prefix) {
  return {
      {"page", "SHAPE", prefix + "flat, curl, fold, cone, bump, ripple or gutter", "curl"},
      {"texture", "KIND|FILE", prefix + "checkerboard, text, plain, or an image file of the page",
       "checkerboard"},
      {"page-size", "WxH", prefix + "page size, mm", "190x240"},
      {"noise", "DN", prefix + "camera noise sigma, DN", "1.5"},
      {"seed", "N", prefix + "noise seed (the same seed gives the same images)", "1"},
      {"scene", "NAME",
       prefix + "what the page lies on: table, support (a board as bright as paper), frame (a "
                "paper mount around the leaf) or spread (an open book: two pages and a gutter)",
       "table"},
      {"outline", "KIND", prefix + "the leaf's outline: rectangle, or burnt (eaten edges, holes)",
       "rectangle"},
      {"thickness", "MM", prefix + "the leaf's thickness, mm", "0.2"},
      {"table-albedo", "A", prefix + "the table's reflectance, 0..1", "0.35"},
      {"scene-albedo", "A", prefix + "the support's or frame's reflectance, 0..1", "0.8"},
      {"pose", "RX,RY,RZ,X,Y,Z",
       prefix + "hold the page in a rigid pose (a calibration board): turned about x, y, z by "
                "these degrees about its centre, its centre then at X, Y, Z mm",
       "0,0,0,0,0,0"},
  };
}

Status SimOptionsFromFlags(const Flags& flags, PageOptions* page, TextureOptions* texture,
                           LightOptions* light, SceneOptions* scene, uint64_t* seed) {
  const std::string scene_name = flags.Get("scene");
  if (scene_name != "table" && scene_name != "support" && scene_name != "frame" &&
      scene_name != "spread") {
    throw UsageError("--scene must be table, support, frame or spread, got '" + scene_name + "'");
  }
  scene->support = scene_name == "support";
  scene->frame = scene_name == "frame";
  scene->spread = scene_name == "spread";
  scene->support_albedo = scene->frame_albedo = flags.GetDouble("scene-albedo", 0, 1);
  light->table_albedo = flags.GetDouble("table-albedo", 0, 1);
  const std::string outline = flags.Get("outline");
  if (outline != "rectangle" && outline != "burnt") {
    throw UsageError("--outline must be rectangle or burnt, got '" + outline + "'");
  }
  page->outline = outline == "burnt" ? OutlineKind::kBurnt : OutlineKind::kRectangle;
  page->thickness_mm = flags.GetDouble("thickness", 0, 10);
  if (!ParsePageShape(flags.Get("page"), &page->shape)) {
    throw UsageError("--page must be flat, curl, fold, cone, bump, ripple or gutter, got '" +
                     flags.Get("page") + "'");
  }
  const cv::Size page_size = flags.GetSize("page-size");
  page->size_mm = cv::Size2d(page_size.width, page_size.height);
  light->noise_dn = flags.GetDouble("noise", 0, 100);
  double pose[6];
  char end = 0;
  if (std::sscanf(flags.Get("pose").c_str(), "%lf,%lf,%lf,%lf,%lf,%lf%c", &pose[0], &pose[1],
                  &pose[2], &pose[3], &pose[4], &pose[5], &end) != 6 ||
      !std::isfinite(pose[0] + pose[1] + pose[2] + pose[3] + pose[4] + pose[5])) {
    throw UsageError("--pose must be six numbers RX,RY,RZ,X,Y,Z, got '" + flags.Get("pose") + "'");
  }
  page->pose_rotation = PoseRotation(pose[0], pose[1], pose[2]);
  page->pose_translation = cv::Vec3d(pose[3], pose[4], pose[5]);
  *seed = static_cast<uint64_t>(flags.GetInt("seed", 0, 1 << 30));
  page->outline_seed = *seed;
  texture->seed = *seed;
  const std::string tex = flags.Get("texture");
  if (!ParseTextureKind(tex, &texture->kind) || texture->kind == TextureKind::kImage) {
    texture->kind = TextureKind::kImage;
    texture->image = cv::imread(tex, cv::IMREAD_COLOR);
    if (texture->image.empty()) {
      return Status::Error(tex + ": not a readable image (and not a texture name)");
    }
  }
  return Status::Ok();
}

std::vector<Flags::Spec> DecodeFlagSpecs() {
  return {
      {"decoder", "NAME", "phase (Gray code + phase shift) or gray (Gray code only)", "phase"},
      {"smooth-radius", "PX", "local fit radius, camera pixels (0..8); 0 = per-pixel decode", "3"},
  };
}

std::vector<Flags::Spec> TriangulateFlagSpecs() {
  return {
      {"max-epipolar", "PX", "reject points farther from their epipolar line, projector px", "1.5"},
  };
}

std::vector<Flags::Spec> FlattenFlagSpecs() {
  return {
      {"grid", "GxH", "flattening grid, nodes across x down", "45x45"},
      {"solver", "NAME", "gauss-newton (fast), euler or rk4 (the paper's simulator)",
       "gauss-newton"},
  };
}

std::vector<Flags::Spec> RestoreFlagSpecs() {
  return {
      {"view", "NAME", "orthographic (true scale) or camera (as the camera would see it)",
       "orthographic"},
      {"dpi", "N", "orthographic resolution; 0 = the camera's sampling on the table", "0"},
  };
}

DecodeOptions DecodeOptionsFromFlags(const Flags& flags) {
  DecodeOptions options;
  const std::string decoder = flags.Get("decoder");
  if (decoder != "phase" && decoder != "gray") {
    throw UsageError("--decoder must be phase or gray, got '" + decoder + "'");
  }
  options.use_phase = decoder == "phase";
  options.smooth_radius_px = flags.GetInt("smooth-radius", 0, 8);
  return options;
}

TriangulateOptions TriangulateOptionsFromFlags(const Flags& flags) {
  TriangulateOptions options;
  options.max_epipolar_error_px = flags.GetDouble("max-epipolar", 0.01, 100);
  return options;
}

MeshOptions MeshOptionsFromFlags(const Flags& flags) {
  MeshOptions options;
  options.grid = flags.GetSize("grid");
  std::string why;
  if (!options.Check(&why)) throw UsageError("--grid: " + why);
  return options;
}

FlattenOptions FlattenOptionsFromFlags(const Flags& flags) {
  FlattenOptions options;
  if (!ParseFlattenSolver(flags.Get("solver"), &options.solver)) {
    throw UsageError("--solver must be gauss-newton, euler or rk4, got '" + flags.Get("solver") +
                     "'");
  }
  return options;
}

RestoreOptions RestoreOptionsFromFlags(const Flags& flags) {
  RestoreOptions options;
  if (!ParseRestoreView(flags.Get("view"), &options.view)) {
    throw UsageError("--view must be orthographic or camera, got '" + flags.Get("view") + "'");
  }
  options.dpi = flags.GetDouble("dpi", 0, 4800);
  return options;
}

std::vector<Flags::Spec> PipelineFlagSpecs() {
  std::vector<Flags::Spec> specs;
  for (const auto& group :
       {DecodeFlagSpecs(), TriangulateFlagSpecs(), FlattenFlagSpecs(), RestoreFlagSpecs()}) {
    specs = Join(specs, group);
  }
  return specs;
}

PipelineOptions PipelineOptionsFromFlags(const Flags& flags) {
  PipelineOptions options;
  options.decode = DecodeOptionsFromFlags(flags);
  options.triangulate = TriangulateOptionsFromFlags(flags);
  options.mesh = MeshOptionsFromFlags(flags);
  options.flatten = FlattenOptionsFromFlags(flags);
  options.restore = RestoreOptionsFromFlags(flags);
  return options;
}

}  // namespace vellum
