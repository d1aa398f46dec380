// What the operator's window shows and what the operator asked, without the window: the
// station as heard on the bus (the live preview and its leaf, the scan's progress, every
// daemon's heartbeat, the scans restored this session, a failure, a prompt to switch a light)
// and the operator's side (the next scan's identity and its form, the sequence's object, the
// leaf hint, which result is shown, the contact sheet, the zoom). ViewerNode feeds it from the
// bus and the window's keys and mouse; DrawViewer (viewer_draw.h) draws it. It holds no SDL, no
// bus and no clock (the times are given), so that a test drives it alone.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/patterns/scan.h"
#include "station/clock.h"
#include "vellum/light_t.hpp"
#include "vellum/pattern_shown_t.hpp"
#include "vellum/restored_t.hpp"
#include "vellum/scan_request_t.hpp"
#include "vellum/status_t.hpp"

namespace vellum::station {

// One field of the identity form: its label and its member of ScanIdentity.
struct FormField {
  const char* name;
  std::string ScanIdentity::*field;
};
// The form's fields, in order: shelfmark, folio, side, operator, note.
const std::vector<FormField>& IdentityForm();

// "MS 12, 3 recto (A. Scribe)"; "(no identity: press e)".
std::string DescribeIdentity(const ScanIdentity& id);

class ViewerState {
 public:
  // What the operator can do (ViewerNode maps the keys to these).
  enum class Action {
    kScan,       // s: ask for a scan of the next identity; the folio advances.
    kEdit,       // e: open the identity form.
    kSheet,      // c: the session's contact sheet, on or off.
    kObject,     // o: the sequence's object: auto, leaf, book.
    kClearHint,  // h (or a click on the preview): no leaf hint.
    kLightDone,  // l: the light asked for is on (or the lights are off).
    kZoom,       // z: the preview's centre at 100%.
    kUndo,       // u: take the last advance back.
    kPrevious,   // Left: an earlier result.
    kNext,       // Right: a later result.
    kQuit,       // q, Esc.
    kFieldNext,  // In the form: Tab, Down.
    kFieldBack,  // In the form: Up.
    kBackspace,  // In the form: one character off the field.
    kFormDone,   // In the form: Return, Esc.
  };
  // What an action asks of the bus.
  struct Command {
    enum class Kind { kNone, kQuit, kRequestScan, kLightOn };
    Kind kind = Kind::kNone;
    scan_request_t request{};  // kRequestScan: publish on SCAN_REQUEST.
    light_t light{};           // kLightOn: publish on LIGHT_ON.
  };
  // A scan restored this session, as shown.
  struct Result {
    int64_t scan_id = 0;
    std::string summary, results, quality;
    std::string title;  // The identity from its report ("MS 12, 3 recto"), or the scan id.
    cv::Mat texture, depth, strain, restored;  // texture: with the leaf's outline drawn.
    std::vector<std::string> warnings;
  };
  // Results kept (the oldest go).
  static constexpr size_t kMaxResults = 50;

  // From the bus. A preview or a restored scan whose image does not decode is the caller's to
  // report; the rest is taken as it comes.
  void OnPreview(const cv::Mat& image, Clock::time_point now);
  void OnFocus(cv::Mat image);
  void OnPatternShown(const pattern_shown_t& m);
  void OnLightPrompt(const light_t& m);
  void OnLightOn(const light_t& m);
  void OnStatus(const status_t& m, Clock::time_point now);
  // `preview`: RESTORED's preview, decoded (empty if it did not decode). Reads the scan's other
  // pictures and its identity from its report on disk.
  void OnRestored(const restored_t& m, const cv::Mat& preview);

  // From the operator. `new_scan_id` names the scan a kScan asks for (the caller's clock: the
  // station's ids are microseconds since the epoch).
  Command Act(Action action, int64_t new_scan_id = 0);
  // Text typed into the form's field (ignored when the form is closed).
  void Type(const std::string& text);
  // A box being dragged over the preview, in fractions of it (drawn; empty when none), and a
  // box dragged to the end: the leaf hint.
  void Dragging(const cv::Rect2d& box) { drag_ = box; }
  void SetHint(const cv::Rect2d& box);

