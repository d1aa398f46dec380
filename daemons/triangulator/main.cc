// vellum-triangulator: CORRESPONDENCE chunks -> the point map (points.ply, depth.png in the
// scan's results) -> POINT_CLOUD chunks.
#include <memory>

#include "cli/options.h"
#include "core/io/scan_io.h"
#include "daemons/common/daemon.h"
#include "daemons/common/messages.h"
#include "daemons/common/scan_store.h"

namespace vellum::station {
namespace {

constexpr double kChunkTimeoutS = 10;  // A product's chunks come within milliseconds.

class TriangulatorNode {
 public:
  TriangulatorNode(Node* node, const Flags& flags)
      : node_(node),
        data_(flags.Get("data")),
        options_(TriangulateOptionsFromFlags(flags)),
        calibrations_(node, flags.Get("calibration")) {
    node->Subscribe<correspondence_t>(channel::kCorrespondence,
                                      [this](const correspondence_t& msg) {
                                        auto copy = std::make_shared<correspondence_t>(msg);
                                        node_->Post([this, copy] { OnChunk(*copy); });
                                      });
  }

 public:
  // On the LCM thread, about once a second: a product whose chunks stopped coming is given up.
  void Tick() {
    node_->Post([this] {
      if (!chunks_.Stale(kChunkTimeoutS)) return;
      node_->Error("scan " + std::to_string(chunks_.scan_id()) + ": CORRESPONDENCE incomplete (" +
                       chunks_.Missing() + ") after " + std::to_string(int(kChunkTimeoutS)) +
                       " s; dropped",
                   chunks_.scan_id());
      chunks_.Reset();
      decoded_ = DecodeResult();
      node_->SetState("idle");
    });
  }

 private:
  void OnChunk(const correspondence_t& msg) {
    if (chunks_.Started() && (chunks_.scan_id() != msg.scan_id || chunks_.Complete())) {
      if (!chunks_.Complete()) {
        node_->Error("scan " + std::to_string(chunks_.scan_id()) + ": CORRESPONDENCE incomplete (" +
                         chunks_.Missing() + ") when scan " + std::to_string(msg.scan_id) +
                         " began; dropped",
                     chunks_.scan_id());
      }
      chunks_.Reset();
      decoded_ = DecodeResult();
    }
    Status s = chunks_.Add(msg.scan_id, msg.chunk_index, msg.chunk_count);
    if (s.ok()) s = AddChunk(msg, &decoded_, &projector_);
    if (!s.ok()) {
      node_->Error("scan " + std::to_string(msg.scan_id) + ": CORRESPONDENCE: " + s.message(),
                   msg.scan_id);
      return;
    }
    stats_ = msg.stats;  // Every chunk carries the scan's figures so far.
    if (chunks_.Complete()) Process(msg.scan_id);
  }

  void Process(int64_t id) {
    node_->SetState("busy", id, "triangulating");
    Calibration calibration;
    Status s = calibrations_.Get(id, &calibration);
    if (s.ok() && (calibration.camera.size != decoded_.projector_x.size() ||
                   calibration.projector.size != projector_)) {
      s = Status::Error("scan " + std::to_string(id) + ": the calibration is for a " +
                        SizeText(calibration.camera.size) + " camera and " +
                        SizeText(calibration.projector.size) + " projector, the scan has " +
                        SizeText(decoded_.projector_x.size()) + " and " + SizeText(projector_));
    }
    if (!s.ok()) {
      node_->Error(s.message(), id);
      node_->SetState("idle");
      return;
    }
    const int64_t start = NowUtime();
    decoded_.status = Status::Ok();
    if (!triangulator_ || !SameCalibration(triangulator_->calibration(), calibration)) {
      triangulator_ = std::make_unique<Triangulator>(calibration);
    }
    triangulator_->Triangulate(decoded_, options_, &map_);
    if (!map_.status.ok()) {
      node_->Error("scan " + std::to_string(id) + ": " + map_.status.message(), id);
      node_->SetState("idle");
      return;
    }
    const double seconds = SecondsSince(start);
    const ScanFolder folder = ScanFolder::For(data_, id);
    double zmin = 0, zmax = 0;
    s = MakeDirectories(folder.results());
    if (s.ok()) s = WritePointProducts(folder.results(), map_.points, &zmin, &zmax);
    if (!s.ok()) node_->Error("scan " + std::to_string(id) + ": " + s.message(), id);
    AddPointStats(map_, seconds, zmin, zmax, &stats_);
    std::vector<point_cloud_t> chunks = ToMessages(id, map_.points, stats_);
    node_->PublishChunks(channel::kPointCloud, &chunks);
    node_->Count("scans triangulated");
    node_->Log("scan " + std::to_string(id) + ": " + std::to_string(map_.valid) + " points in " +
               std::to_string(seconds) + " s");
    node_->SetState("idle");
  }

  static bool SameCalibration(const Calibration& a, const Calibration& b) {
    auto same = [](const CameraModel& x, const CameraModel& y) {
      return x.size == y.size && x.matrix == y.matrix && x.distortion == y.distortion &&
             x.rotation == y.rotation && x.translation == y.translation;
    };
    return same(a.camera, b.camera) && same(a.projector, b.projector);
  }

  Node* node_;
  std::string data_;
  TriangulateOptions options_;
  CalibrationBook calibrations_;
  // Worker thread only:
  ChunkSet chunks_;
  DecodeResult decoded_;
  cv::Size projector_;
  scan_stats_t stats_{};
  std::unique_ptr<Triangulator> triangulator_;  // Its rays, kept while the calibration holds.
  PointMap map_;
};

}  // namespace
}  // namespace vellum::station

int main(int argc, char** argv) {
  using namespace vellum;
  using namespace vellum::station;
  std::vector<Flags::Spec> specs = Join(DaemonFlagSpecs(true), TriangulateFlagSpecs());
  specs.push_back({"calibration", "FILE",
                   "calibration used when a scan comes without a CALIBRATION message", ""});
  return DaemonMain(argc, argv, "vellum-triangulator",
                    "Triangulates each scan's CORRESPONDENCE with the scan's CALIBRATION, writes\n"
                    "points.ply and depth.png to <data>/scan-<id>/results and publishes\n"
                    "POINT_CLOUD (in row chunks).",
                    specs, [](const Flags& flags, Node& node) {
                      TriangulatorNode triangulator(&node, flags);
                      return node.Run(EverySecond([&] { triangulator.Tick(); }));
                    });
}
