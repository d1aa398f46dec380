// The viewer's node on an in-process bus with a real SDL window (SDL's dummy video driver): a
// restored scan is listed and drawn, the operator's `s` asks for a scan, the daemons' statuses
// and errors are drawn; a RESTORED whose preview does not decode is reported, and the viewer
// goes on; the operator's sequence is kept in its session file across a restart.
#include "daemons/viewer/viewer_node.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <opencv2/imgproc.hpp>

#include "io/image_file.h"
#include "station/chain.h"
#include "station/daemon.h"
#include "station/messages.h"
#include "station/testing.h"
#include "vellum/light_t.hpp"
#include "vellum/pattern_shown_t.hpp"
#include "vellum/scan_request_t.hpp"
#include "vellum/status_t.hpp"

namespace vellum::station {
namespace {

namespace fs = std::filesystem;
using testing::MemqBus;

class ViewerNodeTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { setenv("SDL_VIDEODRIVER", "dummy", 1); }
  std::unique_ptr<display::Window> Window() {
    display::WindowOptions o;
    o.size = {960, 540};
    return std::make_unique<display::Window>(o);
  }
  restored_t Restored(int64_t id) {
    restored_t m{};
    m.scan_id = id;
    m.view = "orthographic";
    m.dpi = 41;
    m.width = 300;
    m.height = 400;
    m.results = "/nowhere/scan-" + std::to_string(id) + "/results";
    cv::Mat page(400, 300, CV_8UC3, cv::Scalar(200, 220, 240));
    cv::putText(page, "F", cv::Point(80, 300), cv::FONT_HERSHEY_SIMPLEX, 8, cv::Scalar(0, 0, 0),
                20);
    ToMessage(page, &m.preview);
    return m;
  }
  // The station as the viewer hears it when all is well: every daemon's heartbeat and (unless
  // the test sends its own) a camera preview; waits until the viewer would take a scan. The
  // viewer's clock is the bus's, which stands still: they stay heard.
  void StationAlive(const ViewerNode& viewer, bool with_preview = true) {
    auto beat = [&](const char* process) {
      status_t m{};
      m.process = process;
      m.state = "idle";
      bus_.probe().Publish(StatusChannel(process), &m);
    };
    for (const char* p : kGantry) beat(p);
    for (const ChainLink& link : kChain) beat(link.process);
    if (with_preview) {
      image_t preview{};
      ToMessage(cv::Mat(120, 160, CV_8UC3, cv::Scalar(80, 80, 80)), &preview);
      bus_.probe().Publish(channel::kPreview, &preview);
    }
    ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().Refusal(bus_.clock().Now()).empty(); }))
        << viewer.state().Refusal(bus_.clock().Now());
  }
  MemqBus bus_;
};

TEST_F(ViewerNodeTest, ListsRestoredScansAndAsksForAScanOnS) {
  Node node("vellum-viewer", &bus_.lcm(), &bus_.clock());
  display::Window* window = nullptr;
  auto owned = Window();
  window = owned.get();
  ViewerNode viewer(&node, std::move(owned));
  bus_.AddTick([&] { viewer.Tick(); });
  auto requests = bus_.Record<scan_request_t>(channel::kScanRequest);
  bus_.Watch("vellum-viewer");
  restored_t r = Restored(12);
  bus_.probe().Publish(channel::kRestored, &r);
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().results().size() == 1u; }));
  // Once drawn, the viewer's status names the scan on the screen (what the operator waits for).
  ASSERT_TRUE(bus_.RunUntil([&] { return bus_.Status("vellum-viewer").scan_id == 12; }, 10));
  EXPECT_EQ(node.Counter("restored pages shown"), 1);
  EXPECT_NE(viewer.state().progress().find("scan 12: restored, 300x400 at 41 dpi"),
            std::string::npos)
      << viewer.state().progress();
  // The restored page is drawn in the right third: its dark letter shows there.
  ASSERT_TRUE(bus_.RunUntil(
      [&] {
        const cv::Mat screen = window->Screen();
        if (screen.empty()) return false;
        cv::Mat right =
            screen(cv::Rect(screen.cols * 2 / 3, 60, screen.cols / 3 - 10, screen.rows - 80));
        double low = 0;
        cv::minMaxLoc(right.reshape(1), &low);
        return low < 30;
      },
      10));
  StationAlive(viewer);
  SDL_Event key{};
  key.type = SDL_KEYDOWN;
  key.key.keysym.sym = SDLK_s;
  ASSERT_EQ(SDL_PushEvent(&key), 1) << SDL_GetError();
  ASSERT_TRUE(bus_.RunUntil([&] { return !requests->empty(); }, 10));
  EXPECT_GT(requests->back().scan_id, 0);
}

