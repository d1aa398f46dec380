// vellum-viewer's node: what the operator at the gantry watches. The node is the glue: the bus
// and the window's keys and mouse go into a ViewerState (viewer_state.h), which DrawViewer
// (viewer_draw.h) draws four times a second (ten while the operator acts). A window with the live
// camera preview (PREVIEW, never full frames), the scan's progress, every daemon's status from its
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

#include <memory>

#include "daemons/viewer/viewer_draw.h"
#include "daemons/viewer/viewer_state.h"
#include "display/window.h"
#include "station/node.h"

namespace vellum::station {

struct ViewerNodeOptions {
  // Where the operator's sequence is kept across restarts (ViewerState::SessionJson); "" for
  // nowhere. vellum-viewer keeps it beside the data: <data>/viewer-session.json.
  std::string session_file;
  bool Check(std::string* why) const;
};

// The operator's action for a key (SDL's), with the identity form open or not; false for a key
// that does nothing.
bool ActionForKey(SDL_Keycode key, bool form_open, ViewerState::Action* action);

class ViewerNode {
 public:
  // Everything runs on the LCM thread (the window's events, drawing and the messages).
  // Takes up the session in options.session_file if there is one (one that does not read is
  // reported and set aside as <file>.bad, or .bad.1, .bad.2..., never lost).
  ViewerNode(Node* node, std::unique_ptr<display::Window> window,
             const ViewerNodeOptions& options = ViewerNodeOptions());

  // On the LCM thread, often: handles keys and redraws (see kPace).
  void Tick();
  const ViewerState& state() const { return state_; }
  // Where the preview was last drawn on the window (its pixels); empty before any.
  cv::Rect preview_area() const { return layout_.preview; }

 private:
  void OnKey(SDL_Keycode key);
  void OnMouse(const display::Window::Input& in);
  // Publishes what an action asked, and follows the form opening and closing.
  void Do(ViewerState::Action action);
  void LoadSession();
  // Writes the session when it changed (whole: a new file renamed over the old), and says on
  // the status whether a scan can be asked for, and if not why (with the scan last shown).
  void SaveSessionAndReadiness();

  Node* node_;
  std::unique_ptr<display::Window> window_;
  ViewerNodeOptions options_;
  ViewerState state_;
  std::string saved_session_;    // As last written.
  std::string readiness_;        // As last said on the status.
  int64_t shown_ = 0;            // The scan whose restored page was last drawn (its status).
  ViewerLayout layout_;          // Of the last draw (the mouse reads it).
  cv::Point drag_from_{-1, -1};  // Where a drag on the preview began (window pixels).
  // Real time: the drawing's pace (kPace), and its quickest for the operator (kQuickest).
  static constexpr std::chrono::milliseconds kPace{250}, kQuickest{100};
  std::chrono::steady_clock::time_point next_draw_, last_draw_;
  bool operator_waits_ = false;  // Input or a focus view not yet drawn.
};

}  // namespace vellum::station
