// vellum-restorer's node: FLAT_MESH chunks + the scan's texture and calibration -> the restored
// page (restored.tif, restored.json and the report's pictures), then the scan's report
// (report.html, report.json: every stage's report, as `vellum process` writes them) -> RESTORED
// with a preview of the page.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/restore/restore.h"
#include "station/assembler.h"
#include "station/books.h"
#include "station/messages.h"
#include "station/node.h"

namespace vellum::station {

struct RestorerNodeOptions {
  std::string data_dir = "scans";  // Station data folder: results go to <data_dir>/scan-<id>.
  RestoreOptions restore;
  std::optional<Calibration> fallback_calibration;  // For a scan without CALIBRATION.
  double preview_pixels = 1 << 20;  // RESTORED's preview is scaled down to at most this many.
};

class RestorerNode {
 public:
  RestorerNode(Node* node, const RestorerNodeOptions& options);
  // About once a second: gives up a product whose chunks stopped coming.
  void Tick() {
    textures_.Tick();
    sheets_.Tick();
  }

 private:
  // The flattened sheet under reassembly.
  struct Sheet {
    Mesh mesh;
    std::vector<cv::Point2d> flat;
  };
  void Process(int64_t id, const mesh_t& last);  // Worker thread.

  Node* node_;
  RestorerNodeOptions options_;
  CalibrationBook calibrations_;
  TextureBook textures_;
  Assembler<mesh_t, Sheet> sheets_;
  // Worker thread only:
  Sheet sheet_;
};

}  // namespace vellum::station
