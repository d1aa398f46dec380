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
  // The share of a typical run done before each stage (the simulators flatten for longer).
  const bool slow = options.flatten.solver != FlattenSolver::kGaussNewton;
  auto next = [&](const char* stage, double done) {
    if (progress) progress(stage, done);
  };
  // Runs one stage; false (with out.status set) when it failed.
  auto ran = [&](StageReport stage, bool name_scan) {
    report.stages.push_back(stage);
    if (stage.status.ok()) return true;
    out.status =
        Status::Error((name_scan ? input.scan_dir + ": " : std::string()) + stage.status.message());
    return false;
  };
  Status s = MakeDirectories(results);
  if (!s.ok()) {
    out.status = s;
    return out;
  }
  const IccProfile& icc = options.camera_icc;
  if (!icc.empty() && !input.scan.texture.empty() &&
      icc.channels != input.scan.texture.channels()) {
    // Said before any work: the masters could not be written.
    out.status = Status::Error(icc.source + ": the camera's ICC profile '" + icc.description +
                               "' describes " + (icc.channels == 3 ? "colour" : "gray") +
                               " images, but " + input.scan_dir + "/texture.png is " +
                               (icc.channels == 3 ? "gray" : "colour"));
    return out;
  }
  const FlatField& field = options.flat_field;
  if (!field.empty() && field.projector_size != input.calibration.projector.size) {
    out.status = Status::Error("the flat field is for a " + SizeText(field.projector_size) +
                               " projector, but " + input.calibration_path + " calibrates a " +
                               SizeText(input.calibration.projector.size) + " one");
    return out;
  }
  const StudioField& studio = options.studio_field;
  if (!studio.empty() &&
      (studio.camera_size != input.calibration.camera.size ||
       (!input.scan.texture.empty() && studio.gain.channels() != input.scan.texture.channels()))) {
    out.status =
        Status::Error("the studio field is for a " + SizeText(studio.camera_size) + " camera of " +
                      std::to_string(studio.gain.channels()) + " channel(s), but " +
                      input.scan_dir + "/texture.png is " + SizeText(input.scan.texture.size()) +
                      " with " + std::to_string(input.scan.texture.channels()));
    return out;
  }
  const CameraModel& camera = input.calibration.camera;
  next("decode", 0.35);
  DecodeResult decoded;
  {
    // The decoder's running sums and codes (some 40 bytes a camera pixel) go when it is done,
    // before the point map is made; the decoded maps go once it is.
    Decoder decoder(options.decode);
    if (!ran(DecodeStage(input.scan, &decoder, options.limits, &decoded, input.scan_dir), true))
      return out;
  }
  // The light the projector gave each pixel (white less black), for the albedo.
  const cv::Mat amplitude = options.flat_field.empty() ? cv::Mat() : decoded.amplitude;
  next("triangulate", 0.5);
  const Triangulator triangulator(input.calibration);
  if (!ran(TriangulateStage(decoded, triangulator, options.triangulate, options.limits, results,
                            &out.map),
           false)) {
    return out;
  }
  decoded = DecodeResult();
  if (options.points_only) {
    report.stages.back().Text("options", "until", "points");
    next("report", 0.97);
    out.status = WriteReports(results, input.scan_dir, &report);
    return out;
  }
  next("outline", 0.65);
  const ScanContext context = ScanContext::For(input.scan, input.calibration);
  if (!ran(OutlineStage(out.map.points, input.scan.texture, input.calibration, context,
                        options.outline, options.limits, results, &out.outline),
           true)) {
    return out;
  }
  const size_t pages = out.outline.pages.size();
  for (size_t k = 0; k < pages; ++k) {
    PageResult page;
    page.name = PageName(out.outline, k);
    const cv::Mat& mask = out.outline.pages[k];
    const double done = 0.7 + 0.25 * k / pages, share = 0.25 / pages;
    next("mesh", done);
    if (!ran(MeshStage(out.map.points, mask, camera, options, page.name, &page.mesh), true)) {
      return out;
    }
    next("flatten", done + 0.1 * share);
    if (!ran(FlattenStage(page.mesh, options.flatten, options.limits, results, page.name,
                          &page.flat),
             true)) {
      return out;
    }
    next("restore", done + (slow ? 0.8 : 0.3) * share);
    if (!ran(RestoreStage(input.scan.texture, mask, page.mesh, page.flat, camera, options.restore,
                          options.limits, options.camera_icc, context, report.stages, results,
                          page.name, &page.restored),
             true)) {
      return out;
    }
    if (!options.flat_field.empty()) {
      next("albedo", done + 0.9 * share);
      if (!ran(AlbedoStage(amplitude, out.map.points, mask, input.calibration, options.flat_field,
                           page.restored, context, results, page.name, &page.albedo),
               true)) {
        return out;
      }
    }
    if (!options.studio_field.empty()) {
      next("reflectance", done + 0.93 * share);
      if (!ran(ReflectanceStage(input.scan.texture, out.map.points, mask, input.calibration,
                                options.studio_field, page.restored, context, results, page.name,
                                &page.reflectance),
               true)) {
        return out;
      }
    }
    if (!input.scan.lights.empty()) {
      next("lights", done + 0.95 * share);
      if (!ran(LightsStage(input.scan.lights, mask, page.mesh, page.flat.flat, options.camera_icc,
                           page.restored, context, results, page.name, &page.lights),
               true)) {
        return out;
      }
    }
    out.pages.push_back(std::move(page));
  }
  next("archive", 0.96);
  if (!ran(ArchiveStage(input.scan.texture, context.identity, options.camera_icc, results), true))
    return out;
  next("report", 0.97);
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
