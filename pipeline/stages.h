// The processing of a scan as stages (Brown & Seales 2004, sections 3.2-3.10): decode,
// triangulate, outline (find the leaf, or the two pages of a spread), then for each page mesh
// (build the sheet), flatten and restore. Each stage takes typed options, computes its
// product, writes its files to the scan's results folder and returns a StageReport (its status,
// options, figures, outputs and warnings). `vellum process` runs them in a row (RunPipeline,
// pipeline/process.h); each processing daemon runs its own and carries the reports on with its
// product. One function per stage, so both give the same files.
#pragma once

#include <limits>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/decode/decode.h"
#include "core/flatten/flatten.h"
#include "core/geometry/calibration.h"
#include "core/geometry/triangulate.h"
#include "core/mesh/mesh.h"
#include "core/outline/outline.h"
#include "core/patterns/scan.h"
#include "core/restore/restore.h"
#include "core/shading/albedo.h"
#include "core/shading/photometric.h"
#include "io/xmp.h"
#include "pipeline/context.h"
#include "pipeline/report.h"
#include "pipeline/work.h"

namespace vellum {

// When a result is doubtful (a warning in report.json, the report and on the status channel,
// and `vellum process` exits with status 3).
struct WarningLimits {
  double min_outline_confidence = 0.9;  // Share of the leaf's rim set apart from its surround.
  // A hole of the leaf whose surface stands above it, of this share of the leaf's area or
  // more: the leaf itself, likely, on a support taken for it (HighestRaisedHole).
  double min_raised_hole = 0.02;
  double max_mean_strain = 0.002;  // Mean relative spring-length error after flattening.
  // Relative spring-length error kept by kWidespreadSprings springs or more (a crease, or more
  // than the leaf, strains a line or an area of them). Paper does not stretch by percents: springs
  // kept this far off their rest length lie along a crease sharper than the decoder resolves (its
  // fit rounds the ridge over a few pixels, and the page comes out short across it by tenths of a
  // mm), or on more than the leaf. The single worst spring is no measure: where a crease passes a
  // node, that node's fit cuts its corner and strains its own few springs by 3-5% (five creased
  // leaves of the scene family that met every bar), which the sheet takes up within the cell.
  double max_strain = 0.025;
  cv::Size2d expected_leaf_mm{0, 0};  // The leaf's size as the operator expects it (0: none).
  double size_tolerance = 0.1;        // Relative difference from it that is doubtful.
  // Share of the leaf's pixels that may be clipped (at the camera's maximum, or 0): above it,
  // the texture has lost detail there (glare, or an exposure too long or too short).
  double max_clipped = 0.005;
  // Share of the leaf's pixels that should have a 3D point: below it, parts of the leaf were
  // not measured (glare, the projector's light not reaching, ink too dark to decode).
  double min_valid_in_leaf = 0.9;
  // An output dpi asked above the page's finest true sampling by more than this share is
  // upsampling: the restored page holds no detail finer than the camera saw.
  double max_upsampling = 0.05;
  // Share of the pixels the projector lit (white against black) that must give a 3D point: in a
  // sound scan nearly all do (99.8% on the virtual gantry's leaves); far fewer means the frames
  // do not belong together (frames of another scan, patterns out of order, a projector or camera
  // that moved), and the points that did decode are doubtful too.
  double min_points_of_lit = 0.5;
  // Share of the lit pixels at which a Gray frame and its inverse may fail to add up to the
  // white and black frames (FramePairCheck), above both this and pair_over_usual times the scan's
  // own median pair: a frame of another scan or leaf, a pattern in another's place, or one
  // taken before the projector changed (frame_contradicts, naming the frames).
  double max_pair_disagreement = 0.02;
  double pair_over_usual = 4.0;
  // Above this share a pair is named whatever the scan's usual: when every pair is off (frames
  // of two scans mixed in one folder), the usual is no yardstick (sound pairs: 0.02%).
  double pair_always_named = 0.05;
  // On a spread, the least page surface the gutter keeps from view (UnseenAtGutter's median),
  // mm: above it, the pages' inner margins are not all in the restored pages.
  double max_gutter_unseen_mm = 5.0;
};

// Every stage's options: what `vellum process` takes, and each daemon its own part of.
struct PipelineOptions {
  // The stages' defaults, and the restored page cropped to the leaf and set upright.
  PipelineOptions() {
    restore.deskew = true;
    restore.crop_to_leaf = true;
  }

