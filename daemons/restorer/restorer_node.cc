#include "daemons/restorer/restorer_node.h"

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "core/common/text.h"
#include "io/scan_io.h"
#include "pipeline/report.h"
#include "pipeline/stages.h"
#include "station/scan_store.h"
#include "station/supervisor.h"
#include "vellum/restored_t.hpp"

namespace vellum::station {

RestorerNode::RestorerNode(Node* node, const RestorerNodeOptions& options)
    : node_(node),
      options_(options),
      calibrations_(node, options.fallback_calibration ? &*options.fallback_calibration : nullptr,
                    options.data_dir),
      textures_(node, options.data_dir),
      sheets_(
          node, channel::kFlatMesh,
          [](const mesh_t& m, Sheet* sheet) { return AddChunk(m, &sheet->mesh, &sheet->flat); },
          [this](int64_t id, Sheet* sheet, const mesh_t& last) {
            std::swap(sheet_, *sheet);
            Process(id, last);
          }) {}

void RestorerNode::Process(int64_t id, const mesh_t& last) {
  node_->SetState("busy", id, "restoring");
  ProcessReport report;
  Status s = FromMessages(last.stages, &report.stages);
  if (!s.ok()) return node_->FailScan(id, "FLAT_MESH: " + s.message());
  Calibration calibration;
  s = calibrations_.Get(id, &calibration);
  if (!s.ok()) return node_->FailScan(id, s.message());
  cv::Mat texture;
  s = textures_.Get(id, &texture);
  if (!s.ok()) return node_->FailScan(id, s.message());
  const CameraModel& camera = calibration.camera;
  ConnectSheet(
      last.bend_springs, [&](const cv::Vec3d& x) { return camera.Project(x); }, &sheet_.mesh);
  if (!sheet_.mesh.status.ok())
    return node_->FailScan(id, "FLAT_MESH: " + sheet_.mesh.status.message());
  const ScanFolder folder = ScanFolder::For(options_.data_dir, id);
  s = MakeDirectories(folder.results());
  if (!s.ok()) return node_->FailScan(id, s.message());
  RestoreResult restored;
  report.stages.push_back(RestoreStage(texture, sheet_.mesh, sheet_.flat, camera, options_.restore,
                                       folder.results(), &restored));
  if (!report.stages.back().status.ok())
    return node_->FailScan(id, report.stages.back().status.message());
  report.scan = folder.raw();
  report.calibration = folder.calibration();
  s = WriteReports(folder.results(), "scan " + std::to_string(id), &report);
  if (!s.ok()) return node_->FailScan(id, s.message());

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
  const double scale = std::min(1.0, std::sqrt(options_.preview_pixels / preview.total()));
  if (scale < 1) cv::resize(preview, preview, cv::Size(), scale, scale, cv::INTER_AREA);
  ToMessage(preview, &out.preview);
  out.preview.utime = NowUtime();
  out.preview.scan_id = id;
  out.preview.pattern_index = -1;
  node_->Count("scans restored");
  node_->Publish(channel::kRestored, &out);
  AnnounceHandedOn(node_, id, channel::kRestored);
  node_->Log("scan " + std::to_string(id) + ": restored " + SizeText(restored.image.size()) +
             " in " + std::to_string(report.stages.back().seconds) + " s -> " + out.path);
  node_->SetState("idle", id, "restored " + out.path);
}

}  // namespace vellum::station
