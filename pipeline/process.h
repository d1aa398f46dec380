// `vellum process` as one call: a scan directory and its calibration through every stage of
// pipeline/stages.h, into a results folder (docs/formats.md's products, report.json, report.html).
#pragma once

#include <functional>
#include <string>

#include "core/common/status.h"
#include "core/geometry/calibration.h"
#include "core/patterns/scan.h"
#include "pipeline/pipeline.h"
#include "pipeline/report.h"
#include "pipeline/stages.h"

namespace vellum {

struct ProcessInput {
  std::string scan_dir, calibration_path;  // Where they were read from (for messages, report).
  Scan scan;  // Its frames, or none: RunPipeline then reads them from scan_dir as it decodes.
  Calibration calibration;
};

// Reads the scan directory's scan.yaml and texture (checking that every frame is there, of the
// camera's size; the frames themselves are read while they are decoded) and the calibration,
// and checks that they belong together (camera and projector sizes); errors name the file and
// the problem.
Status ReadProcessInput(const std::string& scan_dir, const std::string& calibration_path,
                        ProcessInput* input);

struct ProcessResult {
  Status status = Status::Error("pipeline not run");
  ProcessReport report;  // The stages that ran, their warnings, and the files written.
  PointMap map;          // The products, for a caller's summary.
  Outline outline;
  std::vector<PageResult> pages;
};

// Runs decode, triangulate and outline, then mesh, flatten and restore for each page, into
// `results`, then writes report.html and report.json. Errors name the scan directory, or the
// file that failed. The results are written whole or not at all: the run writes into a hidden
// folder beside `results` (PartName) that takes its place only when every stage succeeded, so a
// failed run (an error, a full disk) leaves `results` as it was and a killed one only the hidden
// part, which the next run removes. `results` may be new, empty or an earlier run's results
// (it holds report.json): anything else is refused (CheckResultsFolder) before any work.
ProcessResult RunPipeline(const ProcessInput& input, const PipelineOptions& options,
                          const std::string& results, const PipelineProgress& progress = nullptr);

// Ok when a run may write `results`: absent, an empty folder, or an earlier run's results.
Status CheckResultsFolder(const std::string& results);

}  // namespace vellum