// A restored page is drawn as soon as it comes, not at the next of the viewer's ten draws a
// second, and before the report's pictures beside it are read from disk (they follow at once):
// the test ticks the viewer itself, once to draw, then once right after the page came.
TEST_F(ViewerNodeTest, ARestoredPageIsDrawnAtTheFirstTickAfterItCameAndItsPicturesThen) {
  const fs::path results = fs::path(::testing::TempDir()) / "viewer_first_tick" / "results";
  fs::create_directories(results / "report");
  cv::Mat outline(90, 120, CV_8UC3, cv::Scalar(10, 120, 250));
  ASSERT_TRUE(WriteImage((results / "report" / "outline.png").string(), outline).ok());
  Node node("vellum-viewer", &bus_.lcm(), &bus_.clock());
  ViewerNode viewer(&node, Window());
  viewer.Tick();  // Drawn: the next draw is due a tenth of a second later.
  restored_t r = Restored(14);
  r.results = results.string();
  bus_.probe().Publish(channel::kRestored, &r);
  for (int k = 0; k < 100 && viewer.state().results().empty(); ++k) bus_.lcm().handleTimeout(10);
  ASSERT_EQ(viewer.state().results().size(), 1u);
  EXPECT_TRUE(viewer.state().results().back().texture.empty()) << "read before the page was drawn";
  viewer.Tick();
  EXPECT_EQ(node.Counter("restored pages shown"), 1);
  const cv::Mat& texture = viewer.state().results().back().texture;
  ASSERT_EQ(texture.size(), outline.size());
  EXPECT_EQ(cv::norm(texture, outline, cv::NORM_INF), 0.0);
}

// A doubtful result looks doubtful: its warnings are kept, the header says so, and they are
// written in amber (B 0, G 170, R 255) under the restored page.
TEST_F(ViewerNodeTest, ADoubtfulResultShowsItsWarningsInAmber) {
  Node node("vellum-viewer", &bus_.lcm(), &bus_.clock());
  auto owned = Window();
  display::Window* window = owned.get();
  ViewerNode viewer(&node, std::move(owned));
  bus_.AddTick([&] { viewer.Tick(); });
  restored_t r = Restored(21);
  r.warnings = {"page_cut_off: the leaf runs off the camera's view"};
  r.nwarnings = 1;
  bus_.probe().Publish(channel::kRestored, &r);
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().results().size() == 1u; }));
  ASSERT_EQ(viewer.state().warnings().size(), 1u);
  EXPECT_EQ(viewer.state().warnings()[0].rfind("page_cut_off", 0), 0u);
  EXPECT_NE(viewer.state().progress().find("1 warning(s) under the page"), std::string::npos)
      << viewer.state().progress();
  auto amber = [](const cv::Mat& area) {
    cv::Mat mask;
    cv::inRange(area, cv::Scalar(0, 120, 200), cv::Scalar(60, 200, 255), mask);
    return cv::countNonZero(mask);
  };
  ASSERT_TRUE(bus_.RunUntil(
      [&] {
        const cv::Mat screen = window->Screen();
        if (screen.empty()) return false;
        // The bottom of the right third, under the page, above the film strip.
        const cv::Mat under = screen(cv::Rect(
            screen.cols * 2 / 3, screen.rows - kFilmStripHeight - 40, screen.cols / 3, 40));
        return amber(under) > 20;
      },
      10));
  // A clean result afterwards shows none.
  restored_t clean = Restored(22);
  bus_.probe().Publish(channel::kRestored, &clean);
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().results().size() == 2u; }));
  EXPECT_TRUE(viewer.state().warnings().empty());
}

// Pixels of `area` near `colour` (BGR, within 40 each way).
int Near(const cv::Mat& area, const cv::Scalar& colour) {
  cv::Mat mask;
  cv::inRange(area, colour - cv::Scalar(40, 40, 40), colour + cv::Scalar(40, 40, 40), mask);
  return cv::countNonZero(mask);
}

void PushKey(SDL_Keycode sym) {
  SDL_Event key{};
  key.type = SDL_KEYDOWN;
  key.key.keysym.sym = sym;
  ASSERT_EQ(SDL_PushEvent(&key), 1) << SDL_GetError();
}

