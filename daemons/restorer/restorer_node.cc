#include "daemons/restorer/restorer_node.h"

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "core/common/depth.h"
#include "core/common/text.h"
#include "io/manifest.h"
#include "io/scan_io.h"
#include "pipeline/pipeline.h"
#include "pipeline/qc.h"
#include "pipeline/report.h"
#include "station/contact_sheet.h"
#include "station/scan_store.h"
#include "station/supervisor.h"
#include "vellum/restored_t.hpp"
#include "vellum/scan_started_t.hpp"

namespace vellum::station {

namespace {

// The pipeline's archive step on its own: the archival master of `texture` in `results`, and the
// step's report (its failure, or its writes', in its status).
StageReport ArchiveStep(const PipelineOptions& options, const cv::Mat& texture,
                        const ScanIdentity& identity, const std::string& results) {
  ScanWork work;
  work.scan.texture = texture;
  work.context.identity = identity;
  work.results = results;
  Status s = MakeDirectories(results);
  if (s.ok()) s = Pipeline(options).Run(Step::kArchive, Step::kArchive, &work);
  const Status written = work.writes->Wait();
  StageReport report = work.stages.empty() ? StageReport() : work.stages.back();
  if (work.stages.empty()) report.stage = "archive";
  if (report.status.ok() && !s.ok()) report.status = s;
  if (report.status.ok() && !written.ok()) report.status = written;
  return report;
}

}  // namespace

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
            return AddChunk(m, &sheet->mesh, &sheet->flat, &sheet->page, &sheet->rests);
          },
          [this](int64_t id, Sheet* sheet, const mesh_t& last) {
            std::swap(sheet_, *sheet);
            Process(id, last);
          }) {
  sheets_.AwaitAnnounced(channel::kFlatMesh);
  // The decoder sends the projector's light only to a restorer that makes the albedo.
  node->Count(counter::kLightWanted, options.pipeline.flat_field.empty() ? 0 : 1);
  // The archival master is the texture as captured: begun as soon as the texture and the scan's
  // identity are here, while the patterns are still projected.
  node->Subscribe<scan_started_t>(channel::kScanStarted, [this](const scan_started_t& m) {
    node_->Post(
        [this, id = m.scan_id, identity = FromMessage(m.identity)] {
          identities_[id] = identity;
          while (identities_.size() > 8) identities_.erase(identities_.begin());
        },
        "noting a scan's identity");
  });
  textures_.OnTaken([this](int64_t id, const cv::Mat& texture) {
    const auto identity = identities_.find(id);
    if (identity == identities_.end()) return;  // Begun with its first page instead.
    StartArchive(id, texture, identity->second);
    node_->Count("archival masters begun at the texture");
  });
  if (NeedsCloud()) {
    // The albedo and reflectance are made from the point map (and the projector's light, which
    // travels with it): heard as the flattener hears it.
    clouds_assembler_ = std::make_unique<Assembler<point_cloud_t, Cloud>>(
        node, channel::kPointCloud,
        [](const point_cloud_t& m, Cloud* c) { return AddChunk(m, &c->points, &c->amplitude); },
        [this](int64_t id, Cloud* cloud, const point_cloud_t&) { CloudDone(id, cloud); });
    clouds_assembler_->AwaitAnnounced(channel::kPointCloud);
  }
}

bool RestorerNode::NeedsCloud() const {
  return !options_.pipeline.flat_field.empty() || !options_.pipeline.studio_field.empty();
}

void RestorerNode::CloudDone(int64_t id, Cloud* cloud) {
  clouds_[id] = std::move(*cloud);
  while (clouds_.size() > 2) clouds_.erase(clouds_.begin());  // The newest scans'.
  // The pages that came before their scan's point map.
  auto waiting = waiting_.find(id);
  if (waiting == waiting_.end()) return;
  std::vector<Waiting> sheets = std::move(waiting->second.sheets);
  waiting_.erase(waiting);
  for (Waiting& w : sheets) {
    std::swap(sheet_, w.sheet);
    Process(id, w.last);
  }
}

