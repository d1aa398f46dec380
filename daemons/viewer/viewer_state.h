// What the operator's window shows and what the operator asked, without the window: the
// station as heard on the bus (the live preview and its leaf, the scan's progress, every
// daemon's heartbeat, the scans restored this session, a failure, a prompt to switch a light)
// and the operator's side (the next scan's identity and its form, the sequence's object, the
// leaf hint, which result is shown, the contact sheet, the zoom). ViewerNode feeds it from the
// bus and the window's keys and mouse; DrawViewer (viewer_draw.h) draws it. It holds no SDL, no
// bus and no clock (the times are given), so that a test drives it alone.
//
// The sequence protects itself: a scan that failed, or whose verdict is FAIL, is offered again
// (a retake of its folio, "attempt 2") before the sequence goes on; a scan is refused, with the
// reason, while the camera sends nothing or a daemon of the station is silent; the side is
// chosen (recto, verso, none: pages), never typed; quitting asks first. The sequence (the next
// identity, the retake offered, the attempts, the object and the leaf hint) is the session:
// SessionJson / LoadSession keep it across restarts (the node writes it beside the data).
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <opencv2/core.hpp>
#include <optional>
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
// The folio and the attempt at it: "MS 12, 4 verso, attempt 2 (retake)" (the first attempt has
// no suffix); "(no identity: press e)".
std::string AttemptTitle(const ScanIdentity& id, int attempt);

class ViewerState {
 public:
  // What the operator can do (ViewerNode maps the keys to these).
  enum class Action {
    kScan,       // s, Enter: ask for a scan of the next identity (a retake offered first).
    kEdit,       // e: open the identity form.
    kSheet,      // c: the session's contact sheet, on or off.
    kObject,     // o: the sequence's object: auto, leaf, book.
    kClearHint,  // h (or a click on the preview): no leaf hint.
    kLightDone,  // l: the light asked for is on (or the lights are off).
    kZoom,       // z: the preview's centre at 100%.
    kUndo,       // u: decline the retake offered, else take the last advance back.
    kPrevious,   // Left: an earlier result.
    kNext,       // Right: a later result.
    kQuit,       // q, Esc: asks first (Esc leaves the contact sheet when it is open).
    kConfirm,    // y: yes, to the question asked (quit).
    kFieldNext,  // In the form: Tab, Down.
    kFieldBack,  // In the form: Up.
    kBackspace,  // In the form: one character off the field.
    kFormDone,   // In the form: Return, Esc.
    kChoose,     // In the form: Space, Left, Right on a field chosen from a list (the side).
  };
  // What an action asks of the bus.
  struct Command {
    enum class Kind { kNone, kQuit, kRequestScan, kLightOn };
    Kind kind = Kind::kNone;
    scan_request_t request{};  // kRequestScan: publish on SCAN_REQUEST.
    light_t light{};           // kLightOn: publish on LIGHT_ON.
  };
  // A scan asked for: its identity and which attempt at it this is (1, 2 for the first retake).
  struct Asked {
    ScanIdentity identity;
    int attempt = 1;
  };
  // A scan restored this session, as shown.
  struct Result {
    int64_t scan_id = 0;
    ScanIdentity identity;  // From the request (or its report); empty when it had none.
    int attempt = 1;
    std::string summary;  // "300x400 at 41 dpi".
    std::string results, quality;
    // The identity from its report with the attempt ("MS 12, 3 recto, attempt 2 (retake)"), or
    // the scan id.
    std::string title;
    cv::Mat texture, depth, strain, restored;  // texture: with the leaf's outline drawn.
    bool pictures_pending = false;             // texture, depth and strain not read yet.
    std::vector<std::string> warnings;
  };
  // Results kept (the oldest go).
  static constexpr size_t kMaxResults = 50;
  // A scan of this session that failed before it was restored.
  struct Failed {
    int64_t scan_id = 0;
    ScanIdentity identity;
    int attempt = 1;
    std::string why;  // "<process>: <its error>".
  };
  // One tile of the session's contact sheet: a restored scan or a failed one.
  struct SheetEntry {
    const Result* result = nullptr;  // Else:
    const Failed* failed = nullptr;
    int index = -1;  // The result's place in results() (-1 for a failed scan).
  };

  // From the bus. A preview or a restored scan whose image does not decode is the caller's to
  // report; the rest is taken as it comes.
  // `of_capture`: the frame of a scan's capture (PREVIEW with a scan id), which shows a pattern:
  // it says the camera is alive, and never replaces the live view.
  void OnPreview(const cv::Mat& image, Clock::time_point now, bool of_capture = false);
  void OnFocus(cv::Mat image);
  void OnPatternShown(const pattern_shown_t& m);
  void OnLightPrompt(const light_t& m);
  void OnLightOn(const light_t& m);
  void OnStatus(const status_t& m, Clock::time_point now);
  // `preview`: RESTORED's preview, decoded (empty if it did not decode). Reads the scan's
  // identity from its report on disk, and its other pictures unless `read_pictures` is false:
  // then ReadPendingPictures reads them (the viewer draws the restored page first).
  void OnRestored(const restored_t& m, const cv::Mat& preview, bool read_pictures = true);
  // Reads the pictures OnRestored left; whether there were any.
  bool ReadPendingPictures();

