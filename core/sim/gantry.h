// The virtual gantry: renders what the station's camera sees of a known warped page under any
// projector image, with the light model of a real rig (albedo, ambient light, incidence angle,
// projector defocus and shadows, camera noise, 8-bit quantisation), and the exact ground truth
// (3D point and flat page coordinate) of every camera pixel. Replaces the hardware in the demo
// and in every accuracy test.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/geometry/calibration.h"
#include "core/sim/page.h"
#include "core/sim/texture.h"

namespace vellum {

struct LightOptions {
  double ambient = 0.08;          // Ambient light, fraction of full scale.
  double projector_gain = 0.85;   // Projector light at normal incidence, fraction of full scale.
  double studio_light = 0.9;      // Studio light of the texture frame, fraction of full scale.
  double defocus_sigma_px = 0.7;  // Projector defocus, Gaussian sigma, projector pixels.
  double noise_dn = 1.5;          // Camera noise standard deviation, DN.
  double table_albedo = 0.35;     // Reflectance of the table around the page.
  // The surround's albedo (table, support, frame) varies by up to this share either way, as
  // wood grain or cloth does: a smooth random pattern of `grain_seed`, features 2 to 40 mm.
  double grain = 0.0;
  uint64_t grain_seed = 1;
  double shadow_bias_mm = 1.0;   // Depth tolerance of the projector shadow test, mm.
  int albedo_supersampling = 4;  // Albedo samples per pixel side (area-integrates ink edges).
  // The camera as another renderer or a real one draws it: its lens blurs the image (a
  // Gaussian of this sigma, camera pixels, before the noise), and photon (shot) noise adds a
  // standard deviation of shot_noise_dn at full scale, falling as the square root of the level.
  double camera_blur_px = 0.0;
  double shot_noise_dn = 0.0;
  // The studio-light texture's bits per sample: 8, or 16 (a camera that gives more than 8 bits,
  // its full scale at 65535; the noise in the same DN of an 8-bit full scale). The structured
  // light frames are 8-bit either way.
  int texture_bits = 8;
  // The projector's light as a real one gives it, off by default: its irradiance
  // falls with the square of the distance from its centre (relative to the distance to the
  // world's origin on the table) and towards the edges of its image (1 - vignetting r^2, r = 1
  // at the image's corner).
  bool projector_falloff = false;
  double projector_vignetting = 0.3;
  // Studio lamps for the texture (world mm, point sources): each lights a surface point by
  // cos(incidence) / distance^2 (no shadows), the sum scaled to 1 at the world's origin on the
  // table. None: the texture is lit evenly, as before.
  std::vector<cv::Vec3d> studio_lamps;

  bool Check(std::string* why) const;
};

// A light of the station other than the texture's studio lights, each giving one
// extra image of the page in the scan's pose: a distant light from one direction (raking light
// from a side), or the page's UV fluorescence. The page's normal includes its relief
// (PageOptions::ridge_height_mm). Not modelled: the shadow one part of the page casts on
// another (a curl's on the flat part) and light the page throws on itself; a point turned away
// from the light is dark.
struct SceneLight {
  enum class Kind { kDistant, kFluorescence };
  std::string name;
  Kind kind = Kind::kDistant;
  // kDistant: unit vector from the page towards the light, world.
  cv::Vec3d direction{0.0, 0.0, 1.0};
  // kDistant: the camera's level, as a fraction of full scale, for albedo 1 lit square on.
  // kFluorescence: for albedo 1 under the UV lamps, which light the page evenly; the paper
  // fluoresces in proportion to its albedo (ink quenches it).
  double intensity = 1.0;
};

// `count` raking lights at `elevation_deg` above the table, evenly around it starting at
// `azimuth_deg` (0: from +x, counter-clockwise seen from above), named raking-<azimuth>
// ("raking-000", "raking-090", ...).
std::vector<SceneLight> RakingLights(int count, double elevation_deg = 30.0,
                                     double azimuth_deg = 0.0);
// UV fluorescence, named "uv".
SceneLight UvLight();

// What the page lies on and among: the table (z = 0) and, on it, optionally a support board
// under the page and a flat paper frame (mount) whose window the leaf lies in; or, instead of
// one page, an open book. (The board's and frame's sides are not modelled: their tops only.)
struct SceneOptions {
  bool support = false;  // A board under the page (foam board, a box).
  cv::Rect2d support_mm{-180.0, -145.0, 360.0, 290.0};  // World x, y extent of its top, mm.
  double support_height_mm = 5.0;                     // Its top above the table (the page's base).
  double support_albedo = 0.80;                       // White foam board: within 10% of paper.
  bool frame = false;                                 // A paper mount on the page's base.
  cv::Rect2d frame_mm{-150.0, -145.0, 300.0, 290.0};  // Its outer extent, mm.
  double frame_window_margin_mm = 0.0;                // Window: the leaf's rectangle grown by this.
  double frame_thickness_mm = 0.5;
  double frame_albedo = 0.80;
  bool spread = false;         // An open book: two pages (kGutter) left and right of x = 0.
  double spread_gap_mm = 2.0;  // Between the two pages' gutter edges, mm.

