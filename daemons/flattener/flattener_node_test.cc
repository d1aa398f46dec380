// The flattener's node on an in-process bus: POINT_CLOUD, TEXTURE and CALIBRATION in, the
// flattened sheet on disk and FLAT_MESH out, equal to the mesh and flatten stages run directly;
// a scan whose texture never came, a texture of another size and a malformed chunk are each
// reported, and the node goes on.
#include "daemons/flattener/flattener_node.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <opencv2/imgproc.hpp>

#include "station/daemon.h"
#include "station/scan_store.h"
#include "station/testing.h"
#include "vellum/scan_progress_t.hpp"

namespace vellum::station {
namespace {

namespace fs = std::filesystem;
using testing::FirstStages;
using testing::MemqBus;
using testing::ReadBytes;
using testing::SmallScan;
using testing::SmallScanContext;
using testing::SmallScanProducts;

class FlattenerNodeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    options_.data_dir = testing::TestDir("flattener_node");
    options_.fallback_calibration = QuickRig();
  }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(options_.data_dir);
  }
  void PublishTexture(int64_t id, const cv::Mat& texture) {
    for (texture_t& m : TextureMessages(id, texture)) bus_.probe().Publish(channel::kTexture, &m);
  }
  void PublishPoints(int64_t id) {
    for (point_cloud_t& m : ToMessages(id, SmallScanProducts().map.points, cv::Mat(),
                                       SmallScanContext(), FirstStages(2))) {
      bus_.probe().Publish(channel::kPointCloud, &m);
    }
  }

  FlattenerNodeOptions options_;
  MemqBus bus_;
};

TEST_F(FlattenerNodeTest, FlattensTheSheetAsTheStagesDoAndHandsItOn) {
  Node node("vellum-flattener", &bus_.lcm(), &bus_.clock());
  FlattenerNode flattener(&node, options_);
  auto sheets = bus_.Record<mesh_t>(channel::kFlatMesh);
  auto progress = bus_.Record<scan_progress_t>(channel::kScanProgress);
  PublishTexture(5, SmallScan().texture);
  PublishPoints(5);
  ASSERT_TRUE(bus_.RunUntil([&] { return !progress->empty(); }));
  EXPECT_EQ(progress->back().product, "FLAT_MESH");
  Mesh mesh;
  FlattenResult flat;
  SheetPage page;
  for (const mesh_t& m : *sheets) ASSERT_TRUE(AddChunk(m, &mesh, &flat, &page).ok());
  EXPECT_EQ(flat.flat, SmallScanProducts().flat.flat);
  EXPECT_EQ(flat.mean_strain, SmallScanProducts().flat.mean_strain);
  EXPECT_EQ(flat.max_strain, SmallScanProducts().flat.max_strain);
  // The scan's context passes on as it came.
  ScanContext context;
  ASSERT_TRUE(FromMessage(sheets->back().context, &context).ok());
  EXPECT_EQ(context.calibration_sha256, SmallScanContext().calibration_sha256);
  EXPECT_EQ(mesh.point, SmallScanProducts().mesh.point);
  EXPECT_EQ(cv::norm(page.mask, SmallScanProducts().outline.pages[0], cv::NORM_INF), 0);
  EXPECT_EQ(page.count, 1);
  std::vector<StageReport> stages;
  ASSERT_TRUE(FromMessages(sheets->back().stages, &stages).ok());
  ASSERT_EQ(stages.size(), 5u);
  EXPECT_EQ(stages[2].stage, "outline");
  EXPECT_EQ(stages[3].stage, "mesh");
  EXPECT_EQ(stages[4].stage, "flatten");
  EXPECT_TRUE(fs::exists(ScanFolder::For(options_.data_dir, 5).results() + "/flat.ply"));
  EXPECT_TRUE(bus_.RunUntil(
      [&] { return node.Counter("scans flattened") == 1; }));  // Counted after it is announced.
}

