// The stages of a scan named once, in their order, and a run of any slice of them. `vellum
// process` runs them all (RunPipeline, pipeline/process.h); each processing daemon runs its own
// slice on what came over the bus (the decoder kDecode, the triangulator kTriangulate, the
// flattener kOutline and each page's kMesh..kFlatten, the restorer each page's
// kRestore..kLights and then kArchive), so a stage added here runs everywhere.
#pragma once

#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "pipeline/context.h"
#include "pipeline/stages.h"
#include "pipeline/work.h"

namespace vellum {

// The stages, in the order they run. kMesh .. kLights run once for each page of the scan (the
// leaf, or a spread's two pages), page after page; the others once for the scan.
enum class Step {
  kDecode,
  kTriangulate,
  kOutline,
  kMesh,
  kFlatten,
  kRestore,
  kAlbedo,       // With a flat field.
  kReflectance,  // With a studio field.
  kLights,       // With extra lights.
  kArchive,
};
const char* ToString(Step step);
inline bool PerPage(Step step) { return step >= Step::kMesh && step <= Step::kLights; }

// Told before each step its name and the share of the whole run done so far.
using PipelineProgress = std::function<void(const std::string& stage, double done)>;

class Pipeline {
 public:
  explicit Pipeline(const PipelineOptions& options) : options_(options) {}
  const PipelineOptions& options() const { return options_; }

  // What must hold before any work: the camera's ICC profile, the flat field and the studio
  // field fit the scan and its calibration. The error names the files.
  Status Check(const ScanWork& work) const;

  // Runs the steps `from` .. `to` in order, the page steps for every page of work->outline
  // (work->pages made from it when empty), page after page. Stops at the first step that
  // fails, with its error (naming work->name, but for the triangulation's, which names its own);
  // every step's report is in work->stages. The report's pictures may still be being written
  // when it returns: work->writes->Wait() before the files are needed on disk.
  Status Run(Step from, Step to, ScanWork* work, const PipelineProgress& progress = nullptr) const;
  // The page steps `from` .. `to` of page `k` alone (a daemon's page as it came).
  Status RunPage(size_t k, Step from, Step to, ScanWork* work) const;

 private:
  StageReport RunStep(Step step, ScanWork* work) const;
  StageReport RunPageStep(Step step, PageResult* page, ScanWork* work) const;
  bool Skipped(Step step, const ScanWork& work) const;

  PipelineOptions options_;
};

}  // namespace vellum
