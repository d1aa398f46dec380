// The viewer's node on an in-process bus with a real SDL window (SDL's dummy video driver): a
// restored scan is listed and drawn, the operator's `s` asks for a scan, the daemons' statuses
// and errors are drawn; a RESTORED whose preview does not decode is reported, and the viewer
// goes on.
#include "daemons/viewer/viewer_node.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <opencv2/imgproc.hpp>

#include "station/messages.h"
#include "station/testing.h"
#include "vellum/scan_request_t.hpp"

namespace vellum::station {
namespace {

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
  MemqBus bus_;
};

TEST_F(ViewerNodeTest, ListsRestoredScansAndAsksForAScanOnS) {
  Node node("vellum-viewer", &bus_.lcm());
  display::Window* window = nullptr;
  auto owned = Window();
  window = owned.get();
  ViewerNode viewer(&node, std::move(owned));
  bus_.AddTick([&] { viewer.Tick(); });
  auto requests = bus_.Record<scan_request_t>(channel::kScanRequest);
  restored_t r = Restored(12);
  bus_.probe().Publish(channel::kRestored, &r);
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.results() == 1; }));
  EXPECT_NE(viewer.progress().find("scan 12: 300x400 41 dpi restored"), std::string::npos)
      << viewer.progress();
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
  SDL_Event key{};
  key.type = SDL_KEYDOWN;
  key.key.keysym.sym = SDLK_s;
  ASSERT_EQ(SDL_PushEvent(&key), 1) << SDL_GetError();
  ASSERT_TRUE(bus_.RunUntil([&] { return !requests->empty(); }, 10));
  EXPECT_GT(requests->back().scan_id, 0);
}

// A doubtful result looks doubtful: its warnings are kept, the header says so, and they are
// written in amber (B 0, G 170, R 255) under the restored page.
TEST_F(ViewerNodeTest, ADoubtfulResultShowsItsWarningsInAmber) {
  Node node("vellum-viewer", &bus_.lcm());
  auto owned = Window();
  display::Window* window = owned.get();
  ViewerNode viewer(&node, std::move(owned));
  bus_.AddTick([&] { viewer.Tick(); });
  restored_t r = Restored(21);
  r.warnings = {"page_cut_off: the leaf runs off the camera's view"};
  r.nwarnings = 1;
  bus_.probe().Publish(channel::kRestored, &r);
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.results() == 1; }));
  ASSERT_EQ(viewer.warnings().size(), 1u);
  EXPECT_EQ(viewer.warnings()[0].rfind("page_cut_off", 0), 0u);
  EXPECT_NE(viewer.progress().find("with 1 warning(s)"), std::string::npos) << viewer.progress();
  auto amber = [](const cv::Mat& area) {
    cv::Mat mask;
    cv::inRange(area, cv::Scalar(0, 120, 200), cv::Scalar(60, 200, 255), mask);
    return cv::countNonZero(mask);
  };
  ASSERT_TRUE(bus_.RunUntil(
      [&] {
        const cv::Mat screen = window->Screen();
        if (screen.empty()) return false;
        // The bottom of the right third, under the page.
        const cv::Mat under =
            screen(cv::Rect(screen.cols * 2 / 3, screen.rows - 40, screen.cols / 3, 40));
        return amber(under) > 20;
      },
      10));
  // A clean result afterwards shows none.
  restored_t clean = Restored(22);
  bus_.probe().Publish(channel::kRestored, &clean);
  ASSERT_TRUE(bus_.RunUntil([&] { return viewer.results() == 2; }));
  EXPECT_TRUE(viewer.warnings().empty());
}

TEST_F(ViewerNodeTest, AnUndecodablePreviewIsReportedAndTheViewerGoesOn) {
  Node node("vellum-viewer", &bus_.lcm());
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
  EXPECT_TRUE(bus_.RunUntil([&] { return viewer.results() == 2; }));
}

}  // namespace
}  // namespace vellum::station