void RestorerNode::GiveUpWaiting() {
  const auto now = node_->Now();
  for (auto it = waiting_.begin(); it != waiting_.end();) {
    if (now - it->second.since < std::chrono::seconds(30)) {
      ++it;
      continue;
    }
    const int64_t id = it->first;
    it = waiting_.erase(it);
    scans_.erase(id);
    node_->FailScan(
        id,
        "POINT_CLOUD never came whole within 30 s: the albedo and reflectance are made from the "
        "point map and the projector's light (the restorer has a flat field or a "
        "studio field), so the page was not restored");
  }
}

void RestorerNode::Process(int64_t id, const mesh_t& last) {
  const SheetPage& sheet_page = sheet_.page;
  const std::string& name = sheet_page.name;
  const std::string which = name.empty() ? "" : " the " + name + " page";
  if (NeedsCloud() && !clouds_.count(id)) {
    // The point map is still on its way (or was asked again): the page waits for it.
    WaitingScan& w = waiting_[id];
    if (w.sheets.empty()) w.since = node_->Now();
    w.sheets.push_back({std::move(sheet_), last});
    sheet_ = Sheet();
    node_->SetState("busy", id, "waiting for the point map to restore" + which);
    return;
  }
  node_->SetState("busy", id, "restoring" + which);
  ScanWork work;
  Status s = FromMessages(last.stages, &work.stages);
  if (!s.ok()) return node_->FailScan(id, "FLAT_MESH: " + s.message());
  s = FromMessage(last.context, &work.context);
  if (!s.ok()) return node_->FailScan(id, "FLAT_MESH: " + s.message());
  s = calibrations_.Get(id, &work.calibration);
  if (!s.ok()) return node_->FailScan(id, s.message());
  s = textures_.Get(id, &work.scan.texture);
  if (s.ok()) s = textures_.GetLights(id, &work.scan.lights);
  if (!s.ok()) return node_->FailScan(id, s.message());
  const cv::Mat& texture = work.scan.texture;
  if (sheet_page.mask.size() != texture.size()) {
    return node_->FailScan(id, "FLAT_MESH: the page mask is " + SizeText(sheet_page.mask.size()) +
                                   ", the texture " + SizeText(texture.size()));
  }
  const CameraModel& camera = work.calibration.camera;
  ConnectSheet(
      last.bend_springs, [&](const cv::Vec3d& x) { return camera.Project(x); }, &sheet_.mesh);
  if (!sheet_.mesh.status.ok()) {
    return node_->FailScan(id, "FLAT_MESH: " + sheet_.mesh.status.message());
  }
  // The springs' rest lengths as the flattener measured them (along the surface).
  s = SetRestLengths(sheet_.rests, &sheet_.mesh);
  if (!s.ok()) return node_->FailScan(id, s.message());
  if (NeedsCloud()) {
    const Cloud& cloud = clouds_.at(id);
    if (cloud.points.size() != texture.size()) {
      return node_->FailScan(id, "POINT_CLOUD: the point map is " + SizeText(cloud.points.size()) +
                                     ", the texture " + SizeText(texture.size()));
    }
    work.map.points = cloud.points;
    work.amplitude = cloud.amplitude;
    if (!options_.pipeline.flat_field.empty() && work.amplitude.empty()) {
      // Sent before the decoder heard that this restorer wants it (one started since with a
      // flat field): counted as a product lost, so that the decoder makes the scan again.
      node_->Count(counter::kProductsLost);
      return node_->FailScan(id,
                             "POINT_CLOUD came without the projector's light (amplitude), "
                             "which the albedo is made from");
    }
  }
  const ScanFolder folder = ScanFolder::For(options_.data_dir, id);
  work.results = folder.results();
  s = MakeDirectories(work.results);
  if (!s.ok()) return node_->FailScan(id, s.message());
  // The pipeline's page steps from the restore on: the page through its sheet, then its albedo,
  // reflectance and extra lights through the same warp, as `vellum process` does it.
  const Pipeline pipeline(options_.pipeline);
  s = pipeline.Check(work);
  const size_t k = static_cast<size_t>(sheet_page.index);
  work.pages.resize(static_cast<size_t>(sheet_page.count));
  PageResult& page = work.pages[k];
  page.name = name;
  page.mask = sheet_page.mask;
  page.mesh = std::move(sheet_.mesh);
  page.flat = std::move(sheet_.flat);
  const size_t before = work.stages.size();
  if (s.ok()) StartArchive(id, work.scan.texture, work.context.identity);
  if (s.ok()) s = pipeline.RunPage(k, Step::kRestore, Step::kRestore, &work);
  if (s.ok() && (NeedsCloud() || !work.scan.lights.empty())) {
    node_->SetState("busy", id,
                    "restoring the albedo, reflectance or extra lights" +
                        (name.empty() ? std::string() : " of the " + name + " page"));
    s = pipeline.RunPage(k, Step::kAlbedo, Step::kLights, &work);
  }
  const Status written = work.writes->Wait();
  if (s.ok()) s = written;
  if (!s.ok()) {
    scans_.erase(id);
    return node_->FailScan(id, s.message());
  }
  Pages& pages = scans_[id];
  pages.common.clear();
  std::vector<StageReport>& mine = pages.per_page[sheet_page.index];
  mine.clear();
  for (size_t j = 0; j < work.stages.size(); ++j) {
    StageReport& stage = work.stages[j];
    (j < before && stage.page.empty() ? pages.common : mine).push_back(std::move(stage));
  }
  pages.restored[sheet_page.index] = std::move(page.restored);
  if (static_cast<int>(pages.names.size()) < sheet_page.count) pages.names.resize(sheet_page.count);
  pages.names[sheet_page.index] = name;
  pages.context = work.context;
  if (static_cast<int>(pages.restored.size()) == sheet_page.count) {
    // Begun already, unless its scan was put aside meanwhile.
    StartArchive(id, work.scan.texture, work.context.identity);
    Finish(id, &pages);
  }
  while (scans_.size() > 8) scans_.erase(scans_.begin());  // Scans whose pages stopped.
}