  // From the operator, at `now` (what the station was last heard to be then). `new_scan_id`
  // names the scan a kScan asks for (the station's ids are microseconds since the epoch).
  Command Act(Action action, int64_t new_scan_id = 0, Clock::time_point now = {});
  // Why a scan cannot be asked for at `now` ("" when it can): the camera sends nothing (no
  // preview for 2 s), or a daemon of the station is silent (not heard for 3 s).
  std::string Refusal(Clock::time_point now) const;
  // The sequence as JSON (the session file), and back; false (with *why) for a session that
  // does not read, which leaves the state as it was.
  std::string SessionJson() const;
  bool LoadSession(const std::string& json, std::string* why);
  // Text typed into the form's field (ignored when the form is closed, and in a field chosen
  // from a list).
  void Type(const std::string& text);
  // A box being dragged over the preview, in fractions of it (drawn; empty when none), and a
  // box dragged to the end: the leaf hint.
  void Dragging(const cv::Rect2d& box) { drag_ = box; }
  void SetHint(const cv::Rect2d& box);

  // Scans restored this session (the last kMaxResults), and those that failed before.
  const std::deque<Result>& results() const { return results_; }
  const std::deque<Failed>& failed() const { return failed_; }
  // The session's scans in book order: by shelfmark, then folio (its number, then its text),
  // recto before verso, then attempt; a failed scan in its folio's place.
  std::vector<SheetEntry> SheetInBookOrder() const;
  // The result shown (null when none).
  const Result* shown() const;
  int shown_index() const { return shown_; }
  const std::string& progress() const { return progress_; }
  // The warnings and quality verdict of the scan shown (empty when none is shown).
  std::vector<std::string> warnings() const;
  std::string quality() const;
  // The identity the next scan will carry: the folio to retake when one is offered, else the
  // sequence's next.
  const ScanIdentity& next_identity() const { return retake_ ? *retake_ : next_; }
  // The sequence's next identity (what the form edits; after a retake, the sequence goes on here).
  const ScanIdentity& sequence_next() const { return next_; }
  // The retake offered (null when none), and why.
  const ScanIdentity* retake() const { return retake_ ? &*retake_ : nullptr; }
  const std::string& retake_why() const { return retake_why_; }
  // Which attempt at `identity` the next scan of it will be (1 for the first).
  int NextAttempt(const ScanIdentity& identity) const;
  // The scan in progress or last asked for, and what was asked (null when not this session's).
  int64_t scan() const { return scan_; }
  const Asked* asked(int64_t scan_id) const;
  // Quitting was asked and awaits y.
  bool quitting() const { return quitting_; }
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
  // The projector is running a scan's patterns: the live view is held at its last frame from
  // before them (the camera's frames show the patterns, not the leaf as it lies).
  bool capturing() const { return capturing_; }
  // PREVIEW_FOCUS: the view's centre at full resolution (BGR), and its sharpness.
  const cv::Mat& focus() const { return focus_; }
  double focus_sharpness() const { return focus_sharpness_; }
  // The sharpest seen since the 100% view was last opened: the peak to turn the focus ring to.
  double focus_peak() const { return focus_peak_; }
  // The failure of the scan in progress ("" when none): "<process>: <its whole error>".
  const std::string& failure() const { return failure_; }
  int64_t failed_scan() const { return failed_scan_; }
  // What the failed scan is ("MS 12, 4 verso, attempt 2 (retake)", or "scan <id>"), and what
  // the operator does next ("the camera stopped: restart vellum-camera, then Enter to retake
  // MS 12, 4 verso").
  std::string FailedTitle() const;
  std::string FailureNextStep() const;
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
  void Started(int64_t scan_id);        // A scan began: a failure and the result shown before go.
  static void ReadPictures(Result* r);  // Its report's pictures, if pending.
  // A scan of this session failed (or FAILed): its folio is offered again first.
  void OfferRetake(int64_t scan_id, const std::string& why);
  Command RequestScan(int64_t scan_id, Clock::time_point now);
  Command LightDone();
  void ActInForm(Action action);

  cv::Mat preview_shown_, preview_hist_;
  double preview_clipped_ = 0;
  bool capturing_ = false;
  std::string preview_leaf_;
  int preview_off_view_ = 0;  // ViewSide bits where the live outline runs off the view.
  Clock::time_point last_preview_;
  cv::Mat focus_;
  double focus_sharpness_ = 0;
  double focus_peak_ = 0;
  std::string progress_ = "waiting for the station";
  std::map<std::string, status_t> statuses_;
  std::map<std::string, Clock::time_point> seen_;
  std::deque<Result> results_;
  std::deque<Failed> failed_;
  int shown_ = -1;
  ScanIdentity next_;
  ObjectKind object_ = ObjectKind::kAuto;  // The sequence's object, sent with each request.
  std::vector<ScanIdentity> history_;      // The identities of the scans asked for, for undo.
  std::optional<ScanIdentity> retake_;     // A folio to scan again before the sequence goes on.
  std::string retake_why_;
  std::map<std::string, int> attempts_;  // Scans asked of each identity (by IdentitySlug).
  std::map<int64_t, Asked> asked_;       // The session's scans (the last kMaxResults * 4).
  bool quitting_ = false;
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