  bool Check(std::string* why) const;
};

// The default station: camera 1600x1200, f = 2400 px, 600 mm above the table (0.25 mm/px),
// projector 1024x768, f = 1800 px, 225 mm to the side and 650 mm up, aimed at the page.
Calibration DefaultRig();
// A rig for quick tests: DefaultRig's geometry with a 400x300 camera (about 1 mm per pixel)
// and a 320x200 projector; a scan of it renders and processes in about a second.
Calibration QuickRig();

// Per camera pixel ground truth.
struct GroundTruth {
  cv::Mat points;      // CV_32FC3 true world point of the surface seen by the pixel, mm.
  cv::Mat page;        // CV_32FC2 true flat page coordinate (s, t), mm; NaN off the page.
  cv::Mat on_page;     // CV_8U 255 where the pixel sees a page.
  cv::Mat page_index;  // CV_8U which page the pixel sees: 1 + its index in pages(); 0 none.
  cv::Mat lit;         // CV_8U 255 where the projector lights the surface directly.
};

class VirtualGantry {
 public:
  // `page` is the leaf; with scene.spread, the shape of both pages of the book is kGutter.
  // Options that fail their Check() throw std::invalid_argument, naming the option.
  VirtualGantry(const Calibration& rig, const PageOptions& page, const TextureOptions& texture,
                const LightOptions& light = LightOptions(),
                const SceneOptions& scene = SceneOptions());

  const GroundTruth& truth() const { return truth_; }
  // The albedo each camera pixel sees (CV_32F, averaged over the pixel's footprint).
  const cv::Mat& albedo() const { return albedo_; }
  const Calibration& rig() const { return rig_; }
  // The pages in the scene (one leaf, or the two pages of a spread, left then right).
  const std::vector<Page>& pages() const { return pages_; }

  // Camera frame (CV_8U) while the projector shows `projector_image` (CV_8U, projector size,
  // virtual unmirrored frame). `seed` makes the noise repeatable.
  cv::Mat RenderFrame(const cv::Mat& projector_image, uint64_t seed) const;
  // Camera frame under studio light, projector black.
  cv::Mat RenderTexture(uint64_t seed) const;
  // Camera frame under `light` alone (projector black, studio lights off), gray, of the
  // texture's bit depth (LightOptions::texture_bits), with the camera's noise.
  cv::Mat RenderLight(const SceneLight& light, uint64_t seed) const;

 private:
  void TraceCamera();
  void ShadeSetup(const std::vector<PageTexture>& textures);
  // Where a camera ray from `centre` meets the scene around the pages (frame, support, table),
  // and that surface's albedo.
  cv::Vec3d Background(const cv::Vec3d& centre, const cv::Vec3d& ray, double* albedo) const;
  cv::Rect2d FrameWindow() const;
  // A camera image `clean` (CV_32F levels, or CV_32FC3) blurred by the lens and given the
  // camera's noise (read noise `noise`, the same type, and shot noise from `seed`).
  void Camera(cv::Mat* clean, const cv::Mat& noise, uint64_t seed) const;

  Calibration rig_;
  LightOptions light_;
  SceneOptions scene_;
  std::vector<Page> pages_;
  cv::Mat background_albedo_;           // CV_32F albedo of the scene behind each pixel.
  std::vector<cv::Vec3d> grain_waves_;  // The surround's grain: (kx, ky rad/mm, phase) each.
  GroundTruth truth_;
  cv::Mat projector_map_;  // CV_32FC2 projector pixel hit by each camera pixel's point.
  cv::Mat gain_;           // CV_32F DN per unit projector intensity (0 in shadow).
  cv::Mat offset_;         // CV_32F DN of the ambient light.
  cv::Mat albedo_;         // CV_32F albedo seen by each pixel.
  cv::Mat studio_;         // CV_32F the studio lamps' light on each pixel's point (1: even).
  cv::Mat normal_;         // CV_32FC3 the surface's normal at each pixel's point, with relief.
  cv::Mat colour_albedo_;  // CV_32FC3 its albedo per channel (B, G, R); empty when all gray.
};

}  // namespace vellum