void PushText(const std::string& text) {
  SDL_Event e{};
  e.type = SDL_TEXTINPUT;
  std::snprintf(e.text.text, sizeof(e.text.text), "%s", text.c_str());
  ASSERT_EQ(SDL_PushEvent(&e), 1) << SDL_GetError();
}

// The operator types the folio's identity once in the viewer's form; each scan asked
// for carries it and advances the folio (recto, verso, the next recto); u takes the last
// advance back, so the next scan retakes that folio.
TEST_F(ViewerNodeTest, TheFormSetsTheIdentityAndEachScanAdvancesTheFolio) {
  Node node("vellum-viewer", &bus_.lcm(), &bus_.clock());
  ViewerNode viewer(&node, Window());
  bus_.AddTick([&] { viewer.Tick(); });
  auto requests = bus_.Record<scan_request_t>(channel::kScanRequest);
  StationAlive(viewer);
  PushKey(SDLK_e);
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().editing(); }, 10));
  PushText("MS 12");
  PushKey(SDLK_TAB);
  PushText("3");
  PushKey(SDLK_TAB);
  PushText("Recto");    // The side is chosen, not typed: ignored...
  PushKey(SDLK_SPACE);  // ...and chosen: recto.
  PushKey(SDLK_TAB);
  PushText("A. Scribé");    // UTF-8 kept.
  PushKey(SDLK_BACKSPACE);  // One character, both of its bytes.
  PushText("e");
  PushKey(SDLK_s);  // A letter while the form is open: text, not a scan (as SDL sends both).
  PushKey(SDLK_RETURN);
  ASSERT_TRUE(bus_.RunUntil([&] { return !viewer.state().editing(); }, 10));
  EXPECT_EQ(viewer.state().next_identity().shelfmark, "MS 12");
  EXPECT_EQ(viewer.state().next_identity().folio, "3");
  EXPECT_EQ(viewer.state().next_identity().side, "recto");  // Sanitised when the form closes.
  EXPECT_EQ(viewer.state().next_identity().operator_name, "A. Scribe");
  EXPECT_TRUE(requests->empty());
  auto scan = [&](size_t n) {
    PushKey(SDLK_s);
    ASSERT_TRUE(bus_.RunUntil([&] { return requests->size() == n; }, 10));
  };
  scan(1);
  EXPECT_EQ(requests->back().identity.shelfmark, "MS 12");
  EXPECT_EQ(requests->back().identity.folio, "3");
  EXPECT_EQ(requests->back().identity.side, "recto");
  EXPECT_EQ(requests->back().identity.operator_name, "A. Scribe");
  scan(2);
  EXPECT_EQ(requests->back().identity.side, "verso");
  EXPECT_EQ(viewer.state().next_identity().folio, "4");
  EXPECT_EQ(viewer.state().next_identity().side, "recto");
  PushKey(SDLK_u);  // 3 verso again.
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().next_identity().folio == "3"; }, 10));
  scan(3);
  EXPECT_EQ(requests->back().identity.folio, "3");
  EXPECT_EQ(requests->back().identity.side, "verso");
}