  // Scans restored this session (the last kMaxResults).
  const std::deque<Result>& results() const { return results_; }
  // The result shown (null when none).
  const Result* shown() const;
  int shown_index() const { return shown_; }
  const std::string& progress() const { return progress_; }
  // The warnings and quality verdict of the scan shown (empty when none is shown).
  std::vector<std::string> warnings() const;
  std::string quality() const;
  // The identity the next scan will carry.
  const ScanIdentity& next_identity() const { return next_; }
  // The form's field being edited, or -1 when the form is closed.
  int editing_field() const { return editing_; }
  bool editing() const { return editing_ >= 0; }
  bool sheet() const { return sheet_; }
  bool zoomed() const { return zoom_; }
  // The live preview's leaf: "in view", "off the view" (it touches the border), or why none
  // is outlined; "" before any preview.
  const std::string& preview_leaf() const { return preview_leaf_; }
  // The last preview as shown (8-bit BGR, clipped pixels red, the leaf outlined), its
  // histogram (64 bins of gray), the share clipped, and when it came (never: the epoch).
  const cv::Mat& preview_shown() const { return preview_shown_; }
  const cv::Mat& preview_histogram() const { return preview_hist_; }
  double preview_clipped() const { return preview_clipped_; }
  Clock::time_point preview_at() const { return last_preview_; }
  bool has_preview() const { return !preview_shown_.empty(); }
  // PREVIEW_FOCUS: the view's centre at full resolution (BGR), and its sharpness.
  const cv::Mat& focus() const { return focus_; }
  double focus_sharpness() const { return focus_sharpness_; }
  // The failure of the scan in progress ("" when none): "<process>: <its whole error>".
  const std::string& failure() const { return failure_; }
  int64_t failed_scan() const { return failed_scan_; }
  // The operator's prompt (text "" when none): LIGHT_PROMPT.
  const light_t& prompt() const { return prompt_; }
  const std::string& light_prompt() const { return prompt_.text; }
  // The leaf hint the next scan carries, as fractions of the camera's view; empty when none;
  // and the box being dragged.
  const cv::Rect2d& leaf_hint() const { return hint_; }
  const cv::Rect2d& dragging() const { return drag_; }
  // What the operator says the scans of this sequence are ('o' turns it: auto, leaf, book).
  ObjectKind object() const { return object_; }
  // Each daemon's last status and when it was heard.
  const std::map<std::string, status_t>& statuses() const { return statuses_; }
  Clock::time_point heard(const std::string& process) const;

 private:
  void Started(int64_t scan_id);  // A scan began: a failure shown before is over.
  Command RequestScan(int64_t scan_id);
  Command LightDone();
  void ActInForm(Action action);

  cv::Mat preview_shown_, preview_hist_;
  double preview_clipped_ = 0;
  std::string preview_leaf_;
  Clock::time_point last_preview_;
  cv::Mat focus_;
  double focus_sharpness_ = 0;
  std::string progress_ = "waiting for the station";
  std::map<std::string, status_t> statuses_;
  std::map<std::string, Clock::time_point> seen_;
  std::deque<Result> results_;
  int shown_ = -1;
  ScanIdentity next_;
  ObjectKind object_ = ObjectKind::kAuto;  // The sequence's object, sent with each request.
  std::vector<ScanIdentity> history_;      // The identities of the scans asked for, for undo.
  int editing_ = -1;
  bool sheet_ = false;
  bool zoom_ = false;
  int64_t scan_ = 0;  // The scan in progress (or last asked for).
  int64_t failed_scan_ = 0;
  std::string failure_;
  std::map<std::string, int64_t> error_utime_;  // Each process's last error seen.
  light_t prompt_{};
  cv::Rect2d hint_, drag_;
};

}  // namespace vellum::station
