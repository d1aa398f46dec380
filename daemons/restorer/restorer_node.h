// vellum-restorer's node: FLAT_MESH chunks + the scan's texture and calibration -> each page
// restored (restored.tif, restored_mask.png, restored.json and the report's pictures; the images
// under the scan's extra lights, LIGHT_TEXTURE, through the same warp: lights/, normals.tif), then,
// once every page of the scan is in, the scan's report (report.html, report.json: every stage's
// report, as `vellum process` writes them) -> RESTORED with a preview and the warnings.
#pragma once

#include <chrono>
#include <future>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "pipeline/pipeline.h"
#include "station/assembler.h"
#include "station/books.h"
#include "station/contact_sheet.h"
#include "station/messages.h"
#include "station/node.h"

namespace vellum::station {

struct RestorerNodeOptions {
  std::string data_dir = "scans";  // Station data folder: results go to <data_dir>/scan-<id>.
  PipelineOptions pipeline;        // Its restore options and limits.
  std::optional<Calibration> fallback_calibration;  // For a scan without CALIBRATION.
  double preview_pixels = 1 << 20;  // RESTORED's preview is scaled down to at most this many.
  bool Check(std::string* why) const;
};

class RestorerNode {
 public:
  RestorerNode(Node* node, const RestorerNodeOptions& options);
  // Waits for the jobs it posted: none runs after it is gone.
  ~RestorerNode() { node_->Drain(); }
  // About once a second: gives up a product whose chunks stopped coming.
  void Tick() {
    textures_.Tick();
    sheets_.Tick();
    if (clouds_assembler_) {
      clouds_assembler_->Tick();
      node_->Post([this] { GiveUpWaiting(); });
    }
  }

 private:
  // The flattened sheet of a page under reassembly.
  struct Sheet {
    Mesh mesh;
    FlattenResult flat;  // Its flat positions and strains.
    SheetPage page;
    SheetRests rests;  // Its springs' rest lengths.
  };
  // The pages of a scan restored so far.
  struct Pages {
    std::vector<StageReport> common;                   // The scan's stages (page "").
    std::map<int, std::vector<StageReport>> per_page;  // Mesh, flatten, restore of each page.
    std::map<int, RestoreResult> restored;
    std::vector<std::string> names;
    ScanContext context;  // The scan's.
    // The archival master's stage, run on a thread of its own from the scan's texture on (or its
    // first page, when the texture came before this process heard the scan start): it needs
    // only the texture and the scan's identity, not the restored pages.
    std::future<StageReport> archive;
    ScanIdentity archived;  // The identity it was begun with.
  };
  // The point map of a scan and the projector's light, for the albedo and reflectance.
  struct Cloud {
    cv::Mat points, amplitude;
  };
  // A page that came before its scan's point map.
  struct Waiting {
    Sheet sheet;
    mesh_t last;
  };
  struct WaitingScan {
    Clock::time_point since;
    std::vector<Waiting> sheets;
  };
  bool NeedsCloud() const;                       // With a flat field or a studio field.
  void Process(int64_t id, const mesh_t& last);  // Worker thread.
  // Begins the scan's archival master (Pages::archive) unless begun with this identity.
  void StartArchive(int64_t id, const cv::Mat& texture, const ScanIdentity& identity);
  void Finish(int64_t id, Pages* pages);     // Every page is in: the report, RESTORED.
  void CloudDone(int64_t id, Cloud* cloud);  // Worker thread.
  void GiveUpWaiting();  // Worker thread: fails a scan whose point map did not come in 30 s.

  Node* node_;
  RestorerNodeOptions options_;
  CalibrationBook calibrations_;
  TextureBook textures_;
  Assembler<mesh_t, Sheet> sheets_;
  std::unique_ptr<Assembler<point_cloud_t, Cloud>> clouds_assembler_;  // With NeedsCloud().
  // Worker thread only:
  Sheet sheet_;
  std::map<int64_t, Pages> scans_;   // Scans with pages still to come.
  SheetCache contact_sheet_;         // The contact sheet's scans, read again only when changed.
  std::map<int64_t, Cloud> clouds_;  // The newest scans' point maps (with NeedsCloud()).
  std::map<int64_t, WaitingScan> waiting_;
  std::map<int64_t, ScanIdentity> identities_;  // Of the scans heard starting (SCAN_STARTED).
};

}  // namespace vellum::station