// A failed scan looks failed: the header turns red and the daemon's whole message is
// kept (not cut at 70 characters); the next scan clears it. A result's quality verdict shows in
// its colour above the restored page.
TEST_F(ViewerNodeTest, AFailedScanTurnsTheHeaderRedAndTheVerdictShowsInItsColour) {
  Node node("vellum-viewer", &bus_.lcm(), &bus_.clock());
  auto owned = Window();
  display::Window* window = owned.get();
  ViewerNode viewer(&node, std::move(owned));
  bus_.AddTick([&] { viewer.Tick(); });
  status_t st{};
  st.process = "vellum-projector";
  st.pid = 7;
  st.state = "idle";
  bus_.probe().Publish(StatusChannel(st.process), &st);  // Its errors from before: not news.
  pattern_shown_t shown{};
  shown.scan_id = 31;
  shown.pattern_index = -1;
  shown.pattern_count = 54;
  bus_.probe().Publish(channel::kPatternShown, &shown);
  const std::string message =
      "scan 31 failed: no CAPTURE of the texture within 5000 ms (is vellum-camera running, and "
      "on this station's bus?)";
  st.last_error = message;
  st.last_error_utime = 1000;
  st.last_error_scan_id = 31;
  st.errors = 1;
  bus_.probe().Publish(StatusChannel(st.process), &st);
  ASSERT_TRUE(bus_.RunUntil([&] { return !viewer.state().failure().empty(); }, 10));
  EXPECT_EQ(viewer.state().failure(), "vellum-projector: " + message);
  EXPECT_NE(viewer.state().progress().find("scan 31 FAILED"), std::string::npos)
      << viewer.state().progress();
  const cv::Scalar red(40, 40, 220);
  ASSERT_TRUE(bus_.RunUntil(
      [&] {
        const cv::Mat screen = window->Screen();
        return !screen.empty() &&
               Near(screen(cv::Rect(0, 0, screen.cols, 36)), red) > screen.cols * 36 / 2;
      },
      10));
  // The next scan: the failure is over.
  shown.scan_id = 32;
  bus_.probe().Publish(channel::kPatternShown, &shown);
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().failure().empty(); }, 10));
  // A result that failed quality control: a red badge over the restored page.
  restored_t r = Restored(32);
  r.qc = "fail";
  bus_.probe().Publish(channel::kRestored, &r);
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().quality() == "fail"; }, 10));
  EXPECT_NE(viewer.state().progress().find(": FAIL, "), std::string::npos)
      << viewer.state().progress();
  ASSERT_TRUE(bus_.RunUntil(
      [&] {
        const cv::Mat screen = window->Screen();
        return !screen.empty() &&
               Near(screen(cv::Rect(screen.cols * 2 / 3, 44, screen.cols / 3 - 8, 20)), red) >
                   screen.cols / 3 * 10;
      },
      10));
  // The session's contact sheet (c): the result in a red frame over the middle third, where the
  // texture panel was grey.
  PushKey(SDLK_c);
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().sheet(); }, 10));
  ASSERT_TRUE(bus_.RunUntil(
      [&] {
        const cv::Mat screen = window->Screen();
        return !screen.empty() &&
               Near(screen(cv::Rect(screen.cols / 3, 60, screen.cols / 3, 200)), red) > 300;
      },
      10));
}

// The preview shows what clips in red, with a histogram; and "NO SIGNAL" once the
// camera falls silent.
// The leaf being placed is outlined on the live preview, green while it is in view; once it
// runs off the view the outline and a warning turn red; a surround as bright as the leaf gets
// no outline (only the scan can tell them apart), and says so.
TEST_F(ViewerNodeTest, ThePreviewOutlinesTheLeafAndWarnsWhenItRunsOffTheView) {
  Node node("vellum-viewer", &bus_.lcm(), &bus_.clock());
  auto owned = Window();
  display::Window* window = owned.get();
  ViewerNode viewer(&node, std::move(owned));
  bus_.AddTick([&] { viewer.Tick(); });
  const cv::Rect panel(8, 66, 960 / 3 - 12, 150);  // The preview panel's picture.
  auto show = [&](const cv::Rect& leaf, int surround) {
    cv::Mat frame(240, 320, CV_8UC1, cv::Scalar(surround));
    frame(leaf & cv::Rect(0, 0, 320, 240)).setTo(200);
    cv::putText(frame, "f. 3r", leaf.tl() + cv::Point(10, 40), cv::FONT_HERSHEY_SIMPLEX, 0.8,
                cv::Scalar(60), 2);  // Ink on the leaf.
    image_t preview{};
    ToMessage(frame, &preview);
    bus_.probe().Publish(channel::kPreview, &preview);
  };
  const cv::Scalar green(60, 190, 60), red(40, 40, 220);
  show(cv::Rect(80, 50, 150, 140), 40);
  ASSERT_TRUE(bus_.RunUntil(
      [&] {
        const cv::Mat screen = window->Screen();
        return viewer.state().preview_leaf() == "in view" && !screen.empty() &&
               Near(screen(panel), green) > 300 && Near(screen(panel), red) < 20;
      },
      10))
      << viewer.state().preview_leaf();
  show(cv::Rect(200, 50, 150, 140), 40);  // Past the right edge.
  ASSERT_TRUE(bus_.RunUntil(
      [&] {
        const cv::Mat screen = window->Screen();
        return viewer.state().preview_leaf() == "off the view" && !screen.empty() &&
               Near(screen(panel), red) > 300 && Near(screen(panel), green) < 20;
      },
      10))
      << viewer.state().preview_leaf();
  show(cv::Rect(80, 50, 150, 140), 195);  // A support as bright as the leaf.
  ASSERT_TRUE(bus_.RunUntil(
      [&] { return viewer.state().preview_leaf() == "leaf as bright as its surround"; }, 10))
      << viewer.state().preview_leaf();
}

