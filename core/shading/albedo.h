// Reflectance, not shading: the page's albedo per camera pixel from the projector's
// own light, which vellum knows as a calibrated light source.
//
// The model: a Lambertian page lit by the projector alone. What the camera sees under the
// projector's full white, less what it sees under its black (the ambient and the studio light
// cancel), is
//     white - black = albedo * G(p) * cos(i) * (d0 / d)^2
// where p is the projector pixel whose ray lights the point, G(p) the projector's light along
// that ray as this camera sees it (its lamp, its lens's vignetting, its response, and the
// camera's gain), i the angle of incidence on the page (from the page's normal, from the
// measured shape), d the distance from the projector's centre and d0 a reference distance (the
// projector's centre to the world's origin on the table). G is measured once, from a white
// target of known albedo lying on the table (MeasureFlatField: cos(i) and d are known there).
//
// What is not modelled: light the page throws on itself (interreflection, in a deep gutter or a
// tight curl), gloss, the camera's own vignetting where the page stands far from the table (it
// is folded into G as seen on the table), and subsurface light. Pixels where the model does not
// hold are marked, not guessed: not lit by the projector (its shadow; undecoded), lit at a
// grazing angle (cos(i) below a limit), or lit by a projector pixel the flat field never saw.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/geometry/calibration.h"

namespace vellum {

// The projector's light as the camera sees it, on a grid of projector pixels: G(p) in camera DN
// of (white - black) for an albedo-1 surface met square on at the reference distance.
struct FlatField {
  cv::Mat gain;             // CV_32F, one value per cell; NaN where the target never reached.
  int cell_px = 8;          // Projector pixels per cell side; cell (i, j) is centred on
                            // projector pixel ((i + 0.5) cell - 0.5, (j + 0.5) cell - 0.5).
  double reference_mm = 0;  // d0: the projector's centre to the world's origin, mm.
  cv::Size projector_size;  // The projector it was measured for.

  bool empty() const { return gain.empty(); }
  // G at projector pixel p (bilinear between cell centres); NaN outside what was measured.
  double At(const cv::Point2d& p) const;
};

struct FlatFieldOptions {
  double target_albedo = 0.9;  // The white target's reflectance (its maker's figure).
  int cell_px = 8;             // Projector pixels per cell side.
  int min_samples = 4;         // Camera pixels a cell needs to be measured.

  bool Check(std::string* why) const;
};

// The flat field from a scan of a white target lying flat on the table (z = 0): `amplitude` is
// the decoder's (white - black) / 2 per camera pixel (DecodeResult::amplitude), `points` the
// triangulated point map (CV_32FC3, NaN where not measured). Each measured camera pixel on the
// target gives G of the projector pixel lighting it; each cell takes the mean of its pixels.
FlatField MeasureFlatField(const cv::Mat& amplitude, const cv::Mat& points,
                           const Calibration& calibration, const FlatFieldOptions& options,
                           Status* status);

struct AlbedoOptions {
  double min_cos = 0.35;     // Incidence more grazing than this (about 70 degrees) is marked.
  int normal_window_px = 4;  // Half-size of the window the page's normal is taken over.

  bool Check(std::string* why) const;
};

struct AlbedoResult {
  Status status = Status::Error("albedo not estimated");
  cv::Mat albedo;  // CV_32F per camera pixel; 0 where marked.
  cv::Mat valid;   // CV_8U, 255 where the model holds (lit, not grazing, in the flat field).
  // Pixels estimated, and marked: not measured (the projector's shadow, undecoded), within the
  // normal's window of the page's rim, lit at a grazing angle (CorrectTexture: too little of the
  // lamps' light), lit from outside the flat field (CorrectTexture: outside the studio field).
  int estimated = 0, shadowed = 0, rim = 0, grazing = 0, outside_flat_field = 0;
};

// `a.albedo` with its marked pixels NaN: through a warp (RestoreMore), a restored pixel that
// drew on any marked camera pixel comes out NaN, marked too, in the one pass.
cv::Mat MarkedAsNaN(const AlbedoResult& a);

// The albedo of every measured camera pixel of the page (`page`: CV_8U, nonzero on it, e.g. the
// leaf's outline; empty: every pixel): `amplitude` and `points` as for MeasureFlatField, of the
// scan whose page is wanted. The normals come from the page's own points (their plane within
// the window around each pixel; never across the page's rim).
AlbedoResult EstimateAlbedo(const cv::Mat& amplitude, const cv::Mat& points, const cv::Mat& page,
                            const Calibration& calibration, const FlatField& flat_field,
                            const AlbedoOptions& options = AlbedoOptions());

// The studio lights' own flat field: the texture is lit by the studio's lamps, not the
// projector, so its shading is corrected from the same shape where the lamps are described.
// The model: a Lambertian page lit by point lamps of equal strength at known places (world mm),
// each giving cos(i) / d^2, summed as E(x, n) and taken relative to a surface at the world's
// origin facing up; the camera sees level = reflectance * K(p) * E(x, n), where K is the lamps'
// strength and the camera's gain and vignetting along pixel p's ray. K is measured once from the
// texture of a white target of known albedo lying flat on the table under the same lamps and
// exposure (each pixel sees the table point where its ray meets z = 0, facing up). Not
// modelled: the shadow one part of the page casts on another, each lamp's own beam shape away
// from the table, interreflection and gloss.
struct StudioField {
  cv::Mat gain;                  // K per cell, one channel per texture channel; NaN: not seen.
  int cell_px = 8;               // Camera pixels per cell side (K is smooth; cells average
                                 // the target's noise).
  cv::Size camera_size;          // The camera it was measured for.
  std::vector<cv::Vec3d> lamps;  // The lamps, world mm.

  bool empty() const { return gain.empty(); }
  // K at camera pixel p, per channel (bilinear between cell centres); NaN where not measured.
  cv::Vec3d At(const cv::Point2d& p) const;
};

// The lamps' light on a point x with normal n, relative to a surface at the origin facing up.
double LampLight(const std::vector<cv::Vec3d>& lamps, const cv::Vec3d& x, const cv::Vec3d& n);

// The studio field from `texture` (8 or 16 bit, gray or colour) of a white target of
// `target_albedo` lying flat on the table under `lamps`, seen by `camera`.
StudioField MeasureStudioField(const cv::Mat& texture, const CameraModel& camera,
                               const std::vector<cv::Vec3d>& lamps, double target_albedo,
                               Status* status, int cell_px = 8);

// The page's reflectance from its studio-lit texture (same type rules), its point map and
// `page` mask as EstimateAlbedo takes them: AlbedoResult::albedo has one channel per texture
// channel (CV_32F or CV_32FC3), 0 where marked (not measured, the rim, the lamps' light on it
// under a fifth of the reference's, outside the studio field).
AlbedoResult CorrectTexture(const cv::Mat& texture, const cv::Mat& points, const cv::Mat& page,
                            const Calibration& calibration, const StudioField& field,
                            const AlbedoOptions& options = AlbedoOptions());

}  // namespace vellum
