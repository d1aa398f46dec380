// A scan as the pipeline's steps see it (pipeline/pipeline.h): its inputs, then each step's
// product as the step makes it, and each page's. The stages of pipeline/stages.h that run once
// for each page read the scan's part and write their page's.
#pragma once

#include <memory>
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
#include "core/shading/photometric.h"
#include "pipeline/context.h"
#include "pipeline/report.h"
#include "pipeline/writes.h"

namespace vellum {

// The scan's extra lights restored through a page's warp (LightsStage).
struct LightsResult {
  std::vector<std::string> names;  // The lights restored, in the scan's order.
  std::vector<cv::Mat> images;     // Each restored, registered to the restored page.
  cv::Mat normals;  // CV_32FC3 on the restored page (x right, y up, z out); empty without.
  PtmResult ptm;    // With six or more directed lights at two elevations: lights.ptm.
};

// One page of the scan: the leaf, or a page of a spread.
struct PageResult {
  std::string name;  // "" for a single leaf; "left", "right".
  cv::Mat mask;      // The page's camera pixels (CV_8U), from the outline.
  Mesh mesh;
  FlattenResult flat;
  RestoreResult restored;
  RestoreResult albedo;       // With a flat field: the page's albedo, restored as `restored` is.
  RestoreResult reflectance;  // With a studio field: the texture's reflectance, restored alike.
  LightsResult lights;        // The scan's extra lights (and their normals), restored alike.
};

// A scan as a run holds it: its inputs, then each step's product as the step makes it. `vellum
// process` fills the inputs from the scan's folder; a daemon those its slice reads, from the bus
// (the triangulator `decoded`, the flattener `map`, the restorer each page's name, mask, mesh
// and flat, and `map` and `amplitude` for the albedo and reflectance).
struct ScanWork {
  // The scan: its sequence, texture and extra lights, and its frames, or none: they are then
  // read from `frames_dir` as they are decoded, or are those already added to `decoder`.
  Scan scan;
  std::string frames_dir;
  Calibration calibration;
  ScanContext context;
  std::string results;  // The folder the steps write to.
  // The texture's picture is in `results` already (WriteTexturePicture, by a daemon as the
  // texture came): the outline step lists it and does not write it again.
  bool texture_pictured = false;
  std::string name;              // What errors name (the scan's folder); "" for none.
  std::string calibration_name;  // What errors call the calibration (its file).
  // The decode step's decoder, which keeps its buffers between scans; null: one of the step's
  // own, freed when it is done. Likewise the triangulator (null: one from `calibration`).
  Decoder* decoder = nullptr;
  const Triangulator* triangulator = nullptr;

  DecodeResult decoded;  // Until triangulated.
  cv::Mat amplitude;     // The decoder's (white - black) / 2, kept for the albedo (a flat field).
  PointMap map;
  Outline outline;
  std::vector<PageResult> pages;    // The outline's pages, as their steps run.
  std::vector<StageReport> stages;  // Every step's report, in the order they ran.
  // The steps' pictures still being written (pipeline/writes.h): wait for them before the
  // files are needed on disk.
  std::shared_ptr<FileWrites> writes = std::make_shared<FileWrites>();
};

}  // namespace vellum