TEST_F(ViewerNodeTest, ThePreviewShowsClippingAndNoSignal) {
  Node node("vellum-viewer", &bus_.lcm(), &bus_.clock());
  auto owned = Window();
  display::Window* window = owned.get();
  ViewerNode viewer(&node, std::move(owned));
  bus_.AddTick([&] { viewer.Tick(); });
  cv::Mat frame(240, 320, CV_8UC1, cv::Scalar(120));
  frame(cv::Rect(0, 0, 160, 240)).setTo(255);  // The left half clips.
  image_t preview{};
  ToMessage(frame, &preview);
  bus_.probe().Publish(channel::kPreview, &preview);
  const cv::Scalar red(0, 0, 255);
  const cv::Rect panel(8, 66, 960 / 3 - 12, 150);  // The preview panel's picture.
  ASSERT_TRUE(bus_.RunUntil(
      [&] {
        const cv::Mat screen = window->Screen();
        return !screen.empty() && Near(screen(panel), red) > 2000;
      },
      10));
  // z: the view's centre at 100%, pixel for pixel: a 200 x 100 white block on black shows as a
  // white block of that size.
  cv::Mat crop(240, 320, CV_8UC1, cv::Scalar(0));
  crop(cv::Rect(60, 70, 200, 100)).setTo(255);
  image_t focus{};
  ToMessage(crop, &focus);
  bus_.probe().Publish(channel::kPreviewFocus, &focus);
  PushKey(SDLK_z);
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().zoomed(); }, 10));
  ASSERT_TRUE(bus_.RunUntil(
      [&] {
        const cv::Mat screen = window->Screen();
        if (screen.empty()) return false;
        cv::Mat gray, white;
        cv::cvtColor(screen(panel), gray, cv::COLOR_BGR2GRAY);
        cv::threshold(gray, white, 250, 255, cv::THRESH_BINARY);
        const cv::Rect block = cv::boundingRect(white);
        return block.width == 200 && block.height == 100;
      },
      10));
  PushKey(SDLK_z);
  ASSERT_TRUE(bus_.RunUntil([&] { return !viewer.state().zoomed(); }, 10));
  ASSERT_TRUE(bus_.RunUntil(  // The preview again, its clipped half red.
      [&] {
        const cv::Mat screen = window->Screen();
        return !screen.empty() && Near(screen(panel), red) > 2000;
      },
      10));
  // Silent for more than 2 s (by the node's clock): NO SIGNAL, written in red over the panel's
  // middle.
  const cv::Scalar text_red(40, 40, 220);
  int before = 0;
  {
    const cv::Mat screen = window->Screen();
    before = Near(screen(panel), text_red);
  }
  bus_.clock().Advance(2.5);
  ASSERT_TRUE(bus_.RunUntil(
      [&] {
        const cv::Mat screen = window->Screen();
        return !screen.empty() && Near(screen(panel), text_red) > before + 200;
      },
      30));
}

TEST_F(ViewerNodeTest, AnUndecodablePreviewIsReportedAndTheViewerGoesOn) {
  Node node("vellum-viewer", &bus_.lcm(), &bus_.clock());
  ViewerNode viewer(&node, Window());
  bus_.AddTick([&] { viewer.Tick(); });
  bus_.Watch("vellum-viewer");
  restored_t bad = Restored(13);
  bad.preview.pixelformat = 0x47504a4d;  // 'MJPG'
  bus_.probe().Publish(channel::kRestored, &bad);
  EXPECT_TRUE(
      bus_.WaitForError("vellum-viewer", "RESTORED of scan 13: preview: image pixel format 'MJPG'"))
      << bus_.Status("vellum-viewer").last_error;
  image_t preview{};
  preview.width = 640;
  preview.height = 480;
  preview.row_stride = 640;
  preview.pixelformat = image_t::PIXEL_FORMAT_GRAY;
  preview.size = 10;
  preview.data.assign(10, 0);
  bus_.probe().Publish(channel::kPreview, &preview);
  EXPECT_TRUE(bus_.WaitForError("vellum-viewer", "PREVIEW: image data is 10 bytes"))
      << bus_.Status("vellum-viewer").last_error;
  restored_t good = Restored(14);
  bus_.probe().Publish(channel::kRestored, &good);
  EXPECT_TRUE(bus_.RunUntil([&] { return viewer.state().results().size() == 2u; }));
}

