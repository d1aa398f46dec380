// The processing of a scan as five stages (Brown & Seales 2004, sections 3.2-3.10): decode,
// triangulate, mesh (find the page and build the sheet), flatten, restore. Each stage takes
// typed options, computes its product, writes its files to the scan's results folder and
// returns a StageReport (its status, options, figures and outputs). `vellum process` runs them
// in a row (RunPipeline, pipeline/process.h); each processing daemon runs its own and carries
// the reports on with its product. One function per stage, so both give the same files.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/decode/decode.h"
#include "core/flatten/flatten.h"
#include "core/geometry/calibration.h"
#include "core/geometry/triangulate.h"
#include "core/mesh/mesh.h"
#include "core/patterns/scan.h"
#include "core/restore/restore.h"
#include "pipeline/report.h"

namespace vellum {

// Every stage's options: what `vellum process` takes, and each daemon its own part of.
struct PipelineOptions {
  DecodeOptions decode;
  TriangulateOptions triangulate;
  MeshOptions mesh;
  FlattenOptions flatten;
  RestoreOptions restore;

  bool Check(std::string* why) const;
};

// Decode (3.2): the frames of `scan` -> projector coordinates per camera pixel, by `decoder`
// (which keeps its buffers between scans). Writes nothing.
StageReport DecodeStage(const Scan& scan, Decoder* decoder, DecodeResult* decoded);

// Triangulate (3.2): the correspondences -> the point map, by `triangulator` (which holds the
// calibration's rays). Writes points.ply, depth.png, report/valid.png and report/depth.png.
StageReport TriangulateStage(const DecodeResult& decoded, const Triangulator& triangulator,
                             const TriangulateOptions& options, const std::string& results,
                             PointMap* map);

// Mesh (3.5-3.6): the page found in the texture, and the sheet built over the point map there.
// Writes nothing (the sheet is written with its flattened twin).
StageReport MeshStage(const cv::Mat& points, const cv::Mat& texture, const CameraModel& camera,
                      const MeshOptions& options, Mesh* mesh);

// Flatten (3.7-3.8): the sheet onto the plane. Writes mesh.ply and flat.ply.
StageReport FlattenStage(const Mesh& mesh, const FlattenOptions& options,
                         const std::string& results, FlattenResult* flat);

// Restore (3.10): the texture through the flattened sheet. Writes restored.tif,
// restored.json and the report's pictures of the page (texture, grid, strain, before/after).
StageReport RestoreStage(const cv::Mat& texture, const Mesh& mesh,
                         const std::vector<cv::Point2d>& flat, const CameraModel& camera,
                         const RestoreOptions& options, const std::string& results,
                         RestoreResult* restored);

}  // namespace vellum
