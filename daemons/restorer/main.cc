// vellum-restorer: FLAT_MESH chunks + the scan's texture -> the restored page (restored.tif,
// restored.json, report.json in the scan's results) -> RESTORED with a preview.
#include <memory>
#include <opencv2/imgproc.hpp>

#include "cli/options.h"
#include "core/io/scan_io.h"
#include "daemons/common/daemon.h"
#include "daemons/common/messages.h"
#include "daemons/common/scan_store.h"
#include "vellum/restored_t.hpp"

namespace vellum::station {
namespace {

constexpr double kChunkTimeoutS = 10;  // A product's chunks come within milliseconds.

constexpr double kPreviewPixels = 1 << 20;

class RestorerNode {
 public:
  RestorerNode(Node* node, const Flags& flags)
      : node_(node),
        data_(flags.Get("data")),
        options_(RestoreOptionsFromFlags(flags)),
        calibrations_(node, flags.Get("calibration")),
        textures_(node) {
    node->Subscribe<mesh_t>(channel::kFlatMesh, [this](const mesh_t& msg) {
      auto copy = std::make_shared<mesh_t>(msg);
      node_->Post([this, copy] { OnChunk(*copy); });
    });
  }

 public:
  // On the LCM thread, about once a second: a product whose chunks stopped coming is given up.
  void Tick() {
    node_->Post([this] {
      if (!chunks_.Stale(kChunkTimeoutS)) return;
      node_->Error("scan " + std::to_string(chunks_.scan_id()) + ": FLAT_MESH incomplete (" +
                       chunks_.Missing() + ") after " + std::to_string(int(kChunkTimeoutS)) +
                       " s; dropped",
                   chunks_.scan_id());
      chunks_.Reset();
      mesh_ = Mesh();
      flat_.clear();
      node_->SetState("idle");
    });
  }

 private:
  void OnChunk(const mesh_t& msg) {
    if (chunks_.Started() && (chunks_.scan_id() != msg.scan_id || chunks_.Complete())) {
      if (!chunks_.Complete()) {
        node_->Error("scan " + std::to_string(chunks_.scan_id()) + ": FLAT_MESH incomplete (" +
                         chunks_.Missing() + ") when scan " + std::to_string(msg.scan_id) +
                         " began; dropped",
                     chunks_.scan_id());
      }
      chunks_.Reset();
      mesh_ = Mesh();
      flat_.clear();
    }
    Status s = chunks_.Add(msg.scan_id, msg.chunk_index, msg.chunk_count);
    if (s.ok()) s = AddChunk(msg, &mesh_, &flat_);
    if (!s.ok()) {
      node_->Error("scan " + std::to_string(msg.scan_id) + ": FLAT_MESH: " + s.message(),
                   msg.scan_id);
      return;
    }
    header_ = msg;
    if (chunks_.Complete()) Process(msg.scan_id);
  }

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
    if (s.ok()) s = WriteReport(folder.results(), Report(id, stats, restored));
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
  // Worker thread only:
  ChunkSet chunks_;
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
  specs.push_back({"calibration", "FILE",
                   "calibration used when a scan comes without a CALIBRATION message", ""});
  return DaemonMain(argc, argv, "vellum-restorer",
                    "Restores each scan's texture through its FLAT_MESH: writes restored.tif,\n"
                    "restored.json and report.json to <data>/scan-<id>/results and publishes\n"
                    "RESTORED (the results folder and a preview of at most 1 Mpixel).",
                    specs, [](const Flags& flags, Node& node) {
                      RestorerNode restorer(&node, flags);
                      return node.Run(EverySecond([&] { restorer.Tick(); }));
                    });
}