// Lights switched by hand. vellum-lights' LIGHT_PROMPT shows as a blue box with its
// words; L answers LIGHT_ON for the scan (its session, the light, "operator"), and the box goes.
TEST_F(ViewerNodeTest, AnOperatorPromptedToSwitchALightAnswersWithL) {
  Node node("vellum-viewer", &bus_.lcm(), &bus_.clock());
  auto owned = Window();
  display::Window* window = owned.get();
  ViewerNode viewer(&node, std::move(owned));
  bus_.AddTick([&] { viewer.Tick(); });
  auto on = bus_.Record<light_t>(channel::kLightOn);
  light_t prompt{};
  prompt.scan_id = 31;
  prompt.session = 77;
  prompt.index = 1;
  prompt.light_count = 3;
  prompt.light.name = "raking-120";
  prompt.text = "Switch on the light 'raking-120' and nothing else; then press L in the viewer.";
  bus_.probe().Publish(channel::kLightPrompt, &prompt);
  ASSERT_TRUE(bus_.RunUntil([&] { return !viewer.state().light_prompt().empty(); }));
  EXPECT_NE(viewer.state().light_prompt().find("'raking-120'"), std::string::npos);
  // The box's fill (B 90, G 40, R 10) over the middle of the window.
  ASSERT_TRUE(bus_.RunUntil(
      [&] {
        const cv::Mat screen = window->Screen();
        if (screen.empty()) return false;
        cv::Mat mask;
        cv::inRange(screen, cv::Scalar(80, 30, 0), cv::Scalar(100, 50, 20), mask);
        return cv::countNonZero(mask) > 5000;
      },
      10));
  SDL_Event key{};
  key.type = SDL_KEYDOWN;
  key.key.keysym.sym = SDLK_l;
  ASSERT_EQ(SDL_PushEvent(&key), 1) << SDL_GetError();
  ASSERT_TRUE(bus_.RunUntil([&] { return !on->empty(); }, 10));
  EXPECT_EQ(on->back().scan_id, 31);
  EXPECT_EQ(on->back().session, 77);
  EXPECT_EQ(on->back().index, 1);
  EXPECT_EQ(on->back().light.name, "raking-120");
  EXPECT_EQ(on->back().source, "operator");
  EXPECT_TRUE(viewer.state().light_prompt().empty());
}