  DecodeOptions decode;
  TriangulateOptions triangulate;
  OutlineOptions outline;
  MeshOptions mesh;
  bool auto_grid = true;            // Choose each sheet's grid from its shape (mesh.grid at least).
  double max_warp_error_px = 0.05;  // The chosen grid keeps the warp this close, camera pixels.
  FlattenOptions flatten;
  RestoreOptions restore;
  WarningLimits limits;
  // Stop after the point cloud (points.ply, depth.png): an object that is not a page.
  bool points_only = false;
  // The camera's ICC profile, embedded in the masters (--camera-icc); empty: sRGB.
  IccProfile camera_icc;
  // The projector's flat field (--flatfield); with it, each page's albedo (AlbedoStage).
  FlatField flat_field;
  // The studio lamps' field (--studio-field); with it, each page's reflectance from the texture
  // (ReflectanceStage).
  StudioField studio_field;
  // The collection's target (--target-fadgi, --target-ppi, --target-bits): a page short of it
  // cannot pass (AssessQuality names the figure).
  QcTarget target;

  bool Check(std::string* why) const;
};

// A page's name ("" for a single leaf; "left", "right" for the pages of a spread) and the
// folder its files go to (the results folder, or results/pages/<name>).
std::string PageName(const Outline& outline, size_t page);
std::string PageDir(const std::string& results, const std::string& page);

// Decode (3.2): the frames of `scan` -> projector coordinates per camera pixel, by `decoder`
// (which keeps its buffers between scans). The frames are scan.frames; when that is empty
// (ReadScanHeader) they are read from the scan folder `frames_dir` and each is decoded as it is
// read, so they are never all in memory; with no folder either, they are those already added
// to the decoder (Decoder::Begin and Add, as a camera gave them), and it finishes. Writes
// nothing.
StageReport DecodeStage(const Scan& scan, Decoder* decoder, const WarningLimits& limits,
                        DecodeResult* decoded, const std::string& frames_dir = "");

// Triangulate (3.2): the correspondences -> the point map, by `triangulator` (which holds the
// calibration's rays). Writes points.ply, depth.png, report/valid.png and report/depth.png.
// Flags (decode_low) a scan whose lit pixels mostly gave no point (limits.min_points_of_lit).
StageReport TriangulateStage(const DecodeResult& decoded, const Triangulator& triangulator,
                             const TriangulateOptions& options, const WarningLimits& limits,
                             const std::string& results, PointMap* map);

// The texture's picture in the report, relative to the results folder.
inline constexpr const char* kTexturePicture = "report/texture.png";
// Writes it from the scan's texture, as the outline stage does: a daemon writes it as soon as
// the texture comes, while the patterns are still projected.
Status WriteTexturePicture(const std::string& results, const cv::Mat& texture);

// Outline: the leaf (or a spread's two pages) in the point map and the texture
// (core/outline), seeded at the operator's hint for the scan (context.leaf_hint) when there is
// one, else at options.hint, and told what the object is when the operator said
// (context.object). Writes report/texture.png (unless `texture_pictured`: written already by
// WriteTexturePicture) and report/outline.png. Warns of a leaf that runs off the view and of an
// outline of low confidence. `rig` measured the points (its projector's shadows are told from
// the leaf).
StageReport OutlineStage(const cv::Mat& points, const cv::Mat& texture, const Calibration& rig,
                         const ScanContext& context, const OutlineOptions& options,
                         const WarningLimits& limits, const std::string& results,
                         bool texture_pictured, Outline* outline);

// The stages that run once for each page take the scan as the pipeline holds it (`work`: its
// texture, lights, calibration, context, point map, the stages' reports so far and the results
// folder) and the page (`page`: its name and mask, and the products of its earlier stages), and
// write their product into the page.

// Mesh (3.5-3.6): page->mesh, the sheet over the page (its mask, camera pixels) of the point
// map, its grid chosen from the page's shape when `options.auto_grid`. Writes nothing (the sheet
// is written with its flattened twin).
StageReport MeshStage(const ScanWork& work, const PipelineOptions& options, PageResult* page);

// Flatten (3.7-3.8): page->flat, the sheet onto the plane. Writes mesh.ply and flat.ply in the
// page's folder. Warns of strain and fold-over above the limits.
StageReport FlattenStage(const ScanWork& work, const PipelineOptions& options, PageResult* page);

// The archival master of the scan: the texture as captured, as archival.tif in `results`, with
// the scan's identity and the camera's ICC profile (`camera_icc`; empty: sRGB)
// (WriteArchivalMaster). Once per scan, after its pages.
StageReport ArchiveStage(const cv::Mat& texture, const ScanIdentity& identity,
                         const IccProfile& camera_icc, const std::string& results);

// Restore (3.10): page->restored, the texture through the flattened sheet, with the page's mask
// (cropped to the leaf and set upright when options ask it). Writes restored.tif, restored_mask.png
// and restored.json in the page's folder and the report's pictures of the page (grid, strain,
// before/after), and the camera's true sampling of the page (sampling_ppi.tif, its summary and
// picture). Warns of a leaf whose size is not the one expected, and of a dpi asked above the
// true sampling. The scan's identity (a spread's page gets its own, PageIdentity) and its
// calibration's checksum and scale error (work.context), the page's flattening residual
// (page->flat: its flat positions and strains) and the options every stage so far recorded in
// its report (work.stages) go into restored.json and the TIFF's XMP. The TIFF embeds the
// camera's ICC profile (options.camera_icc; empty: sRGB), named in the report.
StageReport RestoreStage(const ScanWork& work, const PipelineOptions& options, PageResult* page);

// Albedo: page->albedo, the page's reflectance from the projector's light (core/shading/albedo.h,
// from work.amplitude, the decoder's, and the point map, with options.flat_field), restored
// through the page's own warp (RestoreMore of page->restored: the same triangles, samples and
// crop): restored_albedo.tif in the
// page's folder, 16-bit gray, linear (65535 = albedo 1), 0 where the model does not hold (marked:
// the projector's shadow, the page's rim, grazing light, outside the flat field).
StageReport AlbedoStage(const ScanWork& work, const PipelineOptions& options, PageResult* page);

// Reflectance from the studio light: page->reflectance, the texture's shading by the studio
// lamps taken out by the page's measured shape (core/shading/albedo.h, CorrectTexture, with
// options.studio_field),
// restored as AlbedoStage restores the albedo: restored_reflectance.tif in the page's folder,
// 16-bit, one channel per texture channel, linear (65535 = reflectance 1), 0 where marked (not
// measured, the page's rim, too little of the lamps' light, outside the studio field).
StageReport ReflectanceStage(const ScanWork& work, const PipelineOptions& options,
                             PageResult* page);

// Lights: page->lights, the scan's extra images (work.scan.lights) restored through the page's
// own warp (RestoreMore of page->restored), so they register to it and to each other pixel for
// pixel: lights/<name>.tif in the page's folder (as captured, with the camera's ICC profile
// options.camera_icc). With three or more lights of known direction, the page's
// photometric normals (core/shading/photometric.h) on the flat page in its own frame:
// normals.tif (WriteNormalMap) and a picture of the relief lit from the top left. With six or
// more, at two or more elevations, a polynomial texture map of the flat page for RTI viewers:
// lights.ptm (FitPtm, WritePtm).
StageReport LightsStage(const ScanWork& work, const PipelineOptions& options, PageResult* page);

}  // namespace vellum