// The report's picture of the texture is written as the texture comes, before the scan's
// points, as the outline stage writes it, and listed among the outline stage's files.
TEST_F(FlattenerNodeTest, TheTexturesPictureIsWrittenAsTheTextureComes) {
  Node node("vellum-flattener", &bus_.lcm(), &bus_.clock());
  FlattenerNode flattener(&node, options_);
  auto sheets = bus_.Record<mesh_t>(channel::kFlatMesh);
  const std::string results = ScanFolder::For(options_.data_dir, 5).results();
  PublishTexture(5, SmallScan().texture);
  // Written whole (a temporary name, then renamed), with no point of the scan yet.
  ASSERT_TRUE(bus_.RunUntil([&] { return fs::exists(results + "/report/texture.png"); }));
  EXPECT_TRUE(sheets->empty());
  const std::string early = ReadBytes(results + "/report/texture.png");
  PublishPoints(5);
  ASSERT_TRUE(bus_.RunUntil([&] { return !sheets->empty(); }));
  std::vector<StageReport> stages;
  ASSERT_TRUE(FromMessages(sheets->back().stages, &stages).ok());
  ASSERT_EQ(stages[2].stage, "outline");
  const std::vector<std::string>& files = stages[2].outputs;
  EXPECT_NE(std::find(files.begin(), files.end(), "report/texture.png"), files.end());
  EXPECT_NE(std::find(files.begin(), files.end(), "report/outline.png"), files.end());
  // The picture the outline stage itself writes of the same texture.
  const std::string own = testing::TestDir("flattener_node_own");
  ASSERT_TRUE(WriteTexturePicture(own, SmallScan().texture).ok());
  EXPECT_GT(early.size(), 1000u);
  EXPECT_TRUE(early == ReadBytes(own + "/report/texture.png"));
  EXPECT_TRUE(ReadBytes(results + "/report/texture.png") == early);
  fs::remove_all(own);
}

TEST_F(FlattenerNodeTest, BadInputIsReportedAndTheNodeGoesOn) {
  Node node("vellum-flattener", &bus_.lcm(), &bus_.clock());
  FlattenerNode flattener(&node, options_);
  bus_.Watch("vellum-flattener");
  PublishPoints(6);  // No TEXTURE for scan 6, and none on disk.
  EXPECT_TRUE(bus_.WaitForError("vellum-flattener", "scan 6: its texture (TEXTURE) never arrived"))
      << bus_.Status("vellum-flattener").last_error;
  cv::Mat small;
  cv::resize(SmallScan().texture, small, cv::Size(200, 150));
  PublishTexture(7, small);
  PublishPoints(7);
  EXPECT_TRUE(
      bus_.WaitForError("vellum-flattener", "the texture is 200x150, the point map 400x300"))
      << bus_.Status("vellum-flattener").last_error;
  point_cloud_t bad = ToMessages(8, SmallScanProducts().map.points, cv::Mat(), SmallScanContext(),
                                 FirstStages(2))[0];
  bad.nxyz -= 1;
  bad.xyz.pop_back();
  bus_.probe().Publish(channel::kPointCloud, &bad);
  EXPECT_TRUE(bus_.WaitForError("vellum-flattener", "POINT_CLOUD: nxyz is not a multiple of 3"))
      << bus_.Status("vellum-flattener").last_error;
  auto progress = bus_.Record<scan_progress_t>(channel::kScanProgress);
  PublishTexture(9, SmallScan().texture);
  PublishPoints(9);
  EXPECT_TRUE(bus_.RunUntil([&] { return !progress->empty(); }));
  EXPECT_TRUE(bus_.RunUntil(
      [&] { return node.Counter("scans flattened") == 1; }));  // Counted after it is announced.
}

TEST(FlattenerNodeOptions, NonsenseIsRefusedByName) {
  FlattenerNodeOptions o;
  std::string why;
  EXPECT_TRUE(o.Check(&why)) << why;
  o.pipeline.outline.unseen_clear_mm = 0;
  EXPECT_FALSE(o.Check(&why));
  EXPECT_NE(why.find("unseen_clear_mm"), std::string::npos) << why;
  o = FlattenerNodeOptions();
  o.data_dir.clear();
  EXPECT_FALSE(o.Check(&why));
  EXPECT_THROW(RequireValid(o), UsageError);
}

}  // namespace
}  // namespace vellum::station