void RestorerNode::StartArchive(int64_t id, const cv::Mat& texture, const ScanIdentity& identity) {
  Pages& pages = scans_[id];
  if (pages.archive.valid()) {
    if (pages.archived == identity) return;  // Begun with the texture, or another page.
    static_cast<void>(pages.archive.get());  // Begun with another identity: written again.
    node_->Count("archival masters written again");
  }
  pages.archived = identity;
  // On a thread when one can be had, else where the report asks for it.
  pages.archive =
      std::async(std::launch::async | std::launch::deferred, ArchiveStep, options_.pipeline,
                 texture, identity, ScanFolder::For(options_.data_dir, id).results());
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
  report.target = options_.pipeline.target;
  // The archival master (the pipeline's last step), written while the pages were restored.
  const StageReport archive = pages->archive.get();
  report.stages.push_back(archive);
  Status s = archive.status;
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
  // And the figures that fail a check with no warning saying so (a target not met), named by
  // their check: a FAIL always says why, on the viewer's screen and in `vellum scan`'s output.
  const QcResult qc = AssessQuality(report);
  for (const QcCheck& c : qc.checks) {
    if (!c.shortfall.empty()) out.warnings.push_back(c.name + ": " + c.shortfall);
  }
  out.nwarnings = static_cast<int32_t>(out.warnings.size());
  out.qc = VerdictName(qc.verdict);
  // The preview: the pages side by side, scaled to at most preview_pixels.
  std::vector<cv::Mat> previews;
  int height = 0;
  for (const auto& [index, restored] : pages->restored) {
    cv::Mat p = EightBitBgr(restored.image);
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
  const Status sheet = WriteContactSheet(options_.data_dir, &contact_sheet_);
  if (!sheet.ok()) node_->Log("contact sheet: " + sheet.message());
  node_->Publish(channel::kRestored, &out);
  AnnounceHandedOn(node_, id, channel::kRestored, "scans restored");
  for (const std::string& w : out.warnings)
    node_->Log("scan " + std::to_string(id) + ": warning: " + w);
  node_->Log("scan " + std::to_string(id) + ": restored " + std::to_string(out.npages) +
             " page(s), quality " + out.qc + " -> " + folder.results());
  node_->SetState("idle", id, "restored " + out.path);
}

}  // namespace vellum::station