// The operator drags a box over the leaf in the preview: it is drawn in cyan, and the next scan
// asks for the leaf there, as fractions of the camera's view (not of the window); h clears it.
// The preview is not square and not placed at the window's corner, so a mapping that forgets
// the panel's offset or its scale fails.
TEST_F(ViewerNodeTest, ABoxDraggedOnThePreviewIsTheNextScansLeafHint) {
  Node node("vellum-viewer", &bus_.lcm(), &bus_.clock());
  auto owned = Window();
  display::Window* window = owned.get();
  ViewerNode viewer(&node, std::move(owned));
  bus_.AddTick([&] { viewer.Tick(); });
  auto requests = bus_.Record<scan_request_t>(channel::kScanRequest);
  image_t preview{};
  ToMessage(cv::Mat(240, 320, CV_8UC1, cv::Scalar(60)), &preview);
  bus_.probe().Publish(channel::kPreview, &preview);
  ASSERT_TRUE(bus_.RunUntil([&] { return !viewer.preview_area().empty(); }, 10));
  StationAlive(viewer, /*with_preview=*/false);
  const cv::Rect at = viewer.preview_area();
  EXPECT_NEAR(static_cast<double>(at.width) / at.height, 320.0 / 240.0, 0.02);
  // From a fifth across and a quarter down to 70% across and 90% down of the camera's view.
  auto point = [&](double fx, double fy) {
    return cv::Point(at.x + cvRound(fx * at.width), at.y + cvRound(fy * at.height));
  };
  auto mouse = [](Uint32 type, cv::Point p) {
    SDL_Event e{};
    e.type = type;
    if (type == SDL_MOUSEMOTION) {
      e.motion.x = p.x;
      e.motion.y = p.y;
      e.motion.state = SDL_BUTTON_LMASK;
    } else {
      e.button.button = SDL_BUTTON_LEFT;
      e.button.x = p.x;
      e.button.y = p.y;
    }
    ASSERT_EQ(SDL_PushEvent(&e), 1) << SDL_GetError();
  };
  mouse(SDL_MOUSEBUTTONDOWN, point(0.2, 0.25));
  mouse(SDL_MOUSEMOTION, point(0.5, 0.5));
  mouse(SDL_MOUSEBUTTONUP, point(0.7, 0.9));
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().leaf_hint().area() > 0; }, 10));
  // Within a screen pixel of the preview (the panel shows 320 px in about 200).
  const double px = 1.0 / at.width, py = 1.0 / at.height;
  EXPECT_NEAR(viewer.state().leaf_hint().x, 0.2, px);
  EXPECT_NEAR(viewer.state().leaf_hint().y, 0.25, py);
  EXPECT_NEAR(viewer.state().leaf_hint().width, 0.5, 2 * px);
  EXPECT_NEAR(viewer.state().leaf_hint().height, 0.65, 2 * py);
  // Drawn in cyan over the preview.
  ASSERT_TRUE(bus_.RunUntil(
      [&] {
        const cv::Mat screen = window->Screen();
        if (screen.empty()) return false;
        cv::Mat mask;
        cv::inRange(screen(at), cv::Scalar(230, 200, 0), cv::Scalar(255, 240, 30), mask);
        return cv::countNonZero(mask) > at.width / 2;
      },
      10));
  PushKey(SDLK_s);
  ASSERT_TRUE(bus_.RunUntil([&] { return requests->size() == 1; }, 10));
  const scan_request_t& r = requests->back();
  EXPECT_NEAR(r.leaf_hint[0], 0.2, px);
  EXPECT_NEAR(r.leaf_hint[1], 0.25, py);
  EXPECT_NEAR(r.leaf_hint[2], 0.5, 2 * px);
  EXPECT_NEAR(r.leaf_hint[3], 0.65, 2 * py);
  // In the camera's pixels of a 1600 x 1200 view, as the decoder turns it into scan.yaml's.
  const cv::Rect pixels = LeafHintPixels(r.leaf_hint, cv::Size(1600, 1200));
  EXPECT_NEAR(pixels.x, 320, 1600 * px);
  EXPECT_NEAR(pixels.br().y, 1080, 1200 * py + 1);
  // The hint stays for the scans after (a book stays where it lies), until h clears it.
  PushKey(SDLK_h);
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().leaf_hint().area() == 0; }, 10));
  PushKey(SDLK_s);
  ASSERT_TRUE(bus_.RunUntil([&] { return requests->size() == 2; }, 10));
  EXPECT_EQ(requests->back().leaf_hint[2], 0.0f);
  EXPECT_TRUE(LeafHintPixels(requests->back().leaf_hint, cv::Size(1600, 1200)).empty());
}

// What the sequence's scans are, as the operator says it: 'o' turns it from auto to a leaf, to
// an open book and back, it stays for the scans after, and every request carries it.
TEST_F(ViewerNodeTest, OSaysWhetherTheScansAreLeavesOrABookAndEachRequestCarriesIt) {
  Node node("vellum-viewer", &bus_.lcm(), &bus_.clock());
  ViewerNode viewer(&node, Window());
  bus_.AddTick([&] { viewer.Tick(); });
  auto requests = bus_.Record<scan_request_t>(channel::kScanRequest);
  StationAlive(viewer);
  EXPECT_EQ(viewer.state().object(), ObjectKind::kAuto);
  PushKey(SDLK_s);
  ASSERT_TRUE(bus_.RunUntil([&] { return requests->size() == 1; }, 10));
  EXPECT_EQ(requests->back().object, "auto");
  PushKey(SDLK_o);
  PushKey(SDLK_o);
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().object() == ObjectKind::kBook; }, 10));
  EXPECT_NE(viewer.state().progress().find("open book"), std::string::npos)
      << viewer.state().progress();
  for (size_t k = 2; k <= 3; ++k) {
    PushKey(SDLK_s);
    ASSERT_TRUE(bus_.RunUntil([&] { return requests->size() == k; }, 10));
    EXPECT_EQ(requests->back().object, "book");
  }
  PushKey(SDLK_o);
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().object() == ObjectKind::kAuto; }, 10));
}

