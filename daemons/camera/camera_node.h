// vellum-camera's node: on each PATTERN_SHOWN, the camera's first frame whose exposure starts
// after it, published as CAPTURE (the texture in colour, patterns in gray); a copy at most 640
// pixels wide on PREVIEW; and a live preview while no scan runs, with the centre of its view at
// full resolution on PREVIEW_FOCUS (the viewer's 100% zoom, for focusing).
#pragma once

#include <chrono>
#include <memory>

#include "core/decode/frame_check.h"
#include "daemons/camera/camera.h"
#include "station/node.h"
#include "vellum/latency_probe_t.hpp"
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
  // The frames around a flash of the display-lag measurement, answered on LATENCY_SEEN
  // (worker thread).
  void OnProbe(const latency_probe_t& m);
  void PublishPreview(const cv::Mat& image, int64_t utime, int64_t scan_id, int index, int count);
  // Counts the frames the camera dropped or refused since the last call (worker thread).
  void CountCameraFaults();
  // The frame for `request`, checked to show its own pattern (core/decode/frame_check.h): a
  // Gray code's inverse against its pattern on a linear camera, every other frame against the
  // camera's next one. A frame that does not is named, counted, never sent, and taken again
  // from the camera's next frame (three tries); a pattern already sent that its inverse finds
  // mixed fails the scan (worker thread).
  Status CheckedCapture(const FrameRequest& request, const std::string& where, cv::Mat* image,
                        int64_t* exposure);
  Status Next(const FrameRequest& request, int64_t after, cv::Mat* image, int64_t* exposure);
  void NameMixed(const std::string& where, const std::string& how);

  Node* node_;
  std::unique_ptr<Camera> camera_;           // Worker thread only (after construction).
  int64_t dropped_seen_ = 0, bad_seen_ = 0;  // Worker thread only.
  // Worker thread only: the scan's frames the checks need (8-bit gray).
  struct Kept {
    int64_t scan_id = 0;
    cv::Mat white, black, pattern;  // pattern: the last Gray-code frame taken, not inverted.
    PatternSpec pattern_spec;
    int pattern_index = -1;
  } kept_;
  FrameCheckOptions check_;
  std::string preview_error_;  // Worker thread only: the last one logged.
  std::chrono::duration<double> preview_period_;
  // LCM thread only:
  Clock::time_point busy_until_, next_preview_;
};

}  // namespace vellum::station
