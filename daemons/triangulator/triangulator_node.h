// vellum-triangulator's node: CORRESPONDENCE chunks + the scan's calibration -> the point map
// (points.ply, depth.png and the report's pictures in the scan's results) -> POINT_CLOUD
// chunks, with the reports of the stages so far.
#pragma once

#include <memory>
#include <optional>
#include <string>

#include "core/geometry/triangulate.h"
#include "pipeline/report.h"
#include "pipeline/stages.h"
#include "station/assembler.h"
#include "station/books.h"
#include "station/messages.h"
#include "station/node.h"

namespace vellum::station {

struct TriangulatorNodeOptions {
  std::string data_dir = "scans";  // Station data folder: results go to <data_dir>/scan-<id>.
  TriangulateOptions triangulate;
  WarningLimits limits;  // What makes its points doubtful (decode_low), as `vellum process` has.
  std::optional<Calibration> fallback_calibration;  // For a scan without CALIBRATION.
  bool Check(std::string* why) const;
};

class TriangulatorNode {
 public:
  TriangulatorNode(Node* node, const TriangulatorNodeOptions& options);
  // Waits for the jobs it posted: none runs after it is gone.
  ~TriangulatorNode() { node_->Drain(); }
  // About once a second: gives up a product whose chunks stopped coming.
  void Tick() { assembler_.Tick(); }

 private:
  // The correspondence map under reassembly.
  struct Correspondence {
    DecodeResult decoded;
    cv::Size projector;
  };
  void Process(int64_t id, const correspondence_t& last);  // Worker thread.
  // Makes the calibration's rays unless they are those made last (worker thread).
  void Prepare(const Calibration& calibration);

  Node* node_;
  TriangulatorNodeOptions options_;
  CalibrationBook calibrations_;
  Assembler<correspondence_t, Correspondence> assembler_;
  // Worker thread only:
  Correspondence product_;
  std::unique_ptr<Triangulator> triangulator_;  // Its rays, kept while the calibration holds.
  PointMap map_;
};

}  // namespace vellum::station
