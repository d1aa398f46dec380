#include "pipeline/process.h"

#include <filesystem>

#include "core/common/text.h"
#include "io/calibration_io.h"
#include "io/scan_io.h"
#include "io/write_whole.h"

namespace vellum {

namespace fs = std::filesystem;

Status ReadProcessInput(const std::string& scan_dir, const std::string& calibration_path,
                        ProcessInput* input) {
  input->scan_dir = scan_dir;
  input->calibration_path = calibration_path;
  Status s = ReadCalibration(calibration_path, &input->calibration);
  if (!s.ok()) return s;
  s = ReadScanHeader(scan_dir, &input->scan);  // The frames are read as they are decoded.
  if (!s.ok()) return s;
  const Calibration& c = input->calibration;
  const Scan& scan = input->scan;
  if (scan.camera_size != c.camera.size) {
    return Status::Error(scan_dir + ": camera images are " + SizeText(scan.camera_size) + " but " +
                         calibration_path + " calibrates a " + SizeText(c.camera.size) + " camera");
  }
  if (scan.sequence.projector_size != c.projector.size) {
    return Status::Error(scan_dir + "/scan.yaml: projector_size is " +
                         SizeText(scan.sequence.projector_size) + " but " + calibration_path +
                         " calibrates a " + SizeText(c.projector.size) + " projector");
  }
  return Status::Ok();
}

namespace {

// The stages, into `results`.
ProcessResult RunStages(const ProcessInput& input, const PipelineOptions& options,
                        const std::string& results, const PipelineProgress& progress) {
  ProcessResult out;
  ProcessReport& report = out.report;
  report.scan = input.scan_dir;
  report.calibration = input.calibration_path;
  report.target = options.target;
  out.status = MakeDirectories(results);
  if (!out.status.ok()) return out;
  ScanWork work;
  work.scan = input.scan;  // Its frames are read from scan_dir as they are decoded.
  work.frames_dir = input.scan_dir;
  work.calibration = input.calibration;
  work.context = ScanContext::For(input.scan, input.calibration);
  work.results = results;
  work.name = input.scan_dir;
  work.calibration_name = input.calibration_path;
  const Pipeline pipeline(options);
  out.status = pipeline.Check(work);  // Said before any work.
  if (!out.status.ok()) return out;
  const Step last = options.points_only ? Step::kTriangulate : Step::kArchive;
  out.status = pipeline.Run(Step::kDecode, last, &work, progress);
  const Status written = work.writes->Wait();  // The pictures, before the reports name them.
  if (out.status.ok()) out.status = written;
  report.stages = std::move(work.stages);
  out.map = std::move(work.map);
  out.outline = std::move(work.outline);
  out.pages = std::move(work.pages);
  if (!out.status.ok()) return out;
  if (options.points_only) report.stages.back().Text("options", "until", "points");
  if (progress) progress("report", 0.97);
  out.status = WriteReports(results, input.scan_dir, &report);
  return out;
}

// `results` without a trailing separator (its name is what the part's is made from).
std::string FolderName(const std::string& results) {
  fs::path p = fs::path(results).lexically_normal();
  if (p.filename().empty() && p.has_parent_path()) p = p.parent_path();
  return p.string();
}

}  // namespace

Status CheckResultsFolder(const std::string& results) {
  std::error_code ec;
  const fs::path dir(FolderName(results));
  if (!fs::exists(dir, ec)) return Status::Ok();
  if (!fs::is_directory(dir, ec)) return Status::Error(results + ": is a file, not a folder");
  if (fs::is_empty(dir, ec) || fs::exists(dir / "report.json", ec)) return Status::Ok();
  return Status::Error(results + ": holds files but no report.json, so it is not an earlier " +
                       "run's results, and a run replaces its results folder whole: give a new " +
                       "or an empty folder");
}

ProcessResult RunPipeline(const ProcessInput& input, const PipelineOptions& options,
                          const std::string& results, const PipelineProgress& progress) {
  ProcessResult out;
  out.status = CheckResultsFolder(results);
  if (!out.status.ok()) return out;
  const std::string folder = FolderName(results);
  const std::string part = PartName(folder);
  std::error_code ec;
  fs::remove_all(part, ec);  // A killed run's.
  out = RunStages(input, options, part, progress);
  if (out.status.ok()) out.status = ReplaceFolder(part, folder);
  if (!out.status.ok()) {
    fs::remove_all(part, ec);
    // Errors name the results folder, not its temporary name.
    std::string message = out.status.message();
    for (size_t at = message.find(part); at != std::string::npos;
         at = message.find(part, at + results.size())) {
      message.replace(at, part.size(), results);
    }
    out.status = Status::Error(message);
  }
  return out;
}

}  // namespace vellum
