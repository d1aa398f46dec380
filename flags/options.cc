#include "flags/options.h"

#include <cmath>
#include <cstdio>

#include "io/calibration_io.h"
#include "io/image_file.h"

namespace vellum {

std::vector<Flags::Spec> Join(std::vector<Flags::Spec> a, const std::vector<Flags::Spec>& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

std::vector<Flags::Spec> PatternFlagSpecs() {
  return {
      {"axes", "WHICH",
       "projector coordinates coded: both (columns and rows), or columns alone (half the "
       "frames: the triangulation needs only columns, but no epipolar check is made)",
       "both"},
      {"phase-steps", "N", "phase shifts per axis; 0 = Gray code only", "8"},
      {"period", "PX", "sinusoid period, projector pixels", "16"},
      {"gray-inverses", "BOOL",
       "each Gray bit with its inverse pattern (false: bits judged against white and black)",
       "true"},
      {"gray-skip-bits", "K",
       "leave out the Gray code's K finest bits (stripes of 2^K px, as a rig whose projector is "
       "wider than its code)",
       "0"},
  };
}

PatternOptions PatternOptionsFromFlags(const Flags& flags, cv::Size projector) {
  PatternOptions o;
  o.projector_size = projector;
  const std::string axes = flags.Get("axes");
  if (axes != "both" && axes != "columns") {
    throw UsageError("--axes: '" + axes + "' is not both or columns");
  }
  o.rows = axes == "both";
  o.phase_steps = flags.GetInt("phase-steps", 0, 64);
  o.phase_period_px = flags.GetInt("period", 4, 4096);
  o.gray_inverses = flags.GetBool("gray-inverses");
  o.gray_skip_bits = flags.GetInt("gray-skip-bits", 0, 15);
  std::string why;
  if (!o.Check(&why)) throw UsageError(why);
  return o;
}

std::vector<Flags::Spec> SimFlagSpecs(const std::string& prefix) {
  return {
      {"page", "SHAPE", prefix + "flat, curl, fold, cone, bump, ripple or gutter", "curl"},
      {"texture", "KIND|FILE",
       prefix + "checkerboard, text, plain, or an image file of the page (PNG, TIFF, JPEG, JPEG "
                "2000 or WebP)",
       "checkerboard"},
      {"page-size", "WxH", prefix + "page size, mm", "190x240"},
      {"centre", "X,Y", prefix + "where the page's centre lies on the table, mm", "0,0"},
      {"noise", "DN", prefix + "camera noise sigma, DN", "1.5"},
      {"seed", "N", prefix + "noise seed (the same seed gives the same images)", "1"},
      {"texture-bits", "N",
       prefix + "bits a sample of the studio-light texture and the lights' images: 8, or 16 as "
                "a camera that gives more than 8 (the structured-light frames stay 8-bit)",
       "8"},
      {"scene", "NAME",
       prefix + "what the page lies on: table, support (a board as bright as paper), frame (a "
                "paper mount around the leaf) or spread (an open book: two pages and a gutter)",
       "table"},
      {"outline", "KIND", prefix + "the leaf's outline: rectangle, or burnt (eaten edges, holes)",
       "rectangle"},
      {"thickness", "MM", prefix + "the leaf's thickness, mm", "0.2"},
      {"ridge", "HEIGHT,T",
       prefix + "an embossed line across the page at T mm from its top edge, HEIGHT mm high "
                "(sigma 0.5 mm; in the shading only, as a raking light shows it); 0,0: none",
       "0,0"},
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
  double ridge[2];
  char ridge_end = 0;
  if (std::sscanf(flags.Get("ridge").c_str(), "%lf,%lf%c", &ridge[0], &ridge[1], &ridge_end) != 2 ||
      !std::isfinite(ridge[0] + ridge[1]) || std::fabs(ridge[0]) > 5) {
    throw UsageError("--ridge must be HEIGHT,T in mm (height within 5 mm), got '" +
                     flags.Get("ridge") + "'");
  }
  page->ridge_height_mm = ridge[0];
  page->ridge_t_mm = ridge[1];
  if (!ParsePageShape(flags.Get("page"), &page->shape)) {
    throw UsageError("--page must be flat, curl, fold, cone, bump, ripple or gutter, got '" +
                     flags.Get("page") + "'");
  }
  const cv::Size page_size = flags.GetSize("page-size");
  page->size_mm = cv::Size2d(page_size.width, page_size.height);
  double centre[2];
  char centre_end = 0;
  if (std::sscanf(flags.Get("centre").c_str(), "%lf,%lf%c", &centre[0], &centre[1], &centre_end) !=
          2 ||
      !std::isfinite(centre[0] + centre[1])) {
    throw UsageError("--centre must be two numbers X,Y, got '" + flags.Get("centre") + "'");
  }
  page->centre_mm = cv::Vec2d(centre[0], centre[1]);
  light->noise_dn = flags.GetDouble("noise", 0, 100);
  light->texture_bits = flags.GetInt("texture-bits", 8, 16);
  if (light->texture_bits != 8 && light->texture_bits != 16) {
    throw UsageError("--texture-bits must be 8 or 16, got " + flags.Get("texture-bits"));
  }
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
    if (!ReadColourImage(tex, &texture->image).ok()) {
      return Status::Error(tex + ": not a readable 8-bit image (and not a texture name)");
    }
  }
  return Status::Ok();
}

std::vector<cv::Vec3d> ParseLamps(const std::string& flag, const std::string& text) {
  std::vector<cv::Vec3d> lamps;
  size_t start = 0;
  while (start <= text.size() && !text.empty()) {
    const size_t end = std::min(text.find(';', start), text.size());
    const std::string item = text.substr(start, end - start);
    double x = 0, y = 0, z = 0;
    char rest = 0;
    if (std::sscanf(item.c_str(), "%lf,%lf,%lf%c", &x, &y, &z, &rest) != 3 ||
        !std::isfinite(x + y + z) || z <= 0) {
      throw UsageError("--" + flag + ": each lamp is X,Y,Z in mm above the table (z > 0), got '" +
                       item + "'");
    }
    lamps.emplace_back(x, y, z);
    start = end + 1;
  }
  return lamps;
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
      {"volume", "LOW:HIGH",
       "working volume, heights above the table, mm; points outside are rejected (default: the "
       "calibration's working_volume_z, else -20:300)",
       ""},
      {"max-flying", "MM",
       "reject flying points (mid-air mixed pixels at edges) off the surface on both sides by "
       "more than this, mm; 0 keeps them",
       "0.5"},
  };
}

std::vector<Flags::Spec> FlattenFlagSpecs() {
  return {
      {"grid", "GxH|auto",
       "flattening grid, nodes across x down; auto: from the page's shape, at least 45x45, fine "
       "enough that the warp strays less than --max-warp-error",
       "auto"},
      {"max-warp-error", "PX", "auto grid: the warp's error allowed, camera pixels", "0.05"},
      {"solver", "NAME", "gauss-newton (fast), euler or rk4 (the paper's simulator)",
       "gauss-newton"},
      {"leaf-hint", "X,Y,W,H",
       "camera pixels inside the leaf, where the scene is ambiguous (default: the view's centre)",
       ""},
      {"object", "KIND",
       "what lies on the table: leaf (never split into two pages), book (an open book: two "
       "pages at a gutter) or auto (split only on strong evidence, else flagged); scan.yaml's "
       "object outranks it",
       "auto"},
  };
}

std::vector<Flags::Spec> RestoreFlagSpecs() {
  return {
      {"view", "NAME", "orthographic (true scale) or camera (as the camera would see it)",
       "orthographic"},
      {"dpi", "N", "orthographic resolution; 0 = the camera's sampling on the table", "0"},
      {"deskew", "BOOL", "orthographic: turn the page so the leaf stands upright", "true"},
      {"crop", "BOOL", "orthographic: crop to the leaf plus --margin", "true"},
      {"margin", "MM", "orthographic: border kept around the leaf, mm", "3"},
      {"leaf-size", "WxH",
       "the leaf's expected size, mm: a restored leaf more than 10% off is "
       "flagged (default: not checked)",
       ""},
      {"camera-icc", "FILE",
       "the camera's ICC profile (RGB, or gray for a gray camera), embedded in the masters "
       "(restored.tif, archival.tif) in place of sRGB (default: sRGB)",
       ""},
      {"flatfield", "FILE",
       "the projector's flat field (vellum calibrate flatfield): also writes each page's "
       "albedo, its reflectance without the shading, as restored_albedo.tif",
       ""},
      {"studio-field", "FILE",
       "the studio lamps' field (vellum calibrate studio): also writes each page's texture "
       "without the lamps' shading, as restored_reflectance.tif",
       ""},
      {"target-fadgi", "STARS",
       "the collection's target, a FADGI star level for manuscripts (1-4): a page whose "
       "sampling, bit depth or scale error falls short of it fails quality control, the figure "
       "named (0: no target)",
       "0"},
      {"target-ppi", "PPI",
       "the collection's least true sampling: a page sampled more coarsely at 5% of it fails "
       "quality control on sampling (0: no target)",
       "0"},
      {"target-bits", "BITS",
       "the collection's bits per channel, 8 or 16: a master with fewer fails quality control "
       "(0: no target)",
       "0"},
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
  options.max_flying_mm = flags.GetDouble("max-flying", 0, 100);
  const std::string volume = flags.Get("volume");
  if (!volume.empty()) {
    double low = 0, high = 0;
    char colon = 0, extra = 0;
    if (std::sscanf(volume.c_str(), "%lf %c %lf %c", &low, &colon, &high, &extra) != 3 ||
        colon != ':' || !(low < high)) {
      throw UsageError("--volume must be LOW:HIGH in mm with LOW < HIGH, got '" + volume + "'");
    }
    options.min_z_mm = low;
    options.max_z_mm = high;
  }
  return options;
}

void FlattenGroupFromFlags(const Flags& flags, PipelineOptions* options) {
  options->auto_grid = flags.Get("grid") == "auto";
  if (!options->auto_grid) {
    options->mesh.grid = flags.GetSize("grid");
    std::string why;
    if (!options->mesh.Check(&why)) throw UsageError("--grid: " + why);
  }
  options->max_warp_error_px = flags.GetDouble("max-warp-error", 0.001, 10);
  options->flatten = FlattenOptionsFromFlags(flags);
  const std::string hint = flags.Get("leaf-hint");
  if (!hint.empty() && !ParseLeafHint(hint, &options->outline.hint)) {
    throw UsageError("--leaf-hint must be X,Y,W,H in camera pixels, got '" + hint + "'");
  }
  if (!ParseObjectKind(flags.Get("object"), &options->outline.object)) {
    throw UsageError("--object must be leaf, book or auto, got '" + flags.Get("object") + "'");
  }
}

FlattenOptions FlattenOptionsFromFlags(const Flags& flags) {
  FlattenOptions options;
  if (!ParseFlattenSolver(flags.Get("solver"), &options.solver)) {
    throw UsageError("--solver must be gauss-newton, euler or rk4, got '" + flags.Get("solver") +
                     "'");
  }
  return options;
}

void RestoreGroupFromFlags(const Flags& flags, PipelineOptions* options) {
  RestoreOptions& r = options->restore;
  if (!ParseRestoreView(flags.Get("view"), &r.view)) {
    throw UsageError("--view must be orthographic or camera, got '" + flags.Get("view") + "'");
  }
  r.dpi = flags.GetDouble("dpi", 0, 4800);
  r.deskew = flags.GetBool("deskew");
  r.crop_to_leaf = flags.GetBool("crop");
  r.margin_mm = flags.GetDouble("margin", 0, 1000);
  if (!flags.Get("leaf-size").empty()) {
    const cv::Size size = flags.GetSize("leaf-size");
    options->limits.expected_leaf_mm = cv::Size2d(size.width, size.height);
  }
  if (!flags.Get("camera-icc").empty()) {
    const Status s = ReadIccFile(flags.Get("camera-icc"), &options->camera_icc);
    if (!s.ok()) throw UsageError("--camera-icc: " + s.message());
  }
  if (!flags.Get("flatfield").empty()) {
    const Status read = ReadFlatField(flags.Get("flatfield"), &options->flat_field);
    if (!read.ok()) throw UsageError("--flatfield: " + read.message());
  }
  if (!flags.Get("studio-field").empty()) {
    const Status read = ReadStudioField(flags.Get("studio-field"), &options->studio_field);
    if (!read.ok()) throw UsageError("--studio-field: " + read.message());
  }
  options->target.fadgi_stars = flags.GetInt("target-fadgi", 0, 4);
  options->target.ppi = flags.GetDouble("target-ppi", 0, 10000);
  options->target.bits = flags.GetInt("target-bits", 0, 16);
  if (options->target.bits != 0 && options->target.bits != 8 && options->target.bits != 16) {
    throw UsageError("--target-bits must be 0 (none), 8 or 16, got " +
                     std::to_string(options->target.bits));
  }
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
  FlattenGroupFromFlags(flags, &options);
  RestoreGroupFromFlags(flags, &options);
  return options;
}

}  // namespace vellum
