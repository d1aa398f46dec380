#include "pipeline/stages.h"

#include <chrono>
#include <filesystem>
#include <opencv2/imgproc.hpp>

#include "core/common/text.h"
#include "core/report/pictures.h"
#include "io/products.h"
#include "io/scan_io.h"

namespace vellum {
namespace fs = std::filesystem;
namespace {

// Starts the clock of a stage's report; Finish sets the status and the wall time.
class Stage {
 public:
  explicit Stage(const char* name) : start_(std::chrono::steady_clock::now()) {
    report_.stage = name;
  }
  StageReport& report() { return report_; }
  StageReport Finish(const Status& status) {
    report_.status = status;
    report_.seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
    return report_;
  }
  // Writes one of the stage's files; records it in the outputs when written.
  Status Output(const std::string& name, const Status& written) {
    if (written.ok()) report_.outputs.push_back(name);
    return written;
  }
  // A picture for report.html in <results>/report/: at most 1400 pixels across, 8-bit.
  Status Picture(const std::string& results, const std::string& name, const cv::Mat& image) {
    Status s = MakeDirectories((fs::path(results) / "report").string());
    if (!s.ok()) return s;
    cv::Mat out = image;
    if (out.depth() != CV_8U) out.convertTo(out, CV_8U, 1.0 / 257);
    if (out.cols > 1400) {
      const double scale = 1400.0 / out.cols;
      cv::resize(out, out, cv::Size(), scale, scale, cv::INTER_AREA);
    }
    const std::string file = "report/" + name;
    return Output(file, WriteImage((fs::path(results) / file).string(), out));
  }

