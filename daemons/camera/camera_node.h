// vellum-camera's node: on each PATTERN_SHOWN, the camera's first frame whose exposure starts
// after it, published as CAPTURE (the texture in colour, patterns in gray); a copy at most 640
// pixels wide on PREVIEW; and a live preview while no scan runs, with the centre of its view at
// full resolution on PREVIEW_FOCUS (the viewer's 100% zoom, for focusing).
#pragma once

#include <chrono>
#include <memory>

#include "daemons/camera/camera.h"
#include "station/node.h"
#include "vellum/pattern_shown_t.hpp"

namespace vellum::station {

struct CameraNodeOptions {
  double preview_hz = 2;  // Live preview rate on PREVIEW while idle.
  bool Check(std::string* why) const;
};

class CameraNode {
 public:
  CameraNode(Node* node, std::unique_ptr<Camera> camera, const CameraNodeOptions& options);
  // Waits for the jobs it posted: none runs after it is gone.
  ~CameraNode() { node_->Drain(); }
  // On the LCM thread, often: posts a live preview frame when it is time and no scan runs.
  void Tick();

 private:
  void OnShown(const pattern_shown_t& m);  // Worker thread.
  void PublishPreview(const cv::Mat& image, int64_t utime, int64_t scan_id, int index, int count);
  // Counts the frames the camera dropped or refused since the last call (worker thread).
  void CountCameraFaults();

  Node* node_;
  std::unique_ptr<Camera> camera_;  // Worker thread only (after construction).
  int64_t dropped_seen_ = 0, bad_seen_ = 0;  // Worker thread only.
  std::string preview_error_;                // Worker thread only: the last one logged.
  std::chrono::duration<double> preview_period_;
  // LCM thread only:
  Clock::time_point busy_until_, next_preview_;
};

}  // namespace vellum::station
