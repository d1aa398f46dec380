// What processing a scan writes (docs/formats.md, `vellum process`): mesh.ply and flat.ply,
// restored.tif and restored.json, the masters. One writer for each, called by the pipeline's
// stages (pipeline/stages.h) for `vellum process` and the daemons alike; points.ply
// (io/ply.h) and depth.png (core/report/pictures.h) are written by the triangulate stage.
#pragma once

#include <map>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/common/text.h"
#include "core/mesh/mesh.h"
#include "core/patterns/scan.h"
#include "core/restore/restore.h"
#include "io/xmp.h"

namespace vellum {

// mesh.ply (3D) and flat.ply (z = 0): the sheet's active nodes in the same order, quad faces.
Status WriteSheets(const std::string& dir, const Mesh& mesh, const std::vector<cv::Point2d>& flat);
// The archival master: the texture as captured (unflattened, the camera's own pixels), as
// archival.tif in `dir`, with the same identity, XMP and ICC profile as the restored page
// (`icc`: the camera's profile; empty: sRGB).
Status WriteArchivalMaster(const std::string& dir, const cv::Mat& texture,
                           const ScanIdentity& identity, const IccProfile& icc = IccProfile());

// restored.tif (TIFF dpi tags in orthographic view), restored_mask.png (when the leaf's mask was
// restored: 255 on the leaf), sampling_ppi.tif (the true sampling map, 32-bit float ppi, 0 off
// the leaf; orthographic view) and restored.json (the map from flat mm to pixels, the turn, the
// scan's catalogue identity when it has one, and `provenance`). `provenance` (key -> text: the
// scale and its error, the calibration's checksum, the options) goes into restored.json and
// the TIFF's XMP beside the dpi. The TIFF embeds `icc` (the camera's profile; empty: sRGB).
Status WriteRestored(const std::string& dir, const RestoreResult& restored,
                     const ScanIdentity& identity = ScanIdentity(),
                     const std::map<std::string, std::string>& provenance = {},
                     const IccProfile& icc = IccProfile());

// restored_albedo.tif (or `file`): the page's restored albedo (16-bit, gray or one channel per
// texture channel, linear reflectance, 65535 = 1, 0 where not measured), with the dpi tags, the
// identity and `figures` in its XMP, and no colour profile (its values are reflectances, not an
// encoded image).
Status WriteRestoredAlbedo(const std::string& dir, const RestoreResult& albedo,
                           const ScanIdentity& identity,
                           const std::map<std::string, std::string>& figures,
                           const std::string& file = "restored_albedo.tif");

// lights/<name>.tif in `dir`: one of the scan's extra lights restored with the page (as
// captured: 8 or 16 bit, gray or colour), with the dpi tags of `restored`, the identity and
// `figures` in its XMP, and the camera's ICC profile `icc` (empty: sRGB).
Status WriteRestoredLight(const std::string& dir, const std::string& name, const cv::Mat& image,
                          const RestoreResult& restored, const ScanIdentity& identity,
                          const std::map<std::string, std::string>& figures,
                          const IccProfile& icc = IccProfile());

// normals.tif in `dir`: the page's photometric normals as a normal map (NormalMapImage: 16-bit,
// R, G, B = x right, y up, z out of the page, each (c + 1) / 2 of full scale; 0 where marked),
// with the dpi tags of `restored`, the identity and `figures` in its XMP, no colour profile.
Status WriteNormalMap(const std::string& dir, const cv::Mat& normal_map,
                      const RestoreResult& restored, const ScanIdentity& identity,
                      const std::map<std::string, std::string>& figures);

}  // namespace vellum
