// vellum-flattener's node: POINT_CLOUD chunks + the scan's texture and calibration -> the leaf
// found (or a spread's two pages; report/outline.png) -> for each page the mass-spring sheet,
// flattened (mesh.ply, flat.ply in the page's results) -> FLAT_MESH chunks, page after page,
// with the reports of the stages so far.
#pragma once

#include <future>
#include <map>
#include <optional>
#include <string>

#include "pipeline/stages.h"
#include "station/assembler.h"
#include "station/books.h"
#include "station/messages.h"
#include "station/node.h"

namespace vellum::station {

struct FlattenerNodeOptions {
  std::string data_dir = "scans";  // Station data folder: results go to <data_dir>/scan-<id>.
  PipelineOptions pipeline;        // Its outline, mesh, flatten and limits parts.
  std::optional<Calibration> fallback_calibration;  // For a scan without CALIBRATION.
  bool Check(std::string* why) const;
};

class FlattenerNode {
 public:
  FlattenerNode(Node* node, const FlattenerNodeOptions& options);
  // Waits for the jobs it posted: none runs after it is gone.
  ~FlattenerNode() { node_->Drain(); }
  // About once a second: gives up a product whose chunks stopped coming.
  void Tick() {
    textures_.Tick();
    assembler_.Tick();
  }

 private:
  void Process(int64_t id, const point_cloud_t& last);  // Worker thread.

  Node* node_;
  FlattenerNodeOptions options_;
  CalibrationBook calibrations_;
  TextureBook textures_;
  Assembler<point_cloud_t, cv::Mat> assembler_;
  // Worker thread only:
  cv::Mat points_;
  // The report's picture of each recent scan's texture, written as the texture came.
  std::map<int64_t, std::shared_future<Status>> pictured_;
};

}  // namespace vellum::station
