// vellum-triangulator: CORRESPONDENCE chunks -> the point map (points.ply, depth.png in the
// scan's results) -> POINT_CLOUD chunks.
#include <memory>

#include "cli/options.h"
#include "core/io/scan_io.h"
#include "daemons/common/assembler.h"
#include "daemons/common/daemon.h"
#include "daemons/common/messages.h"
#include "daemons/common/scan_store.h"

namespace vellum::station {
namespace {

// The correspondence map under reassembly.
struct Correspondence {
  DecodeResult decoded;
  cv::Size projector;
};

class TriangulatorNode {
 public:
  TriangulatorNode(Node* node, const Flags& flags)
      : node_(node),
        data_(flags.Get("data")),
        options_(TriangulateOptionsFromFlags(flags)),
        calibrations_(node, flags.Get("calibration"), flags.Get("data")),
        assembler_(
            node, channel::kCorrespondence,
            [](const correspondence_t& m, Correspondence* c) {
              return AddChunk(m, &c->decoded, &c->projector);
            },
            [this](int64_t id, Correspondence* c, const correspondence_t& last) {
              decoded_ = std::move(c->decoded);
              projector_ = c->projector;
              stats_ = last.stats;
              Process(id);
            }) {}

  void Tick() { assembler_.Tick(); }

 private:
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
  Assembler<correspondence_t, Correspondence> assembler_;
  // Worker thread only:
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
  specs.push_back(FallbackCalibrationSpec());
  return DaemonMain(argc, argv, "vellum-triangulator",
                    "Triangulates each scan's CORRESPONDENCE with the scan's CALIBRATION, writes\n"
                    "points.ply and depth.png to <data>/scan-<id>/results and publishes\n"
                    "POINT_CLOUD (in row chunks).",
                    specs, [](const Flags& flags, Node& node) {
                      TriangulatorNode triangulator(&node, flags);
                      return node.Run(EverySecond([&] { triangulator.Tick(); }));
                    });
}
