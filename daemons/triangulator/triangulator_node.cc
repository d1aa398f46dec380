#include "daemons/triangulator/triangulator_node.h"

#include <filesystem>
#include <memory>
#include <mutex>
#include <utility>
#include <vector>

#include "core/common/text.h"
#include "io/manifest.h"
#include "io/scan_io.h"
#include "pipeline/pipeline.h"
#include "station/scan_store.h"
#include "station/supervisor.h"

namespace vellum::station {
namespace {

bool SameCalibration(const Calibration& a, const Calibration& b) {
  auto same = [](const CameraModel& x, const CameraModel& y) {
    return x.size == y.size && x.matrix == y.matrix && x.distortion == y.distortion &&
           x.rotation == y.rotation && x.translation == y.translation;
  };
  return same(a.camera, b.camera) && same(a.projector, b.projector);
}

}  // namespace

bool TriangulatorNodeOptions::Check(std::string* why) const {
  if (data_dir.empty()) {
    *why = "triangulator: data_dir must be named";
    return false;
  }
  return triangulate.Check(why) && (!fallback_calibration || fallback_calibration->Check(why));
}

TriangulatorNode::TriangulatorNode(Node* node, const TriangulatorNodeOptions& options)
    : node_(node),
      options_(options),
      calibrations_(node, options.fallback_calibration ? &*options.fallback_calibration : nullptr,
                    options.data_dir),
      assembler_(
          node, channel::kCorrespondence,
          [](const correspondence_t& m, Correspondence* c) {
            return AddChunk(m, &c->decoded, &c->projector);
          },
          [this](int64_t id, Correspondence* c, const correspondence_t& last) {
            std::swap(product_, *c);
            Process(id, last);
          }) {
  assembler_.AwaitAnnounced(channel::kCorrespondence);
  // The rays of a scan's calibration are made while it is captured, not after its last frame.
  calibrations_.OnTaken([this](int64_t, const Calibration& calibration) {
    node_->Post([this, calibration] { Prepare(calibration); }, "preparing a calibration's rays");
  });
}

void TriangulatorNode::Prepare(const Calibration& calibration) {
  if (!triangulator_ || !SameCalibration(triangulator_->calibration(), calibration)) {
    triangulator_ = std::make_unique<Triangulator>(calibration);
    node_->Count("calibrations' rays made");
  }
}

void TriangulatorNode::Process(int64_t id, const correspondence_t& last) {
  node_->SetState("busy", id, "triangulating");
  std::vector<StageReport> stages;
  Status s = FromMessages(last.stages, &stages);
  if (!s.ok()) return node_->FailScan(id, "CORRESPONDENCE: " + s.message());
  Calibration calibration;
  s = calibrations_.Get(id, &calibration);
  if (!s.ok()) return node_->FailScan(id, s.message());
  ScanContext context;
  s = FromMessage(last.context, &context);
  if (!s.ok()) return node_->FailScan(id, "CORRESPONDENCE: " + s.message());
  // The points are measured with this calibration: the context carries its checksum on.
  context.MeasuredWith(calibration);
  const DecodeResult& decoded = product_.decoded;
  if (calibration.camera.size != decoded.projector_x.size() ||
      calibration.projector.size != product_.projector) {
    return node_->FailScan(
        id, "the calibration is for a " + SizeText(calibration.camera.size) + " camera and " +
                SizeText(calibration.projector.size) + " projector, the scan has " +
                SizeText(decoded.projector_x.size()) + " and " + SizeText(product_.projector));
  }
  Prepare(calibration);
  const ScanFolder folder = ScanFolder::For(options_.data_dir, id);
  const std::string results = folder.results();
  s = MakeDirectories(results);
  if (!s.ok()) return node_->FailScan(id, s.message());
  // The pipeline's triangulate step, with this node's triangulator (the calibration's rays).
  PipelineOptions options;
  options.triangulate = options_.triangulate;
  options.limits = options_.limits;
  ScanWork work;
  work.calibration = calibration;
  work.context = context;
  work.results = results;
  work.triangulator = triangulator_.get();
  work.stages = std::move(stages);
  // The files it writes, noted as each is written, to be hashed once the points are handed on.
  auto written = std::make_shared<std::pair<std::mutex, std::vector<std::string>>>();
  work.writes->AfterEachFile([written](const std::string& path) {
    const std::lock_guard<std::mutex> lock(written->first);
    written->second.push_back(path);
  });
  // With the decoder's count of the lit pixels, which the points are judged against, and its
  // amplitude, which passes on for the albedo.
  const cv::Mat amplitude = decoded.amplitude;
  std::swap(work.decoded, product_.decoded);
  std::swap(work.map, map_);
  s = Pipeline(options).Run(Step::kTriangulate, Step::kTriangulate, &work);
  std::swap(work.map, map_);
  if (!s.ok()) return node_->FailScan(id, s.message());
  // Each chunk made as it is sent, into one message. Its files (points.ply, the pictures) are
  // written while the points travel, and are on disk before their last chunk goes: before the
  // next stage can start.
  s = node_->PublishChunks(channel::kPointCloud,
                           PointCloudChunks(id, map_.points, amplitude, context, work.stages),
                           [&work] { return work.writes->Wait(); });
  if (!s.ok()) return node_->FailScan(id, s.message());
  AnnounceHandedOn(node_, id, channel::kPointCloud, "scans triangulated");
  // Its files hashed while the flattener finds the leaf, long before the restorer writes the
  // scan's manifest, which then need not read them again (points.ply is most of a scan's
  // results). One that cannot be hashed now, or a record not saved, the manifest hashes itself.
  HashRecord hashes(folder.root, RecordedHashesName("triangulator"));
  for (const std::string& path : written->second) {
    static_cast<void>(hashes.Add(std::filesystem::path(path).lexically_relative(folder.root)));
  }
  static_cast<void>(hashes.Save());
  node_->Log("scan " + std::to_string(id) + ": " + std::to_string(map_.valid) + " points in " +
             std::to_string(work.stages.back().seconds) + " s");
  node_->SetState("idle");
}

}  // namespace vellum::station
