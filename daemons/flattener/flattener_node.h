// vellum-flattener's node: POINT_CLOUD chunks + the scan's texture (where the page is) and
// calibration -> the mass-spring sheet over the page, flattened (mesh.ply, flat.ply in the
// scan's results) -> FLAT_MESH chunks, with the reports of the stages so far.
#pragma once

#include <optional>
#include <string>

#include "core/flatten/flatten.h"
#include "core/mesh/mesh.h"
#include "station/assembler.h"
#include "station/books.h"
#include "station/messages.h"
#include "station/node.h"

namespace vellum::station {

struct FlattenerNodeOptions {
  std::string data_dir = "scans";  // Station data folder: results go to <data_dir>/scan-<id>.
  MeshOptions mesh;
  FlattenOptions flatten;
  std::optional<Calibration> fallback_calibration;  // For a scan without CALIBRATION.
};

class FlattenerNode {
 public:
  FlattenerNode(Node* node, const FlattenerNodeOptions& options);
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
};

}  // namespace vellum::station
