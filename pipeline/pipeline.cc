#include "pipeline/pipeline.h"

#include <algorithm>

#include "core/common/text.h"

namespace vellum {

const char* ToString(Step step) {
  switch (step) {
    case Step::kDecode:
      return "decode";
    case Step::kTriangulate:
      return "triangulate";
    case Step::kOutline:
      return "outline";
    case Step::kMesh:
      return "mesh";
    case Step::kFlatten:
      return "flatten";
    case Step::kRestore:
      return "restore";
    case Step::kAlbedo:
      return "albedo";
    case Step::kReflectance:
      return "reflectance";
    case Step::kLights:
      return "lights";
    case Step::kArchive:
      return "archive";
  }
  return "?";
}

namespace {

Step Next(Step step) { return static_cast<Step>(static_cast<int>(step) + 1); }

// The share of a typical run done before each step of the scan.
double ScanShare(Step step) {
  switch (step) {
    case Step::kDecode:
      return 0.35;
    case Step::kTriangulate:
      return 0.5;
    case Step::kOutline:
      return 0.65;
    default:
      return 0.96;  // The archive.
  }
}

// The share of a page's part of the run done before each of its steps (the simulators, `slow`,
// flatten for longer).
double PageShare(Step step, bool slow) {
  switch (step) {
    case Step::kMesh:
      return 0;
    case Step::kFlatten:
      return 0.1;
    case Step::kRestore:
      return slow ? 0.8 : 0.3;
    case Step::kAlbedo:
      return 0.9;
    case Step::kReflectance:
      return 0.93;
    default:
      return 0.95;  // The lights.
  }
}

// The report of a step asked of the wrong runner: it runs once per `kind` ("page", "scan").
StageReport Misplaced(Step step, const char* kind) {
  StageReport report;
  report.stage = ToString(step);
  report.status = Status::Error(std::string("the ") + ToString(step) + " step runs per " + kind);
  return report;
}

// The pages of the outline, named, with their masks, when there are none yet.
void MakePages(ScanWork* work) {
  if (!work->pages.empty()) return;
  for (size_t k = 0; k < work->outline.pages.size(); ++k) {
    PageResult page;
    page.name = PageName(work->outline, k);
    page.mask = work->outline.pages[k];
    work->pages.push_back(std::move(page));
  }
}

}  // namespace

Status Pipeline::Check(const ScanWork& work) const {
  const std::string texture_name =
      work.name.empty() ? "the scan's texture" : work.name + "/texture.png";
  const std::string calibration_name =
      work.calibration_name.empty() ? "the scan's calibration" : work.calibration_name;
  const IccProfile& icc = options_.camera_icc;
  const cv::Mat& texture = work.scan.texture;
  if (!icc.empty() && !texture.empty() && icc.channels != texture.channels()) {
    return Status::Error(icc.source + ": the camera's ICC profile '" + icc.description +
                         "' describes " + (icc.channels == 3 ? "colour" : "gray") +
                         " images, but " + work.name + "/texture.png is " +
                         (icc.channels == 3 ? "gray" : "colour"));
  }
  const Calibration& calibration = work.calibration;
  const FlatField& field = options_.flat_field;
  if (!field.empty() && field.projector_size != calibration.projector.size) {
    return Status::Error("the flat field is for a " + SizeText(field.projector_size) +
                         " projector, but " + calibration_name + " calibrates a " +
                         SizeText(calibration.projector.size) + " one");
  }
  const StudioField& studio = options_.studio_field;
  if (!studio.empty() && (studio.camera_size != calibration.camera.size ||
                          (!texture.empty() && studio.gain.channels() != texture.channels()))) {
    return Status::Error("the studio field is for a " + SizeText(studio.camera_size) +
                         " camera of " + std::to_string(studio.gain.channels()) +
                         " channel(s), but " + texture_name + " is " + SizeText(texture.size()) +
                         " with " + std::to_string(texture.channels()));
  }
  return Status::Ok();
}

bool Pipeline::Skipped(Step step, const ScanWork& work) const {
  switch (step) {
    case Step::kAlbedo:
      return options_.flat_field.empty();
    case Step::kReflectance:
      return options_.studio_field.empty();
    case Step::kLights:
      return work.scan.lights.empty();
    default:
      return false;
  }
}

Status Pipeline::Run(Step from, Step to, ScanWork* work, const PipelineProgress& progress) const {
  const WritesDuring writes(work->writes.get());  // The pictures, while the steps go on.
  const bool slow = options_.flatten.solver != FlattenSolver::kGaussNewton;
  auto told = [&](Step step, double done) {
    if (progress) progress(ToString(step), done);
  };
  for (Step step = from; step <= to; step = Next(step)) {
    if (!PerPage(step)) {
      told(step, ScanShare(step));
      work->stages.push_back(RunStep(step, work));
      const StageReport& report = work->stages.back();
      if (!report.status.ok()) {
        const bool named = !work->name.empty() && step != Step::kTriangulate;
        return Status::Error((named ? work->name + ": " : "") + report.status.message());
      }
      continue;
    }
    // The page steps in [from, to], page after page.
    const Step last = std::min(to, Step::kLights);
    MakePages(work);
    const size_t pages = work->pages.size();
    for (size_t k = 0; k < pages; ++k) {
      const double done = 0.7 + 0.25 * k / pages, share = 0.25 / pages;
      for (Step s = step; s <= last; s = Next(s)) {
        if (Skipped(s, *work)) continue;
        told(s, done + PageShare(s, slow) * share);
        const Status ran = RunPage(k, s, s, work);
        if (!ran.ok()) return ran;
      }
    }
    step = last;
  }
  return Status::Ok();
}

Status Pipeline::RunPage(size_t k, Step from, Step to, ScanWork* work) const {
  const WritesDuring writes(work->writes.get());
  MakePages(work);
  if (k >= work->pages.size()) {
    return Status::Error("page " + std::to_string(k) + " of a scan of " +
                         std::to_string(work->pages.size()) + " page(s)");
  }
  for (Step step = std::max(from, Step::kMesh); step <= std::min(to, Step::kLights);
       step = Next(step)) {
    if (Skipped(step, *work)) continue;
    work->stages.push_back(RunPageStep(step, &work->pages[k], work));
    const StageReport& report = work->stages.back();
    if (!report.status.ok()) {
      return Status::Error((work->name.empty() ? "" : work->name + ": ") + report.status.message());
    }
  }
  return Status::Ok();
}

StageReport Pipeline::RunStep(Step step, ScanWork* work) const {
  const PipelineOptions& o = options_;
  switch (step) {
    case Step::kDecode: {
      // A decoder of its own goes when it is done (its running sums and codes, some 40 bytes a
      // camera pixel), before the point map is made.
      if (work->decoder) {
        return DecodeStage(work->scan, work->decoder, o.limits, &work->decoded, work->frames_dir);
      }
      Decoder decoder(o.decode);
      return DecodeStage(work->scan, &decoder, o.limits, &work->decoded, work->frames_dir);
    }
    case Step::kTriangulate: {
      // The light the projector gave each pixel, kept for the albedo; the decoded maps go once
      // the points are made.
      work->amplitude = o.flat_field.empty() ? cv::Mat() : work->decoded.amplitude;
      std::unique_ptr<Triangulator> own;
      const Triangulator* triangulator = work->triangulator;
      if (!triangulator) {
        own = std::make_unique<Triangulator>(work->calibration);
        triangulator = own.get();
      }
      StageReport report = TriangulateStage(work->decoded, *triangulator, o.triangulate, o.limits,
                                            work->results, &work->map);
      if (report.status.ok()) work->decoded = DecodeResult();
      return report;
    }
    case Step::kOutline:
      return OutlineStage(work->map.points, work->scan.texture, work->calibration, work->context,
                          o.outline, o.limits, work->results, work->texture_pictured,
                          &work->outline);
    case Step::kArchive:
      return ArchiveStage(work->scan.texture, work->context.identity, o.camera_icc, work->results);
    default:
      break;
  }
  return Misplaced(step, "page");
}

StageReport Pipeline::RunPageStep(Step step, PageResult* page, ScanWork* work) const {
  switch (step) {
    case Step::kMesh:
      return MeshStage(*work, options_, page);
    case Step::kFlatten:
      return FlattenStage(*work, options_, page);
    case Step::kRestore:
      return RestoreStage(*work, options_, page);
    case Step::kAlbedo:
      return AlbedoStage(*work, options_, page);
    case Step::kReflectance:
      return ReflectanceStage(*work, options_, page);
    case Step::kLights:
      return LightsStage(*work, options_, page);
    default:
      break;
  }
  return Misplaced(step, "scan");
}

}  // namespace vellum
