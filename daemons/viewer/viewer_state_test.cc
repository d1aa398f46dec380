// The viewer's state and its picture without a window or a bus: the operator's actions and what
// they ask of the bus, the identity form, a failure and what clears it, the light prompt, the
// results stepped through, and the picture's layout and its NO SIGNAL, at times the test gives.
#include "daemons/viewer/viewer_state.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <opencv2/imgproc.hpp>

#include "daemons/viewer/viewer_draw.h"
#include "io/image_file.h"
#include "station/chain.h"
#include "station/testing.h"

namespace vellum::station {
namespace {

using Action = ViewerState::Action;
using Kind = ViewerState::Command::Kind;
namespace fs = std::filesystem;

// A heartbeat of `process`, with its last error (about scan `scan`, at `utime`).
status_t Status(const std::string& process, const std::string& error = "", int64_t scan = 0,
                int64_t utime = 0) {
  status_t m{};
  m.process = process;
  m.state = "idle";
  m.last_error = error;
  m.last_error_scan_id = scan;
  m.last_error_utime = utime;
  return m;
}

// The station heard at `now`: a camera preview and every daemon's heartbeat.
void Alive(ViewerState* v, Clock::time_point now) {
  v->OnPreview(cv::Mat(60, 80, CV_8UC3, cv::Scalar(90, 90, 90)), now);
  for (const char* p : kGantry) v->OnStatus(Status(p), now);
  for (const ChainLink& link : kChain) v->OnStatus(Status(link.process), now);
}

// The operator names the next folio in the form: each text field cleared and typed, the side
// chosen (Space) until it is `side`.
void NameFolio(ViewerState* v, const std::string& shelfmark, const std::string& folio,
               const std::string& side) {
  v->Act(Action::kEdit);
  for (const std::string* text : {&shelfmark, &folio}) {
    const FormField& field = IdentityForm()[v->editing_field()];
    while (!(v->sequence_next().*field.field).empty()) v->Act(Action::kBackspace);
    v->Type(*text);
    v->Act(Action::kFieldNext);
  }
  while (v->sequence_next().side != side) v->Act(Action::kChoose);
  v->Act(Action::kFormDone);
}

// An identity of MS 12: folio and side.
ScanIdentity Folio(const std::string& folio, const std::string& side) {
  ScanIdentity id;
  id.shelfmark = "MS 12";
  id.folio = folio;
  id.side = side;
  return id;
}

restored_t Restored(int64_t id, const std::string& qc) {
  restored_t m{};
  m.scan_id = id;
  m.view = "orthographic";
  m.dpi = 300;
  m.width = 30;
  m.height = 40;
  m.qc = qc;
  m.results = "/nowhere/scan-" + std::to_string(id) + "/results";
  return m;
}

// The panels beside the restored page come from the scan's report pictures, read side by side:
// the outline (else the bare texture), the depth map, the strain (a spread's left page's).
TEST(ViewerState, ThePanelsAreTheScansReportPictures) {
  const std::string results = testing::TestDir("viewer_panels");
  fs::create_directories(fs::path(results) / "report");
  auto picture = [](int rows, int cols, int seed) {
    cv::Mat m(rows, cols, CV_8UC3);
    cv::randu(m, cv::Scalar::all(0), cv::Scalar::all(256 - seed));
    return m;
  };
  const cv::Mat texture = picture(30, 40, 1), depth = picture(31, 41, 2),
                strain = picture(32, 42, 3);
  auto write = [&](const char* name, const cv::Mat& m) {
    ASSERT_TRUE(WriteImage((fs::path(results) / "report" / name).string(), m).ok());
  };
  write("texture.png", texture);
  write("depth.png", depth);
  write("strain-left.png", strain);
  ViewerState v;
  restored_t m = Restored(61, "pass");
  m.results = results;
  v.OnRestored(m, cv::Mat());
  const ViewerState::Result& r = v.results().back();
  ASSERT_EQ(r.texture.size(), texture.size());
  EXPECT_EQ(cv::norm(r.texture, texture, cv::NORM_INF), 0);
  ASSERT_EQ(r.depth.size(), depth.size());
  EXPECT_EQ(cv::norm(r.depth, depth, cv::NORM_INF), 0);
  ASSERT_EQ(r.strain.size(), strain.size());
  EXPECT_EQ(cv::norm(r.strain, strain, cv::NORM_INF), 0);
  // With its outline drawn, the outline is shown instead; a scan without a report has none.
  const cv::Mat outline = picture(33, 43, 4);
  write("outline.png", outline);
  v.OnRestored(m, cv::Mat());
  EXPECT_EQ(v.results().back().texture.size(), outline.size());
  v.OnRestored(Restored(62, "pass"), cv::Mat());
  EXPECT_TRUE(v.results().back().texture.empty());
  EXPECT_TRUE(v.results().back().depth.empty());
}

TEST(ViewerState, TheFormSetsTheIdentityEachScanAdvancesItAndUndoTakesTheAdvanceBack) {
  ViewerState v;
  const Clock::time_point now = Clock::Steady().Now();
  Alive(&v, now);
  EXPECT_EQ(v.Act(Action::kEdit).kind, Kind::kNone);
  ASSERT_TRUE(v.editing());
  v.Type("MS 12");
  v.Act(Action::kFieldNext);
  v.Type("3");
  v.Act(Action::kFieldNext);
  v.Type("rceto");  // The side is chosen, not typed: a typo cannot switch the numbering.
  EXPECT_EQ(v.sequence_next().side, "");
  v.Act(Action::kChoose);
  EXPECT_EQ(v.sequence_next().side, "recto");
  v.Act(Action::kChoose);
  v.Act(Action::kChoose);
  EXPECT_EQ(v.sequence_next().side, "");  // None: pages.
  v.Act(Action::kChoose);
  v.Act(Action::kFieldNext);
  v.Type("A. Scribé");
  v.Act(Action::kBackspace);  // One character: both bytes of the é.
  v.Type("e");
  EXPECT_EQ(v.Act(Action::kScan, 7, now).kind, Kind::kNone) << "the form has the keyboard";
  EXPECT_EQ(v.Act(Action::kQuit).kind, Kind::kNone) << "Esc closes the form, never the viewer";
  v.Act(Action::kFormDone);
  ASSERT_FALSE(v.editing());
  EXPECT_EQ(v.next_identity().side, "recto");
  EXPECT_EQ(v.next_identity().operator_name, "A. Scribe");

  v.Act(Action::kObject);  // auto -> leaf
  const ViewerState::Command first = v.Act(Action::kScan, 101, now);
  ASSERT_EQ(first.kind, Kind::kRequestScan);
  EXPECT_EQ(first.request.scan_id, 101);
  EXPECT_EQ(first.request.identity.shelfmark, "MS 12");
  EXPECT_EQ(first.request.identity.folio, "3");
  EXPECT_EQ(first.request.identity.side, "recto");
  EXPECT_EQ(first.request.object, "leaf");
  EXPECT_EQ(v.next_identity().side, "verso");
  EXPECT_EQ(v.Act(Action::kScan, 102, now).request.identity.side, "verso");
  EXPECT_EQ(v.next_identity().folio, "4");
  v.Act(Action::kUndo);
  EXPECT_EQ(v.next_identity().folio, "3");
  EXPECT_EQ(v.next_identity().side, "verso");
  EXPECT_EQ(v.NextAttempt(v.next_identity()), 2);
  EXPECT_NE(v.progress().find("next scan again: MS 12, 3 verso"), std::string::npos)
      << v.progress();
  EXPECT_EQ(v.Act(Action::kScan, 103, now).kind, Kind::kRequestScan);
  EXPECT_NE(v.progress().find("MS 12, 3 verso, attempt 2 (retake)"), std::string::npos)
      << v.progress();
}

// After a failure or a FAIL, the next scan offered is the retake of that folio, never the next
// folio; after the retake the sequence goes on where it was. u goes on without it.
TEST(ViewerState, AFolioThatFailedIsOfferedAgainBeforeTheSequenceGoesOn) {
  ViewerState v;
  const Clock::time_point now = Clock::Steady().Now();
  Alive(&v, now);
  NameFolio(&v, "MS 12", "4", "recto");
  ASSERT_EQ(v.Act(Action::kScan, 41, now).request.identity.side, "recto");
  ASSERT_EQ(v.Act(Action::kScan, 42, now).request.identity.side, "verso");  // 4v: it fails.
  v.OnStatus(Status("vellum-decoder", "", 0, 10), now);  // Heard before: its errors from now on.
  v.OnStatus(Status("vellum-decoder", "scan 42 failed: no capture for 30 s", 42, 20), now);
  ASSERT_NE(v.retake(), nullptr);
  EXPECT_EQ(v.next_identity().folio, "4");
  EXPECT_EQ(v.next_identity().side, "verso");
  EXPECT_EQ(v.FailedTitle(), "MS 12, 4 verso");
  EXPECT_NE(v.FailureNextStep().find("Enter to retake MS 12, 4 verso"), std::string::npos)
      << v.FailureNextStep();
  const ViewerState::Command retake = v.Act(Action::kScan, 43, now);
  ASSERT_EQ(retake.kind, Kind::kRequestScan);
  EXPECT_EQ(retake.request.identity.folio, "4");
  EXPECT_EQ(retake.request.identity.side, "verso");
  EXPECT_EQ(v.asked(43)->attempt, 2);
  EXPECT_EQ(v.failure(), "") << "the retake began";
  EXPECT_EQ(v.next_identity().folio, "5");
  EXPECT_EQ(v.next_identity().side, "recto");
  // 5r restored with the verdict FAIL: 5r offered again; u goes on without it, to 5v.
  EXPECT_EQ(v.Act(Action::kScan, 51, now).request.identity.folio, "5");
  v.OnRestored(Restored(51, "fail"), cv::Mat());
  ASSERT_NE(v.retake(), nullptr);
  EXPECT_EQ(v.retake()->side, "recto");
  EXPECT_EQ(v.results().back().title, "MS 12, 5 recto");
  v.Act(Action::kUndo);
  EXPECT_EQ(v.retake(), nullptr);
  EXPECT_EQ(v.next_identity().side, "verso");
  EXPECT_EQ(v.next_identity().folio, "5");
}

// s is refused, with the reason, while the camera sends nothing or a daemon is silent.
TEST(ViewerState, AScanIsRefusedWhileTheCameraSendsNothingOrADaemonIsSilent) {
  ViewerState v;
  const Clock::time_point t0 = Clock::Steady().Now();
  EXPECT_EQ(v.Act(Action::kScan, 1, t0).kind, Kind::kNone);
  EXPECT_NE(v.progress().find("scan refused: the camera sends nothing"), std::string::npos)
      << v.progress();
  Alive(&v, t0);
  EXPECT_EQ(v.Refusal(t0 + Seconds(1.5)), "");
  EXPECT_NE(v.Refusal(t0 + Seconds(2.5)).find("no preview for 2 s"), std::string::npos);
  // The camera goes on; the restorer falls silent.
  v.OnPreview(cv::Mat(60, 80, CV_8UC3, cv::Scalar(90, 90, 90)), t0 + Seconds(4));
  for (const char* p : kGantry) v.OnStatus(Status(p), t0 + Seconds(4));
  for (const ChainLink& link : kChain) {
    if (std::string(link.process) != "vellum-restorer")
      v.OnStatus(Status(link.process), t0 + Seconds(4));
  }
  EXPECT_EQ(v.Act(Action::kScan, 2, t0 + Seconds(4)).kind, Kind::kNone);
  EXPECT_NE(v.progress().find("vellum-restorer is silent (4 s): restart it"), std::string::npos)
      << v.progress();
  v.OnStatus(Status("vellum-restorer"), t0 + Seconds(4));
  EXPECT_EQ(v.Act(Action::kScan, 3, t0 + Seconds(4)).kind, Kind::kRequestScan);
}

TEST(ViewerState, QuittingAsksFirstAndEscLeavesTheContactSheet) {
  ViewerState v;
  v.Act(Action::kSheet);
  EXPECT_EQ(v.Act(Action::kQuit).kind, Kind::kNone);
  EXPECT_FALSE(v.sheet());
  EXPECT_FALSE(v.quitting());
  EXPECT_EQ(v.Act(Action::kQuit).kind, Kind::kNone);
  EXPECT_TRUE(v.quitting());
  EXPECT_EQ(v.Act(Action::kSheet).kind, Kind::kNone) << "any other key stays";
  EXPECT_FALSE(v.quitting());
  EXPECT_FALSE(v.sheet()) << "and does nothing else";
  v.Act(Action::kQuit);
  EXPECT_EQ(v.Act(Action::kConfirm).kind, Kind::kQuit);
}

// The sequence (next folio, the retake offered, the attempts, the object, the hint) read back
// from its session is the same sequence; a session that does not read changes nothing.
TEST(ViewerState, TheSessionCarriesTheSequenceAcrossARestart) {
  ViewerState v;
  const Clock::time_point now = Clock::Steady().Now();
  Alive(&v, now);
  NameFolio(&v, "MS 12", "4", "recto");
  v.Act(Action::kObject);
  v.SetHint(cv::Rect2d(0.1, 0.2, 0.3, 0.4));
  v.Act(Action::kScan, 41, now);
  v.Act(Action::kScan, 42, now);
  v.OnStatus(Status("vellum-decoder", "", 0, 10), now);
  v.OnStatus(Status("vellum-decoder", "scan 42 failed: disk full", 42, 20), now);
  ASSERT_NE(v.retake(), nullptr);

  ViewerState restarted;
  std::string why;
  ASSERT_TRUE(restarted.LoadSession(v.SessionJson(), &why)) << why;
  EXPECT_EQ(restarted.next_identity(), v.next_identity());
  ASSERT_NE(restarted.retake(), nullptr);
  EXPECT_EQ(restarted.retake_why(), v.retake_why());
  EXPECT_EQ(restarted.sequence_next(), Folio("5", "recto"));
  EXPECT_EQ(restarted.NextAttempt(Folio("4", "verso")), 2);
  EXPECT_EQ(restarted.object(), ObjectKind::kLeaf);
  EXPECT_EQ(restarted.leaf_hint(), cv::Rect2d(0.1, 0.2, 0.3, 0.4));
  EXPECT_EQ(restarted.SessionJson(), v.SessionJson());

  for (const std::string& bad : {std::string("{"), std::string("{\"version\": 2}"),
                                 std::string("{\"version\": 1, \"object\": \"scroll\"}"),
                                 std::string("{\"version\": 1, \"leaf_hint\": [1, 2]}")}) {
    ViewerState fresh;
    const std::string before = fresh.SessionJson();
    EXPECT_FALSE(fresh.LoadSession(bad, &why)) << bad;
    EXPECT_FALSE(why.empty());
    EXPECT_EQ(fresh.SessionJson(), before) << bad;
  }
}

// A new scan clears the result shown (it is not this scan's); Left shows it again.
TEST(ViewerState, ANewScanClearsTheResultShown) {
  ViewerState v;
  const Clock::time_point now = Clock::Steady().Now();
  Alive(&v, now);
  v.OnRestored(Restored(1, "pass"), cv::Mat());
  ASSERT_NE(v.shown(), nullptr);
  v.Act(Action::kScan, 2, now);
  EXPECT_EQ(v.shown(), nullptr);
  v.Act(Action::kPrevious);  // Nothing shown: stays.
  v.Act(Action::kNext);
  EXPECT_EQ(v.shown()->scan_id, 1);
}

// A leaf hint dragged on the preview travels with every scan asked for, until it is cleared.
TEST(ViewerState, TheLeafHintRidesEveryRequestUntilCleared) {
  ViewerState v;
  const Clock::time_point now = Clock::Steady().Now();
  Alive(&v, now);
  v.SetHint(cv::Rect2d(0.2, 0.25, 0.5, 0.9));  // Beyond the view's bottom: cut to it.
  const ViewerState::Command c = v.Act(Action::kScan, 5, now);
  EXPECT_FLOAT_EQ(c.request.leaf_hint[0], 0.2f);
  EXPECT_FLOAT_EQ(c.request.leaf_hint[1], 0.25f);
  EXPECT_FLOAT_EQ(c.request.leaf_hint[2], 0.5f);
  EXPECT_FLOAT_EQ(c.request.leaf_hint[3], 0.75f);
  v.Act(Action::kClearHint);
  EXPECT_EQ(v.Act(Action::kScan, 6, now).request.leaf_hint[2], 0);
}

// What the live view saw at the edge rides the scan asked for: a bright leaf on a dark table
// running off the right edge is "right" (not "left": the test leaf is asymmetric), one wholly in
// view is "", and so is a view where the live outline cannot tell the leaf.
TEST(ViewerState, WhereTheLiveViewSawTheLeafRunOffRidesTheRequest) {
  ViewerState v;
  const Clock::time_point now = Clock::Steady().Now();
  Alive(&v, now);
  cv::Mat preview(120, 160, CV_8UC3, cv::Scalar(40, 40, 40));
  cv::rectangle(preview, cv::Rect(100, 30, 60, 70), cv::Scalar(220, 220, 220), cv::FILLED);
  v.OnPreview(preview, now);
  EXPECT_EQ(v.preview_leaf(), "off the view");
  EXPECT_EQ(v.Act(Action::kScan, 5, now).request.live_off_view, "right");
  preview.setTo(cv::Scalar(40, 40, 40));
  cv::rectangle(preview, cv::Rect(40, 30, 60, 70), cv::Scalar(220, 220, 220), cv::FILLED);
  v.OnPreview(preview, now);
  EXPECT_EQ(v.preview_leaf(), "in view");
  EXPECT_EQ(v.Act(Action::kScan, 6, now).request.live_off_view, "");
  v.OnPreview(cv::Mat(120, 160, CV_8UC3, cv::Scalar(40, 40, 40)), now);  // No leaf.
  EXPECT_EQ(v.Act(Action::kScan, 7, now).request.live_off_view, "");
  v.OnPreview(cv::Mat(3, 2, CV_8UC3, cv::Scalar(220, 220, 220)), now);  // Too small to tell.
  EXPECT_EQ(v.preview_leaf(), "no leaf in view");
  EXPECT_EQ(v.Act(Action::kScan, 8, now).request.live_off_view, "");
}

// A new error about the scan in progress is its failure; an old error (heard first), an error
// about another scan, or one without a scan is not; the next scan's first pattern clears it.
TEST(ViewerState, AFailureIsTheScanInProgressesAndTheNextScanClearsIt) {
  ViewerState v;
  const Clock::time_point t0 = Clock::Steady().Now();
  v.OnStatus(Status("vellum-decoder", "scan 3: old news", 3, 100), t0);
  EXPECT_EQ(v.failure(), "");
  Alive(&v, t0);
  v.Act(Action::kScan, 10, t0);
  v.OnStatus(Status("vellum-decoder", "scan 9: another scan", 9, 200), t0);
  EXPECT_EQ(v.failure(), "");
  v.OnStatus(Status("vellum-decoder", "no scan named", 0, 300), t0);
  EXPECT_EQ(v.failure(), "");
  v.OnStatus(Status("vellum-decoder", "scan 10 failed: no capture for 30 s", 10, 400), t0);
  EXPECT_EQ(v.failure(), "vellum-decoder: scan 10 failed: no capture for 30 s");
  EXPECT_EQ(v.failed_scan(), 10);
  EXPECT_NE(v.progress().find("scan 10 FAILED"), std::string::npos) << v.progress();
  pattern_shown_t next{};
  next.scan_id = 11;
  next.pattern_index = -1;
  v.OnPatternShown(next);
  EXPECT_EQ(v.failure(), "");
  EXPECT_EQ(v.progress(), "scan 11: texture");
}

TEST(ViewerState, APromptedLightIsAnsweredOnceAndTheLightsOffPromptIsOnlyDismissed) {
  ViewerState v;
  EXPECT_EQ(v.Act(Action::kLightDone).kind, Kind::kNone);  // Nothing asked.
  light_t prompt{};
  prompt.scan_id = 4;
  prompt.index = 1;
  prompt.light.name = "raking-120";
  prompt.text = "Switch on the light 'raking-120'";
  v.OnLightPrompt(prompt);
  const ViewerState::Command on = v.Act(Action::kLightDone);
  ASSERT_EQ(on.kind, Kind::kLightOn);
  EXPECT_EQ(on.light.scan_id, 4);
  EXPECT_EQ(on.light.index, 1);
  EXPECT_EQ(on.light.source, "operator");
  EXPECT_EQ(on.light.text, "");
  EXPECT_EQ(v.light_prompt(), "");
  EXPECT_EQ(v.Act(Action::kLightDone).kind, Kind::kNone);
  prompt.index = -1;  // All off, at the end.
  prompt.text = "";
  v.OnLightPrompt(prompt);
  EXPECT_EQ(v.light_prompt(), "(vellum-lights asks, with no words)");
  EXPECT_EQ(v.Act(Action::kLightDone).kind, Kind::kNone);
  EXPECT_EQ(v.light_prompt(), "");
}

// While the projector runs a scan's patterns the live view holds its last frame from before
// them (the camera's frames show stripes, not the leaf); the camera still counts as alive; once
// the projector is no longer scanning, the live view goes on.
TEST(ViewerState, TheLiveViewIsHeldWhileThePatternsRun) {
  ViewerState v;
  const Clock::time_point t0 = Clock::Steady().Now();
  v.OnPreview(cv::Mat(60, 80, CV_8UC3, cv::Scalar(90, 90, 90)), t0);
  const cv::Mat before = v.preview_shown().clone();
  pattern_shown_t shown{};
  shown.scan_id = 7;
  shown.pattern_index = 3;
  shown.pattern_count = 40;
  v.OnPatternShown(shown);
  ASSERT_TRUE(v.capturing());
  v.OnPreview(cv::Mat(60, 80, CV_8UC3, cv::Scalar(255, 255, 255)), t0 + Seconds(3));  // Stripes.
  EXPECT_EQ(cv::norm(v.preview_shown(), before, cv::NORM_INF), 0) << "the live frame is held";
  EXPECT_EQ(v.preview_at(), t0 + Seconds(3)) << "and the camera is alive";
  status_t scanning = Status("vellum-projector");
  scanning.state = "scanning";
  v.OnStatus(scanning, t0 + Seconds(3));
  EXPECT_TRUE(v.capturing());
  // Drawn dimmed as often as the window redraws, the held frame itself stays as it was.
  ViewerLayout layout;
  for (int k = 0; k < 5; ++k) DrawViewer(v, cv::Size(960, 540), t0 + Seconds(3), &layout);
  EXPECT_EQ(cv::norm(v.preview_shown(), before, cv::NORM_INF), 0) << "the held frame was dimmed";
  v.OnStatus(Status("vellum-projector"), t0 + Seconds(4));  // Idle: the scan is captured.
  EXPECT_FALSE(v.capturing());
  // The last capture's frame, come after the projector went idle: still not the live view.
  v.OnPreview(cv::Mat(60, 80, CV_8UC3, cv::Scalar(0, 0, 0)), t0 + Seconds(4), true);
  EXPECT_EQ(cv::norm(v.preview_shown(), before, cv::NORM_INF), 0);
  v.OnPreview(cv::Mat(60, 80, CV_8UC3, cv::Scalar(30, 30, 30)), t0 + Seconds(5));
  EXPECT_GT(cv::norm(v.preview_shown(), before, cv::NORM_INF), 0);
}

// The session's sheet in book order whatever the order scanned: 3 recto, 3 verso (failed, then
// retaken), 10 recto; a failed scan in its folio's place.
TEST(ViewerState, TheSessionSheetIsInBookOrderWithFailuresInTheirPlace) {
  ViewerState v;
  const Clock::time_point now = Clock::Steady().Now();
  Alive(&v, now);
  v.OnStatus(Status("vellum-decoder", "", 0, 1), now);
  auto scan = [&](int64_t id, const std::string& folio, const std::string& side) {
    NameFolio(&v, "", folio, side);
    ASSERT_EQ(v.Act(Action::kScan, id, now).kind, Kind::kRequestScan);
  };
  scan(1, "10", "recto");
  v.OnRestored(Restored(1, "pass"), cv::Mat());
  scan(2, "3", "verso");
  v.OnStatus(Status("vellum-decoder", "scan 2 failed: no capture for 30 s", 2, 2), now);
  ASSERT_EQ(v.Act(Action::kScan, 3, now).request.identity.folio, "3");  // The retake.
  v.OnRestored(Restored(3, "pass"), cv::Mat());
  scan(4, "3", "recto");
  v.OnRestored(Restored(4, "warn"), cv::Mat());
  const std::vector<ViewerState::SheetEntry> sheet = v.SheetInBookOrder();
  ASSERT_EQ(sheet.size(), 4u);
  auto id = [](const ViewerState::SheetEntry& e) {
    return e.result ? e.result->scan_id : e.failed->scan_id;
  };
  EXPECT_EQ(id(sheet[0]), 4);  // 3 recto
  EXPECT_EQ(id(sheet[1]), 2);  // 3 verso, failed
  ASSERT_NE(sheet[1].failed, nullptr);
  EXPECT_NE(sheet[1].failed->why.find("no capture"), std::string::npos);
  EXPECT_EQ(id(sheet[2]), 3);  // 3 verso, attempt 2
  EXPECT_EQ(sheet[2].result->title, "3 verso, attempt 2 (retake)");
  EXPECT_EQ(id(sheet[3]), 1);  // 10 recto
}

// The focus meter holds the sharpest frame seen since the 100% view was opened.
TEST(ViewerState, TheFocusMeterHoldsItsPeakUntilTheViewIsOpenedAgain) {
  ViewerState v;
  cv::Mat sharp(120, 160, CV_8U, cv::Scalar(0));
  for (int x = 0; x < sharp.cols; x += 4) sharp.col(x).setTo(255);
  cv::Mat soft;
  cv::GaussianBlur(sharp, soft, cv::Size(0, 0), 2);
  v.Act(Action::kZoom);
  v.OnFocus(soft);
  const double low = v.focus_sharpness();
  v.OnFocus(sharp);
  const double high = v.focus_sharpness();
  ASSERT_GT(high, 4 * low);
  v.OnFocus(soft);
  EXPECT_EQ(v.focus_peak(), high);
  EXPECT_EQ(v.focus_sharpness(), low);
  v.Act(Action::kZoom);
  v.Act(Action::kZoom);  // Opened again: the peak starts from the present.
  EXPECT_EQ(v.focus_peak(), low);
}

TEST(ViewerState, ResultsAreSteppedThroughAndTheNewestIsShown) {
  ViewerState v;
  for (int k = 1; k <= 3; ++k) v.OnRestored(Restored(k, k == 2 ? "fail" : "pass"), cv::Mat());
  EXPECT_EQ(v.shown()->scan_id, 3);
  EXPECT_EQ(v.results().front().title, "scan 1");  // No report on disk: the scan id.
  v.Act(Action::kPrevious);
  EXPECT_EQ(v.quality(), "fail");
  v.Act(Action::kPrevious);
  v.Act(Action::kPrevious);
  EXPECT_EQ(v.shown()->scan_id, 1);
  v.Act(Action::kNext);
  v.Act(Action::kNext);
  v.Act(Action::kNext);
  EXPECT_EQ(v.shown()->scan_id, 3);
  for (int k = 4; k <= 60; ++k) v.OnRestored(Restored(k, "pass"), cv::Mat());
  EXPECT_EQ(v.results().size(), ViewerState::kMaxResults);
  EXPECT_EQ(v.results().front().scan_id, 60 - static_cast<int>(ViewerState::kMaxResults) + 1);
}

// The picture: the preview in the left third, where the layout says, with the leaf hint drawn
// over it where it lies; NO SIGNAL once the camera was silent for more than 2 s by the time
// given, not before.
// The film strip under the results: the session's scans in book order, not the order scanned
// (10 recto, then 3 verso failed, then 3 recto warn), each framed in its verdict's colour: amber
// for 3r, red for 3v's failure, green for 10r; none before the first scan.
TEST(ViewerDraw, TheFilmStripShowsTheSessionInBookOrderInItsVerdictsColours) {
  ViewerState v;
  const Clock::time_point now = Clock::Steady().Now();
  Alive(&v, now);
  const cv::Size size(1280, 720);
  ViewerLayout layout;
  DrawViewer(v, size, now, &layout);
  EXPECT_TRUE(layout.strip.empty());
  v.OnStatus(Status("vellum-decoder", "", 0, 1), now);
  auto scan = [&](int64_t id, const std::string& folio, const std::string& side) {
    NameFolio(&v, "MS 12", folio, side);
    ASSERT_EQ(v.Act(Action::kScan, id, now).kind, Kind::kRequestScan);
  };
  const cv::Mat page(40, 30, CV_8UC3, cv::Scalar(200, 200, 200));
  scan(1, "10", "recto");
  v.OnRestored(Restored(1, "pass"), page);
  scan(2, "3", "verso");
  v.OnStatus(Status("vellum-decoder", "scan 2 failed: no capture for 30 s", 2, 2), now);
  v.Act(Action::kUndo);  // Decline the retake.
  scan(3, "3", "recto");
  v.OnRestored(Restored(3, "warn"), page);
  const cv::Mat drawn = DrawViewer(v, size, now, &layout);
  ASSERT_EQ(layout.strip.size(), 3u);
  for (size_t k = 1; k < layout.strip.size(); ++k) {
    EXPECT_GT(layout.strip[k].x, layout.strip[k - 1].x);
  }
  EXPECT_GE(layout.strip[0].x, size.width / 3);       // Under the results, not the preview.
  EXPECT_GT(layout.strip[0].y, size.height * 3 / 4);  // Along the bottom.
  // The frame's colour: a pixel on each tile's left edge, half way down.
  auto frame = [&](const cv::Rect& cell) {
    return drawn.at<cv::Vec3b>(cell.y + cell.height / 2, cell.x + 1);
  };
  const cv::Vec3b amber(0, 170, 255), red(40, 40, 220), green(60, 190, 60);
  EXPECT_EQ(frame(layout.strip[0]), amber) << "3 recto, warn";
  EXPECT_EQ(frame(layout.strip[1]), red) << "3 verso, failed";
  EXPECT_EQ(frame(layout.strip[2]), green) << "10 recto, pass";
}

TEST(ViewerDraw, ThePreviewIsWhereTheLayoutSaysAndNoSignalFollowsTheTimeGiven) {
  ViewerState v;
  const Clock::time_point t0 = Clock::Steady().Now();
  cv::Mat preview(240, 320, CV_8UC3, cv::Scalar(60, 60, 60));
  v.OnPreview(preview, t0);
  v.SetHint(cv::Rect2d(0.5, 0.5, 0.25, 0.25));  // The lower right quarter's corner only.
  const cv::Size size(960, 540);
  ViewerLayout layout;
  const cv::Mat fresh = DrawViewer(v, size, t0 + Seconds(1), &layout);
  ASSERT_EQ(fresh.size(), size);
  ASSERT_FALSE(layout.preview.empty());
  EXPECT_LE(layout.preview.br().x, size.width / 3);
  EXPECT_NEAR(static_cast<double>(layout.preview.width) / layout.preview.height, 320.0 / 240, 0.02);
  // The hint's cyan in the preview's lower right, none in its upper left.
  auto cyan = [&](const cv::Mat& image, cv::Rect r) {
    cv::Mat near;
    cv::inRange(image(r), cv::Scalar(235, 200, 0), cv::Scalar(255, 240, 30), near);
    return cv::countNonZero(near);
  };
  const cv::Rect at = layout.preview;
  const cv::Rect upper_left(at.x, at.y, at.width / 2 - 2, at.height / 2 - 2);
  const cv::Rect lower_right(at.x + at.width / 2 - 2, at.y + at.height / 2 - 2, at.width / 2 + 2,
                             at.height / 2 + 2);
  EXPECT_EQ(cyan(fresh, upper_left), 0);
  EXPECT_GT(cyan(fresh, lower_right), at.width / 4);
  // NO SIGNAL (red text over the preview) 3 s after the preview, not 1 s after.
  auto red = [&](const cv::Mat& image) {
    cv::Mat near;
    cv::inRange(image(at), cv::Scalar(30, 30, 200), cv::Scalar(50, 50, 240), near);
    return cv::countNonZero(near);
  };
  const cv::Mat silent = DrawViewer(v, size, t0 + Seconds(3), &layout);
  EXPECT_EQ(red(fresh), 0);
  EXPECT_GT(red(silent), 200);
  // Zoomed, the preview is not drawn (and a drag cannot begin on it).
  v.Act(Action::kZoom);
  DrawViewer(v, size, t0 + Seconds(1), &layout);
  EXPECT_TRUE(layout.preview.empty());
}

// The draws scale each picture once and keep it while it is shown (ten draws a second share the
// cores with the chain): a new preview of the same size and kind (gray, as a mono camera sends
// it) is drawn as itself, not as the last one's picture, and the page shown is drawn again from
// what was scaled, the same pixels.
TEST(ViewerDraw, ANewPictureIsDrawnAsItselfAndAPictureShownAgainIsTheSame) {
  ViewerState v;
  const Clock::time_point t0 = Clock::Steady().Now();
  const cv::Size size(960, 540);
  ViewerLayout layout;
  auto mean_of_preview = [&](const cv::Mat& drawn) { return cv::mean(drawn(layout.preview))[1]; };
  v.OnPreview(cv::Mat(240, 320, CV_8UC1, cv::Scalar(40)), t0);
  const cv::Mat dark = DrawViewer(v, size, t0, &layout);
  ASSERT_FALSE(layout.preview.empty());
  v.OnPreview(cv::Mat(240, 320, CV_8UC1, cv::Scalar(200)), t0);
  const cv::Mat light = DrawViewer(v, size, t0, &layout);
  EXPECT_LT(mean_of_preview(dark), 60);
  EXPECT_GT(mean_of_preview(light), 180) << "the last preview's scaled picture was drawn again";
  const cv::Mat again = DrawViewer(v, size, t0, &layout);
  EXPECT_EQ(cv::norm(light, again, cv::NORM_INF), 0);
}

}  // namespace
}  // namespace vellum::station
