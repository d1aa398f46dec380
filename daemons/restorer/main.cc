// vellum-restorer: FLAT_MESH chunks + the scan's texture -> the restored page (restored.tif,
// restored.json, report.json in the scan's results) -> RESTORED with a preview.
#include <memory>
#include <opencv2/imgproc.hpp>

#include "cli/options.h"
#include "core/io/html_report.h"
#include "core/io/scan_io.h"
#include "daemons/common/assembler.h"
#include "daemons/common/daemon.h"
#include "daemons/common/messages.h"
#include "daemons/common/scan_store.h"
#include "vellum/restored_t.hpp"

namespace vellum::station {
namespace {

constexpr double kPreviewPixels = 1 << 20;

// The flattened sheet under reassembly.
struct Sheet {
  Mesh mesh;
  std::vector<cv::Point2d> flat;
};

class RestorerNode {
 public:
  RestorerNode(Node* node, const Flags& flags)
      : node_(node),
        data_(flags.Get("data")),
        options_(RestoreOptionsFromFlags(flags)),
        calibrations_(node, flags.Get("calibration"), flags.Get("data")),
        textures_(node, flags.Get("data")),
        sheets_(
            node, channel::kFlatMesh,
            [](const mesh_t& m, Sheet* sheet) { return AddChunk(m, &sheet->mesh, &sheet->flat); },
            [this](int64_t id, Sheet* sheet, const mesh_t& last) {
              mesh_ = std::move(sheet->mesh);
              flat_ = std::move(sheet->flat);
              header_ = last;
              Process(id);
            }),
        clouds_(
            node, channel::kPointCloud,
            [](const point_cloud_t& m, cv::Mat* points) { return AddChunk(m, points); },
            [this](int64_t id, cv::Mat* points, const point_cloud_t&) {
              points_id_ = id;  // For the report's depth map and valid-pixel mask.
              points_ = *points;
            }) {}

  void Tick() {
    sheets_.Tick();
    clouds_.Tick();
  }

 private:
  void Fail(int64_t id, const std::string& message) {
    node_->Error("scan " + std::to_string(id) + ": " + message, id);
    node_->SetState("idle");
  }

  void Process(int64_t id) {
    node_->SetState("busy", id, "restoring");
    Calibration calibration;
    Status s = calibrations_.Get(id, &calibration);
    if (!s.ok()) return Fail(id, s.message());
    cv::Mat texture;
    s = textures_.Get(id, &texture);
    if (!s.ok()) return Fail(id, s.message());
    ConnectSheet(
        header_.bend_springs, [&](const cv::Vec3d& x) { return calibration.camera.Project(x); },
        &mesh_);
    if (!mesh_.status.ok()) return Fail(id, "FLAT_MESH: " + mesh_.status.message());
    const int64_t start = NowUtime();
    const RestoreResult restored = Restore(texture, mesh_, flat_, calibration.camera, options_);
    if (!restored.status.ok()) return Fail(id, restored.status.message());
    scan_stats_t stats = header_.stats;
    stats.restore_s = SecondsSince(start);

    const ScanFolder folder = ScanFolder::For(data_, id);
    s = MakeDirectories(folder.results());
    if (s.ok()) s = WriteRestored(folder.results(), restored);
    const ProcessReport report = Report(id, stats, restored);
    if (s.ok()) s = WriteReport(folder.results(), report);
    if (s.ok()) {
      HtmlReportInput html;
      html.title = "scan " + std::to_string(id);
      html.figures = &report;
      html.texture = texture;
      if (points_id_ == id) html.points = points_;
      html.mesh = &mesh_;
      html.flat = &flat_;
      html.restored = &restored;
      html.camera = calibration.camera;
      s = WriteHtmlReport(folder.results(), html);
    }
    if (!s.ok()) return Fail(id, s.message());

    restored_t out{};
    out.scan_id = id;
    out.view = ToString(restored.view);
    out.dpi = restored.view == RestoreView::kOrthographic ? restored.dpi : 0;
    out.width = restored.image.cols;
    out.height = restored.image.rows;
    for (int k = 0; k < 6; ++k) out.pixel_from_flat[k] = restored.pixel_from_flat.val[k];
    out.path = folder.results() + "/restored.tif";
    out.results = folder.results();
    cv::Mat preview = restored.image;
    if (preview.depth() != CV_8U) preview.convertTo(preview, CV_8U, 1.0 / 257);
    const double scale = std::min(1.0, std::sqrt(kPreviewPixels / preview.total()));
    if (scale < 1) cv::resize(preview, preview, cv::Size(), scale, scale, cv::INTER_AREA);
    ToMessage(preview, &out.preview);
    out.preview.utime = NowUtime();
    out.preview.scan_id = id;
    out.preview.pattern_index = -1;
    node_->Publish(channel::kRestored, &out);
    node_->Count("scans restored");
    node_->Log("scan " + std::to_string(id) + ": restored " + SizeText(restored.image.size()) +
               " in " + std::to_string(stats.restore_s) + " s -> " + out.path);
    node_->SetState("idle", id, "restored " + out.path);
  }

  ProcessReport Report(int64_t id, const scan_stats_t& stats, const RestoreResult& restored) {
    ProcessReport r;
    const ScanFolder folder = ScanFolder::For(data_, id);
    r.scan = folder.raw();
    r.calibration = folder.calibration();
    r.text_options = {{"grid", std::to_string(mesh_.cols) + "x" + std::to_string(mesh_.rows)},
                      {"solver", header_.solver},
                      {"view", ToString(restored.view)}};
    r.number_options = {{"dpi", restored.dpi}};
    FillReport(stats, &r);
    r.measured_nodes = header_.measured_nodes;
    r.filled_nodes = header_.filled_nodes;
    r.skirt_nodes = header_.skirt_nodes;
    r.springs = header_.springs;
    r.quads = header_.quads;
    r.solver = header_.solver;
    r.iterations = header_.iterations;
    r.mean_strain = header_.mean_strain;
    r.max_strain = header_.max_strain;
    r.folded_quads = header_.folded_quads;
    return r;
  }

  Node* node_;
  std::string data_;
  RestoreOptions options_;
  CalibrationBook calibrations_;
  TextureBook textures_;
  Assembler<mesh_t, Sheet> sheets_;
  Assembler<point_cloud_t, cv::Mat> clouds_;
  // Worker thread only:
  int64_t points_id_ = 0;
  cv::Mat points_;
  Mesh mesh_;
  std::vector<cv::Point2d> flat_;
  mesh_t header_;
};

}  // namespace
}  // namespace vellum::station

int main(int argc, char** argv) {
  using namespace vellum;
  using namespace vellum::station;
  std::vector<Flags::Spec> specs = Join(DaemonFlagSpecs(true), RestoreFlagSpecs());
  specs.push_back(FallbackCalibrationSpec());
  return DaemonMain(argc, argv, "vellum-restorer",
                    "Restores each scan's texture through its FLAT_MESH: writes restored.tif,\n"
                    "restored.json and report.json to <data>/scan-<id>/results and publishes\n"
                    "RESTORED (the results folder and a preview of at most 1 Mpixel).",
                    specs, [](const Flags& flags, Node& node) {
                      RestorerNode restorer(&node, flags);
                      return node.Run(EverySecond([&] { restorer.Tick(); }));
                    });
}