 private:
  std::chrono::steady_clock::time_point start_;
  StageReport report_;
};

}  // namespace

bool PipelineOptions::Check(std::string* why) const {
  return decode.Check(why) && triangulate.Check(why) && mesh.Check(why) && flatten.Check(why) &&
         restore.Check(why);
}

StageReport DecodeStage(const Scan& scan, Decoder* decoder, DecodeResult* decoded) {
  Stage stage("decode");
  StageReport& r = stage.report();
  const DecodeOptions& o = decoder->options();
  r.Text("options", "decoder", o.use_phase ? "phase" : "gray");
  r.Number("options", "smooth_radius_px", o.smooth_radius_px);
  r.Number("options", "min_contrast_dn", o.min_contrast_dn);
  r.Number("options", "min_modulation_dn", o.min_modulation_dn);
  r.Number("options", "max_unwrap_error", o.max_unwrap_error);
  r.Text("sizes", "camera", SizeText(scan.camera_size));
  r.Text("sizes", "projector", SizeText(scan.sequence.projector_size));
  r.Number("sizes", "patterns", static_cast<double>(scan.sequence.patterns.size()));
  decoder->Decode(scan.sequence, scan.frames, decoded);
  if (!decoded->status.ok()) return stage.Finish(decoded->status);
  const DecodeStats& d = decoded->stats;
  r.Number("pixels", "camera", d.pixels);
  r.Number("pixels", "lit", d.lit);
  r.Number("pixels", "decoded", d.valid);
  r.Number("pixels", "rejected_saturated", d.rejected_saturated);
  r.Number("pixels", "rejected_gray_bits", d.rejected_bits);
  r.Number("pixels", "rejected_modulation", d.rejected_modulation);
  r.Number("pixels", "rejected_unwrap", d.rejected_unwrap);
  r.Number("pixels", "fit_fallbacks", d.fit_fallbacks);
  return stage.Finish(Status::Ok());
}

StageReport TriangulateStage(const DecodeResult& decoded, const Triangulator& triangulator,
                             const TriangulateOptions& options, const std::string& results,
                             PointMap* map) {
  Stage stage("triangulate");
  StageReport& r = stage.report();
  r.Number("options", "max_epipolar_error_px", options.max_epipolar_error_px);
  triangulator.Triangulate(decoded, options, map);
  if (!map->status.ok()) return stage.Finish(map->status);
  r.Number("pixels", "valid", map->valid);
  r.Number("pixels", "rejected_epipolar", map->rejected_epipolar);
  r.Number("pixels", "rejected_volume", map->rejected_volume);
  double z_min = 0, z_max = 0;
  Status s = WritePointProducts(results, map->points, &z_min, &z_max);
  if (!s.ok()) return stage.Finish(s);
  r.outputs.push_back("points.ply");
  r.outputs.push_back("depth.png");
  r.Number("height_mm", "min", z_min);
  r.Number("height_mm", "max", z_max);
  s = stage.Picture(results, "valid.png", ValidMask(map->points));
  double bar_min = 0, bar_max = 0;
  if (s.ok()) {
    s = stage.Picture(results, "depth.png", DepthWithColourBar(map->points, &bar_min, &bar_max));
  }
  return stage.Finish(s);
}

StageReport MeshStage(const cv::Mat& points, const cv::Mat& texture, const CameraModel& camera,
                      const MeshOptions& options, Mesh* mesh) {
  Stage stage("mesh");
  StageReport& r = stage.report();
  r.Text("options", "grid", SizeText(options.grid));
  if (texture.size() != points.size()) {
    return stage.Finish(Status::Error("the texture is " + SizeText(texture.size()) +
                                      ", the point map " + SizeText(points.size())));
  }
  const cv::Mat page = SegmentPage(texture);
  *mesh = BuildMesh(points, page, options, [&](const cv::Vec3d& x) { return camera.Project(x); });
  if (!mesh->status.ok()) return stage.Finish(mesh->status);
  r.Number("pixels", "page", cv::countNonZero(page));
  r.Number("sheet", "measured_nodes", mesh->measured);
  r.Number("sheet", "filled_nodes", mesh->filled);
  r.Number("sheet", "skirt_nodes", mesh->skirt);
  r.Number("sheet", "springs", static_cast<double>(mesh->springs.size()));
  r.Number("sheet", "quads", static_cast<double>(mesh->quads.size()));
  return stage.Finish(Status::Ok());
}

StageReport FlattenStage(const Mesh& mesh, const FlattenOptions& options,
                         const std::string& results, FlattenResult* flat) {
  Stage stage("flatten");
  StageReport& r = stage.report();
  r.Text("options", "solver", ToString(options.solver));
  *flat = Flatten(mesh, options);
  if (!flat->status.ok()) return stage.Finish(flat->status);
  r.Text("flattening", "solver", ToString(options.solver));
  r.Number("flattening", "iterations", flat->iterations);
  r.Number("flattening", "mean_strain", flat->mean_strain);
  r.Number("flattening", "max_strain", flat->max_strain);
  r.Number("flattening", "folded_quads", flat->folded_quads);
  const Status s = WriteSheets(results, mesh, flat->flat);
  if (s.ok()) r.outputs = {"mesh.ply", "flat.ply"};
  return stage.Finish(s);
}

StageReport RestoreStage(const cv::Mat& texture, const Mesh& mesh,
                         const std::vector<cv::Point2d>& flat, const CameraModel& camera,
                         const RestoreOptions& options, const std::string& results,
                         RestoreResult* restored) {
  Stage stage("restore");
  StageReport& r = stage.report();
  r.Text("options", "view", ToString(options.view));
  *restored = Restore(texture, mesh, flat, camera, options);
  if (!restored->status.ok()) return stage.Finish(restored->status);
  r.Number("options", "dpi", restored->dpi);
  r.Number("restored", "width", restored->image.cols);
  r.Number("restored", "height", restored->image.rows);
  Status s = WriteRestored(results, *restored);
  if (!s.ok()) return stage.Finish(s);
  r.outputs.push_back("restored.tif");
  r.outputs.push_back("restored.json");
  s = stage.Picture(results, "texture.png", texture);
  if (s.ok()) s = stage.Picture(results, "grid.png", GridOverPage(mesh, flat, *restored, camera));
  if (s.ok()) {
    s = stage.Picture(results, "strain.png", StrainPicture(mesh, flat, *restored, camera));
  }
  if (s.ok()) {
    s = stage.Picture(results, "before_after.png",
                      BeforeAfter(texture, mesh, flat, *restored, camera));
  }
  return stage.Finish(s);
}

}  // namespace vellum
