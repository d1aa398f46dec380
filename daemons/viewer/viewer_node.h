// vellum-viewer's node: what the operator at the gantry watches. A window with the live camera
// preview (PREVIEW, never full frames), the scan's progress, every daemon's status from its
// heartbeat (alive, state, last error), and for each finished scan its texture, depth map,
// strain map and the restored page side by side, with the leaf's outline over the texture and
// a doubtful result's warnings in amber under the restored page, and its quality verdict
// (pass, warn, fail) in green, amber or red. A scan that fails turns the header red with the
// daemon's whole message. The preview shows clipped pixels in red with a histogram under it, and
// "NO SIGNAL" when the camera falls silent. The leaf's outline is drawn over the preview as it
// is placed (by brightness: LeafInPreview), with a red warning when it runs off the view.
//
// The next scan's catalogue identity (shelfmark, folio, side, operator, note) is set in a form
// (e opens it; Tab or Down / Up move between fields; Return or Esc closes it); each scan then
// advances the folio (recto, verso, the next recto: NextFolio), and u takes the last advance
// back (to scan a folio again). Keys: s = start a scan, e = edit the identity, u = undo the last
// advance, z = the preview's centre at 100% (the camera's own pixels, with a focus figure),
// c = the session's contact sheet (every scan restored this session, its verdict in its
// colour; on disk, <data>/index.html), left/right = step through the scans of this session,
// q or Esc = quit.
//
// Where the scene is ambiguous (a leaf on a support as bright as it, in a frame), the operator
// drags a box over the leaf in the camera preview: the leaf hint, drawn in cyan, which every
// scan asked for from here on carries (SCAN_REQUEST's leaf_hint) until h clears it (or a click
// without a drag).
//
// A station whose extra lights the operator switches by hand (vellum-lights --backend manual):
// its LIGHT_PROMPT shows as a blue box over the results (which light to switch on, and that
// nothing else may be on), and l answers LIGHT_ON for the scan, which then goes on; the box
// goes when the light is on. vellum-lights' status is listed once it is heard.
#pragma once

#include <chrono>
#include <deque>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "core/patterns/scan.h"
#include "display/window.h"
#include "station/node.h"
#include "vellum/light_t.hpp"
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
  // The quality verdict of the scan shown ("" when none is shown).
  std::string quality() const;
  // The identity the next scan will carry.
  const ScanIdentity& next_identity() const { return next_; }
  bool editing() const { return editing_ >= 0; }
  bool sheet() const { return sheet_; }
  bool zoomed() const { return zoom_; }
  // The live preview's leaf: "in view", "off the view" (it touches the border), or why none
  // is outlined; "" before any preview.
  const std::string& preview_leaf() const { return preview_leaf_; }
  // The failure of the scan in progress ("" when none): "<process>: <its whole error>".
  const std::string& failure() const { return failure_; }
  // The operator's prompt shown ("" when none): LIGHT_PROMPT's text.
  const std::string& light_prompt() const { return prompt_.text; }
  // The leaf hint the next scan carries, as fractions of the camera's view; empty when none.
  const cv::Rect2d& leaf_hint() const { return hint_; }
  // What the operator says the scans of this sequence are ('o' turns it: auto, leaf, book).
  ObjectKind object() const { return object_; }
  // Where the preview was last drawn on the window (its pixels); empty before any.
  cv::Rect preview_area() const { return preview_at_; }

 private:
  struct Result {
    int64_t scan_id = 0;
    std::string summary, results, quality;
    std::string title;  // The identity from its report ("MS 12, 3 recto"), or the scan id.
    cv::Mat texture, depth, strain, restored;  // texture: with the leaf's outline drawn.
    std::vector<std::string> warnings;
  };
  void OnKey(SDL_Keycode key);
  void OnText(const std::string& text);
  void OnMouse(const display::Window::Input& in);
  void ClearHint();  // h, or a click without a drag.
  void OnStatus(const status_t& m);
  void OnRestored(const restored_t& m);
  void Started(int64_t scan_id);  // A scan began: a failure shown before is over.
  cv::Mat Draw() const;
  void DrawSheet(cv::Mat& canvas, cv::Rect area) const;
  void DrawLeft(cv::Mat& canvas, int top, int width) const;

  using Clock = std::chrono::steady_clock;
  Node* node_;
  std::unique_ptr<display::Window> window_;
  cv::Mat preview_;
  cv::Mat preview_shown_, preview_hist_;  // As shown (clipped pixels red), and its histogram.
  double preview_clipped_ = 0;            // Share of its pixels clipped.
  std::string preview_leaf_;              // See preview_leaf().
  std::string progress_ = "waiting for the station";
  std::map<std::string, status_t> statuses_;
  std::map<std::string, Clock::time_point> seen_;
  Clock::time_point last_preview_;
  std::deque<Result> results_;
  int shown_ = -1;
  Clock::time_point next_draw_;
  ScanIdentity next_;
  ObjectKind object_ = ObjectKind::kAuto;  // The sequence's object, sent with each request.
  std::vector<ScanIdentity> history_;      // The identities of the scans asked for, for undo.
  int editing_ = -1;                       // The field being edited, or -1.
  bool sheet_ = false;                     // The contact sheet is shown.
  bool zoom_ = false;                      // The preview at 100%: the focus crop.
  cv::Mat focus_;               // PREVIEW_FOCUS: the view's centre, full resolution, BGR.
  double focus_sharpness_ = 0;  // Its Laplacian's variance.
  int64_t scan_ = 0;            // The scan in progress (or last asked for).
  int64_t failed_scan_ = 0;
  std::string failure_;
  std::map<std::string, int64_t> error_utime_;  // Each process's last error seen.
  light_t prompt_{};                            // The operator's prompt (text "" when none).
  cv::Rect2d hint_;                             // See leaf_hint().
  cv::Point drag_from_{-1, -1};                 // Where a drag on the preview began (window).
  cv::Point drag_to_;
  // Set by each draw (Draw is const: the layout is its own), read by the mouse.
  mutable cv::Rect preview_at_;
};

}  // namespace vellum::station