// The operator's sequence outlives the viewer: restarted, it offers the same folio (here the
// retake of one that failed); a session file that does not read is set aside, never lost, and
// the viewer starts afresh.
TEST_F(ViewerNodeTest, ARestartedViewerResumesTheSequenceFromItsSessionFile) {
  const std::string dir = testing::TestDir("viewer_session");
  fs::create_directories(dir);
  ViewerNodeOptions options;
  options.session_file = dir + "/viewer-session.json";
  auto requests = bus_.Record<scan_request_t>(channel::kScanRequest);
  bus_.Watch("vellum-viewer");
  ViewerNode* current = nullptr;  // The viewer running now.
  bus_.AddTick([&] {
    if (current) current->Tick();
  });
  {
    Node node("vellum-viewer", &bus_.lcm(), &bus_.clock());
    ViewerNode viewer(&node, Window(), options);
    current = &viewer;
    StationAlive(viewer);
    PushKey(SDLK_e);
    ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().editing(); }, 10));
    PushText("MS 12");
    PushKey(SDLK_TAB);
    PushText("4");
    PushKey(SDLK_TAB);
    PushKey(SDLK_SPACE);
    PushKey(SDLK_SPACE);  // verso
    PushKey(SDLK_RETURN);
    ASSERT_TRUE(bus_.RunUntil([&] { return !viewer.state().editing(); }, 10));
    PushKey(SDLK_RETURN);  // Enter scans.
    ASSERT_TRUE(bus_.RunUntil([&] { return requests->size() == 1; }, 10));
    EXPECT_EQ(requests->back().identity.side, "verso");
    // The projector fails it.
    status_t failed{};
    failed.process = "vellum-projector";
    failed.state = "idle";
    failed.last_error = "scan " + std::to_string(requests->back().scan_id) +
                        " failed: no CAPTURE of pattern 3 of 40 within 5000 ms";
    failed.last_error_scan_id = requests->back().scan_id;
    failed.last_error_utime = 1;
    bus_.probe().Publish(StatusChannel("vellum-projector"), &failed);
    ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().retake() != nullptr; }, 10));
    EXPECT_NE(viewer.state().FailureNextStep().find("restart vellum-camera"), std::string::npos)
        << viewer.state().FailureNextStep();
    ASSERT_TRUE(bus_.RunUntil(
        [&] {
          return testing::ReadBytes(options.session_file).find("retake") != std::string::npos;
        },
        10));
    PushKey(SDLK_q);  // Quitting asks first...
    ASSERT_TRUE(bus_.RunUntil([&] { return viewer.state().quitting(); }, 10));
    EXPECT_FALSE(node.Stopping());
    PushKey(SDLK_y);  // ...and y quits.
    ASSERT_TRUE(bus_.RunUntil([&] { return node.Stopping(); }, 10));
    current = nullptr;
  }
  {  // Restarted: the retake of 4 verso is offered, as its second attempt.
    Node node("vellum-viewer", &bus_.lcm(), &bus_.clock());
    ViewerNode viewer(&node, Window(), options);
    current = &viewer;
    ASSERT_NE(viewer.state().retake(), nullptr);
    EXPECT_EQ(viewer.state().next_identity().folio, "4");
    EXPECT_EQ(viewer.state().next_identity().side, "verso");
    EXPECT_EQ(viewer.state().NextAttempt(viewer.state().next_identity()), 2);
    StationAlive(viewer);
    PushKey(SDLK_RETURN);
    ASSERT_TRUE(bus_.RunUntil([&] { return requests->size() == 2; }, 10));
    EXPECT_EQ(requests->back().identity.folio, "4");
    EXPECT_EQ(requests->back().identity.side, "verso");
    current = nullptr;
  }
  {  // A session file that does not read: set aside, reported, a fresh sequence.
    std::ofstream(options.session_file) << "{ half a session";
    Node node("vellum-viewer", &bus_.lcm(), &bus_.clock());
    ViewerNode viewer(&node, Window(), options);
    EXPECT_EQ(viewer.state().retake(), nullptr);
    EXPECT_EQ(viewer.state().next_identity(), ScanIdentity());
    EXPECT_EQ(testing::ReadBytes(options.session_file + ".bad"), "{ half a session");
    EXPECT_TRUE(bus_.WaitForError("vellum-viewer", "not taken up"))
        << bus_.Status("vellum-viewer").last_error;
  }
}

TEST(WindowOptions, NonsenseIsRefusedByName) {
  display::WindowOptions o;
  std::string why;
  EXPECT_TRUE(o.Check(&why)) << why;
  o.display = -1;
  EXPECT_FALSE(o.Check(&why));
  EXPECT_NE(why.find("display"), std::string::npos) << why;
}

}  // namespace
}  // namespace vellum::station
