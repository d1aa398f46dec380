// vellum-flattener: POINT_CLOUD chunks + the scan's texture (page mask) -> the mass-spring
// sheet, flattened (mesh.ply, flat.ply in the scan's results) -> FLAT_MESH chunks.
#include <memory>

#include "cli/options.h"
#include "core/io/scan_io.h"
#include "daemons/common/assembler.h"
#include "daemons/common/daemon.h"
#include "daemons/common/messages.h"
#include "daemons/common/scan_store.h"

namespace vellum::station {
namespace {

class FlattenerNode {
 public:
  FlattenerNode(Node* node, const Flags& flags)
      : node_(node),
        data_(flags.Get("data")),
        mesh_options_(MeshOptionsFromFlags(flags)),
        flatten_options_(FlattenOptionsFromFlags(flags)),
        calibrations_(node, flags.Get("calibration"), flags.Get("data")),
        textures_(node, flags.Get("data")),
        assembler_(
            node, channel::kPointCloud,
            [](const point_cloud_t& m, cv::Mat* points) { return AddChunk(m, points); },
            [this](int64_t id, cv::Mat* points, const point_cloud_t& last) {
              points_ = *points;
              stats_ = last.stats;
              Process(id);
            }) {}

  void Tick() { assembler_.Tick(); }

 private:
  void Fail(int64_t id, const std::string& message) {
    node_->Error("scan " + std::to_string(id) + ": " + message, id);
    node_->SetState("idle");
  }

  void Process(int64_t id) {
    node_->SetState("busy", id, "building the sheet");
    Calibration calibration;
    Status s = calibrations_.Get(id, &calibration);
    if (!s.ok()) return Fail(id, s.message());
    cv::Mat texture;
    s = textures_.Get(id, &texture);
    if (!s.ok()) return Fail(id, s.message());
    if (texture.size() != points_.size()) {
      return Fail(
          id, "texture is " + SizeText(texture.size()) + ", point map " + SizeText(points_.size()));
    }
    int64_t start = NowUtime();
    const cv::Mat page = SegmentPage(texture);
    const Mesh mesh = BuildMesh(points_, page, mesh_options_,
                                [&](const cv::Vec3d& x) { return calibration.camera.Project(x); });
    if (!mesh.status.ok()) return Fail(id, mesh.status.message());
    stats_.page = cv::countNonZero(page);
    stats_.mesh_s = SecondsSince(start);
    node_->SetState("busy", id, "flattening");
    start = NowUtime();
    const FlattenResult flat = Flatten(mesh, flatten_options_);
    if (!flat.status.ok()) return Fail(id, flat.status.message());
    stats_.flatten_s = SecondsSince(start);
    const ScanFolder folder = ScanFolder::For(data_, id);
    s = MakeDirectories(folder.results());
    if (s.ok()) s = WriteSheets(folder.results(), mesh, flat.flat);
    if (!s.ok()) node_->Error("scan " + std::to_string(id) + ": " + s.message(), id);
    mesh_t header{};
    header.solver = ToString(flatten_options_.solver);
    header.iterations = flat.iterations;
    header.mean_strain = flat.mean_strain;
    header.max_strain = flat.max_strain;
    header.folded_quads = flat.folded_quads;
    header.measured_nodes = mesh.measured;
    header.filled_nodes = mesh.filled;
    header.skirt_nodes = mesh.skirt;
    header.springs = static_cast<int32_t>(mesh.springs.size());
    header.quads = static_cast<int32_t>(mesh.quads.size());
    header.stats = stats_;
    std::vector<mesh_t> chunks =
        ToMessages(id, mesh, mesh_options_.bend_springs, flat.flat, header);
    node_->PublishChunks(channel::kFlatMesh, &chunks);
    node_->Count("scans flattened");
    node_->Log("scan " + std::to_string(id) + ": flattened " + SizeText(mesh_options_.grid) +
               " in " + std::to_string(stats_.flatten_s) + " s, strain mean " +
               std::to_string(flat.mean_strain) + " max " + std::to_string(flat.max_strain));
    node_->SetState("idle");
  }

  Node* node_;
  std::string data_;
  MeshOptions mesh_options_;
  FlattenOptions flatten_options_;
  CalibrationBook calibrations_;
  TextureBook textures_;
  Assembler<point_cloud_t, cv::Mat> assembler_;
  // Worker thread only:
  cv::Mat points_;
  scan_stats_t stats_{};
};

}  // namespace
}  // namespace vellum::station

int main(int argc, char** argv) {
  using namespace vellum;
  using namespace vellum::station;
  std::vector<Flags::Spec> specs = Join(DaemonFlagSpecs(true), FlattenFlagSpecs());
  specs.push_back(FallbackCalibrationSpec());
  return DaemonMain(argc, argv, "vellum-flattener",
                    "Builds the mass-spring sheet over each scan's POINT_CLOUD (the page found in\n"
                    "its texture), flattens it, writes mesh.ply and flat.ply to\n"
                    "<data>/scan-<id>/results and publishes FLAT_MESH.",
                    specs, [](const Flags& flags, Node& node) {
                      FlattenerNode flattener(&node, flags);
                      return node.Run(EverySecond([&] { flattener.Tick(); }));
                    });
}
