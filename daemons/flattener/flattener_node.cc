#include "daemons/flattener/flattener_node.h"

#include "core/common/text.h"
#include "io/scan_io.h"
#include "pipeline/stages.h"
#include "station/scan_store.h"
#include "station/supervisor.h"

namespace vellum::station {

bool FlattenerNodeOptions::Check(std::string* why) const {
  if (data_dir.empty()) {
    *why = "flattener: data_dir must be named";
    return false;
  }
  return pipeline.Check(why) && (!fallback_calibration || fallback_calibration->Check(why));
}

FlattenerNode::FlattenerNode(Node* node, const FlattenerNodeOptions& options)
    : node_(node),
      options_(options),
      calibrations_(node, options.fallback_calibration ? &*options.fallback_calibration : nullptr,
                    options.data_dir),
      textures_(node, options.data_dir),
      assembler_(
          node, channel::kPointCloud,
          [](const point_cloud_t& m, cv::Mat* points) { return AddChunk(m, points); },
          [this](int64_t id, cv::Mat* points, const point_cloud_t& last) {
            points_ = *points;
            Process(id, last);
          }) {
  assembler_.AwaitAnnounced(channel::kPointCloud);
}

void FlattenerNode::Process(int64_t id, const point_cloud_t& last) {
  node_->SetState("busy", id, "finding the leaf");
  std::vector<StageReport> stages;
  Status s = FromMessages(last.stages, &stages);
  if (!s.ok()) return node_->FailScan(id, "POINT_CLOUD: " + s.message());
  Calibration calibration;
  s = calibrations_.Get(id, &calibration);
  if (!s.ok()) return node_->FailScan(id, s.message());
  cv::Mat texture;
  s = textures_.Get(id, &texture);
  if (!s.ok()) return node_->FailScan(id, s.message());
  const PipelineOptions& o = options_.pipeline;
  const std::string results = ScanFolder::For(options_.data_dir, id).results();
  s = MakeDirectories(results);
  if (!s.ok()) return node_->FailScan(id, s.message());
  ScanContext context;
  s = FromMessage(last.context, &context);
  if (!s.ok()) return node_->FailScan(id, "POINT_CLOUD: " + s.message());
  Outline outline;
  stages.push_back(
      OutlineStage(points_, texture, calibration, context, o.outline, o.limits, results, &outline));
  if (!stages.back().status.ok()) return node_->FailScan(id, stages.back().status.message());
  const size_t common = stages.size();  // Every page's sheet carries the scan's reports.
  for (size_t k = 0; k < outline.pages.size(); ++k) {
    SheetPage page;
    page.name = PageName(outline, k);
    page.index = static_cast<int>(k);
    page.count = static_cast<int>(outline.pages.size());
    page.mask = outline.pages[k];
    const std::string of = page.name.empty() ? "" : " of the " + page.name + " page";
    node_->SetState("busy", id, "building the sheet" + of);
    stages.resize(common);
    Mesh mesh;
    stages.push_back(MeshStage(points_, page.mask, calibration.camera, o, page.name, &mesh));
    if (!stages.back().status.ok()) return node_->FailScan(id, stages.back().status.message());
    node_->SetState("busy", id, "flattening the sheet" + of);
    FlattenResult flat;
    stages.push_back(FlattenStage(mesh, o.flatten, o.limits, results, page.name, &flat));
    if (!stages.back().status.ok()) return node_->FailScan(id, stages.back().status.message());
    std::vector<mesh_t> chunks =
        ToMessages(id, mesh, o.mesh.bend_springs, flat, context, stages, page);
    node_->PublishChunks(channel::kFlatMesh, &chunks);
    const std::string what = page.name.empty() ? "the leaf" : "the " + page.name + " page";
    node_->Log("scan " + std::to_string(id) + ": flattened " + what + " on a " +
               SizeText(cv::Size(mesh.cols, mesh.rows)) + " sheet in " +
               std::to_string(stages.back().seconds) + " s, strain mean " +
               std::to_string(flat.mean_strain) + " max " + std::to_string(flat.max_strain));
  }
  node_->Count("scans flattened");
  AnnounceHandedOn(node_, id, channel::kFlatMesh);
  node_->SetState("idle");
}

}  // namespace vellum::station
