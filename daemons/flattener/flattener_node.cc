#include "daemons/flattener/flattener_node.h"

#include "core/common/text.h"
#include "io/scan_io.h"
#include "pipeline/pipeline.h"
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
  // The texture's picture for the report needs nothing but the texture: written as it comes,
  // while the patterns are still projected, on a thread of its own.
  textures_.OnTaken([this](int64_t id, const cv::Mat& texture) {
    pictured_[id] = std::async(std::launch::async | std::launch::deferred,
                               [results = ScanFolder::For(options_.data_dir, id).results(),
                                texture] { return WriteTexturePicture(results, texture); })
                        .share();
    while (pictured_.size() > 8) pictured_.erase(pictured_.begin());
  });
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
  // The pipeline's outline step, then each page's mesh and flatten steps.
  ScanWork work;
  s = FromMessage(last.context, &work.context);
  if (!s.ok()) return node_->FailScan(id, "POINT_CLOUD: " + s.message());
  work.scan.texture = texture;
  work.calibration = calibration;
  work.results = results;
  work.stages = std::move(stages);
  work.map.points = points_;
  const auto pictured = pictured_.find(id);
  if (pictured != pictured_.end()) {
    work.texture_pictured = pictured->second.get().ok();  // Else written with the outline.
    pictured_.erase(pictured);
  }
  const Pipeline pipeline(o);
  s = pipeline.Run(Step::kOutline, Step::kOutline, &work);
  if (!s.ok()) return node_->FailScan(id, s.message());
  const size_t common = work.stages.size();  // Every page's sheet carries the scan's reports.
  const size_t pages = work.outline.pages.size();
  for (size_t k = 0; k < pages; ++k) {
    const size_t before = work.stages.size();
    const std::string& name = PageName(work.outline, k);
    const std::string of = name.empty() ? "" : " of the " + name + " page";
    node_->SetState("busy", id, "building the sheet" + of);
    s = pipeline.RunPage(k, Step::kMesh, Step::kMesh, &work);
    if (s.ok()) {
      node_->SetState("busy", id, "flattening the sheet" + of);
      s = pipeline.RunPage(k, Step::kFlatten, Step::kFlatten, &work);
    }
    if (s.ok()) s = work.writes->Wait();  // Its files on disk before the sheet goes on.
    if (!s.ok()) return node_->FailScan(id, s.message());
    const PageResult& page = work.pages[k];
    SheetPage sheet;
    sheet.name = page.name;
    sheet.index = static_cast<int>(k);
    sheet.count = static_cast<int>(pages);
    sheet.mask = page.mask;
    std::vector<StageReport> carried(work.stages.begin(), work.stages.begin() + common);
    carried.insert(carried.end(), work.stages.begin() + before, work.stages.end());
    std::vector<mesh_t> chunks =
        ToMessages(id, page.mesh, o.mesh.bend_springs, page.flat, work.context, carried, sheet);
    node_->PublishChunks(channel::kFlatMesh, &chunks);
    const std::string what = name.empty() ? "the leaf" : "the " + name + " page";
    node_->Log("scan " + std::to_string(id) + ": flattened " + what + " on a " +
               SizeText(cv::Size(page.mesh.cols, page.mesh.rows)) + " sheet in " +
               std::to_string(carried.back().seconds) + " s, strain mean " +
               std::to_string(page.flat.mean_strain) + " max " +
               std::to_string(page.flat.max_strain));
  }
  AnnounceHandedOn(node_, id, channel::kFlatMesh, "scans flattened");
  node_->SetState("idle");
}

}  // namespace vellum::station
