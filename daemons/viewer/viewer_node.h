// vellum-viewer's node: what the operator at the gantry watches. A window with the live camera
// preview (PREVIEW, never full frames), the scan's progress, every daemon's status from its
// heartbeat (alive, state, last error), and for each finished scan its texture, depth map,
// strain map and the restored page side by side, with the leaf's outline over the texture and
// a doubtful result's warnings in amber under the restored page. Keys: s = start a scan, left/right
// = step through the scans of this session, q or Esc = quit.
#pragma once

#include <chrono>
#include <deque>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "display/window.h"
#include "station/node.h"
#include "vellum/restored_t.hpp"
#include "vellum/status_t.hpp"

namespace vellum::station {

class ViewerNode {
 public:
  // Everything runs on the LCM thread (the window's events, drawing and the messages).
  ViewerNode(Node* node, std::unique_ptr<display::Window> window);

  // On the LCM thread, often: handles keys and redraws (at most ten times a second).
  void Tick();
  // Scans restored this session (the last 50 are kept).
  int results() const { return static_cast<int>(results_.size()); }
  const std::string& progress() const { return progress_; }
  // The warnings of the scan shown (code: message each), empty for a clean one.
  std::vector<std::string> warnings() const;

 private:
  struct Result {
    int64_t scan_id = 0;
    std::string summary, results;
    cv::Mat texture, depth, strain, restored;  // texture: with the leaf's outline drawn.
    std::vector<std::string> warnings;
  };
  void OnKey(SDL_Keycode key);
  void OnRestored(const restored_t& m);
  cv::Mat Draw() const;

  using Clock = std::chrono::steady_clock;
  Node* node_;
  std::unique_ptr<display::Window> window_;
  cv::Mat preview_;
  std::string progress_ = "waiting for the station";
  std::map<std::string, status_t> statuses_;
  std::map<std::string, Clock::time_point> seen_;
  std::deque<Result> results_;
  int shown_ = -1;
  Clock::time_point next_draw_;
};

}  // namespace vellum::station
