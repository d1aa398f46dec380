#include "daemons/restorer/restorer_node.h"

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "core/common/text.h"
#include "io/manifest.h"
#include "io/scan_io.h"
#include "pipeline/qc.h"
#include "pipeline/report.h"
#include "pipeline/stages.h"
#include "station/contact_sheet.h"
#include "station/scan_store.h"
#include "station/supervisor.h"
#include "vellum/restored_t.hpp"

namespace vellum::station {

bool RestorerNodeOptions::Check(std::string* why) const {
  if (data_dir.empty() || !(preview_pixels >= 1)) {
    *why = "restorer: data_dir must be named and preview_pixels >= 1";
    return false;
  }
  return pipeline.Check(why) && (!fallback_calibration || fallback_calibration->Check(why));
}

RestorerNode::RestorerNode(Node* node, const RestorerNodeOptions& options)
    : node_(node),
      options_(options),
      calibrations_(node, options.fallback_calibration ? &*options.fallback_calibration : nullptr,
                    options.data_dir),
      textures_(node, options.data_dir, /*lights=*/true),
      sheets_(
          node, channel::kFlatMesh,
          [](const mesh_t& m, Sheet* sheet) {
            return AddChunk(m, &sheet->mesh, &sheet->flat, &sheet->page);
          },
          [this](int64_t id, Sheet* sheet, const mesh_t& last) {
            std::swap(sheet_, *sheet);
            Process(id, last);
          }) {
  sheets_.AwaitAnnounced(channel::kFlatMesh);
}

void RestorerNode::Process(int64_t id, const mesh_t& last) {
  const SheetPage& sheet_page = sheet_.page;
  const std::string& name = sheet_page.name;
  node_->SetState("busy", id, "restoring" + (name.empty() ? "" : " the " + name + " page"));
  std::vector<StageReport> stages;
  Status s = FromMessages(last.stages, &stages);
  if (!s.ok()) return node_->FailScan(id, "FLAT_MESH: " + s.message());
  Calibration calibration;
  s = calibrations_.Get(id, &calibration);
  if (!s.ok()) return node_->FailScan(id, s.message());
  cv::Mat texture;
  s = textures_.Get(id, &texture);
  if (!s.ok()) return node_->FailScan(id, s.message());
  if (sheet_page.mask.size() != texture.size()) {
    return node_->FailScan(id, "FLAT_MESH: the page mask is " + SizeText(sheet_page.mask.size()) +
                                   ", the texture " + SizeText(texture.size()));
  }
  const CameraModel& camera = calibration.camera;
  ConnectSheet(
      last.bend_springs, [&](const cv::Vec3d& x) { return camera.Project(x); }, &sheet_.mesh);
  if (!sheet_.mesh.status.ok()) {
    return node_->FailScan(id, "FLAT_MESH: " + sheet_.mesh.status.message());
  }
  const ScanFolder folder = ScanFolder::For(options_.data_dir, id);
  s = MakeDirectories(folder.results());
  if (!s.ok()) return node_->FailScan(id, s.message());
  ScanContext context;
  s = FromMessage(last.context, &context);
  if (!s.ok()) return node_->FailScan(id, "FLAT_MESH: " + s.message());
  const PipelineOptions& o = options_.pipeline;
  RestoreResult restored;
  StageReport restore =
      RestoreStage(texture, sheet_page.mask, sheet_.mesh, sheet_.flat, camera, o.restore, o.limits,
                   o.camera_icc, context, stages, folder.results(), name, &restored);
  if (!restore.status.ok()) {
    scans_.erase(id);
    return node_->FailScan(id, restore.status.message());
  }
  // The scan's extra lights through the page's own warp, as `vellum process` does it.
  std::vector<ScanLight> lights;
  s = textures_.GetLights(id, &lights);
  std::optional<StageReport> lit;
  if (s.ok() && !lights.empty()) {
    node_->SetState("busy", id, "restoring its " + std::to_string(lights.size()) + " extra lights");
    LightsResult result;
    lit = LightsStage(lights, sheet_page.mask, sheet_.mesh, sheet_.flat.flat, o.camera_icc,
                      restored, context, folder.results(), name, &result);
    s = lit->status;
  }
  if (!s.ok()) {
    scans_.erase(id);
    return node_->FailScan(id, s.message());
  }
  Pages& pages = scans_[id];
  pages.common.clear();
  std::vector<StageReport>& mine = pages.per_page[sheet_page.index];
  mine.clear();
  for (StageReport& stage : stages) (stage.page.empty() ? pages.common : mine).push_back(stage);
  mine.push_back(restore);
  if (lit) mine.push_back(*lit);
  pages.restored[sheet_page.index] = std::move(restored);
  if (static_cast<int>(pages.names.size()) < sheet_page.count) pages.names.resize(sheet_page.count);
  pages.names[sheet_page.index] = name;
  pages.identity = context.identity;
  while (scans_.size() > 8) scans_.erase(scans_.begin());  // Scans whose pages stopped.
  if (static_cast<int>(pages.restored.size()) == sheet_page.count) Finish(id, &pages);
}

void RestorerNode::Finish(int64_t id, Pages* pages) {
  const ScanFolder folder = ScanFolder::For(options_.data_dir, id);
  ProcessReport report;
  report.stages = pages->common;
  for (const auto& [index, stages] : pages->per_page) {
    report.stages.insert(report.stages.end(), stages.begin(), stages.end());
  }
  report.scan = folder.raw();
  report.calibration = folder.calibration();
  // The archival master, once the pages are restored (as RunPipeline does).
  cv::Mat texture;
  Status s = textures_.Get(id, &texture);
  if (s.ok()) {
    const StageReport archive =
        ArchiveStage(texture, pages->identity, options_.pipeline.camera_icc, folder.results());
    report.stages.push_back(archive);
    s = archive.status;
  }
  if (s.ok()) s = WriteReports(folder.results(), "scan " + std::to_string(id), &report);
  // The archive's proof that the scan is whole: a SHA-256 of every file of raw/ and results/,
  // in the scan's folder (manifest-sha256.txt; `vellum manifest check` verifies it).
  if (s.ok()) s = WriteManifest(folder.root, {"raw", "results"});
  if (!s.ok()) {
    scans_.erase(id);
    return node_->FailScan(id, s.message());
  }
  const RestoreResult& first = pages->restored.begin()->second;
  restored_t out{};
  out.scan_id = id;
  out.view = ToString(first.view);
  out.dpi = first.view == RestoreView::kOrthographic ? first.dpi : 0;
  out.width = first.image.cols;
  out.height = first.image.rows;
  for (int k = 0; k < 6; ++k) out.pixel_from_flat[k] = first.pixel_from_flat.val[k];
  out.path = (PageDir(folder.results(), pages->names.front()) + "/restored.tif");
  out.results = folder.results();
  out.pages = pages->names;
  out.npages = static_cast<int32_t>(out.pages.size());
  for (const Warning& w : report.Warnings()) out.warnings.push_back(w.code + ": " + w.message);
  out.nwarnings = static_cast<int32_t>(out.warnings.size());
  out.qc = VerdictName(AssessQuality(report).verdict);
  // The preview: the pages side by side, scaled to at most preview_pixels.
  std::vector<cv::Mat> previews;
  int height = 0;
  for (const auto& [index, restored] : pages->restored) {
    cv::Mat p = restored.image;
    if (p.depth() != CV_8U) p.convertTo(p, CV_8U, 1.0 / 257);
    if (p.channels() == 1) cv::cvtColor(p, p, cv::COLOR_GRAY2BGR);
    height = std::max(height, p.rows);
    previews.push_back(p);
  }
  for (cv::Mat& p : previews) {
    if (p.rows < height) cv::copyMakeBorder(p, p, 0, height - p.rows, 0, 0, cv::BORDER_CONSTANT);
  }
  cv::Mat preview;
  cv::hconcat(previews, preview);
  if (first.image.channels() == 1) cv::cvtColor(preview, preview, cv::COLOR_BGR2GRAY);
  const double scale = std::min(1.0, std::sqrt(options_.preview_pixels / preview.total()));
  if (scale < 1) cv::resize(preview, preview, cv::Size(), scale, scale, cv::INTER_AREA);
  ToMessage(preview, &out.preview);
  out.preview.utime = NowUtime();
  out.preview.scan_id = id;
  out.preview.pattern_index = -1;
  scans_.erase(id);
  // The session's contact sheet, with this scan in it (before RESTORED: whoever hears it finds
  // the sheet up to date).
  const Status sheet = WriteContactSheet(options_.data_dir);
  if (!sheet.ok()) node_->Log("contact sheet: " + sheet.message());
  node_->Count("scans restored");
  node_->Publish(channel::kRestored, &out);
  AnnounceHandedOn(node_, id, channel::kRestored);
  for (const std::string& w : out.warnings)
    node_->Log("scan " + std::to_string(id) + ": warning: " + w);
  node_->Log("scan " + std::to_string(id) + ": restored " + std::to_string(out.npages) +
             " page(s), quality " + out.qc + " -> " + folder.results());
  node_->SetState("idle", id, "restored " + out.path);
}

}  // namespace vellum::station
