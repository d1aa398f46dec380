// The triangulator's node on an in-process bus: CORRESPONDENCE and CALIBRATION in, the point
// map on disk and POINT_CLOUD out, equal to the triangulate stage run directly; a malformed
// chunk, a calibration of another rig and a scan without calibration are each reported, and the
// node goes on.
#include "daemons/triangulator/triangulator_node.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "io/calibration_io.h"
#include "io/manifest.h"
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
using testing::SmallScanProducts;

class TriangulatorNodeTest : public ::testing::Test {
 protected:
  void SetUp() override { options_.data_dir = testing::TestDir("triangulator_node"); }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(options_.data_dir);
  }
  void PublishCalibration(int64_t id, const Calibration& c) {
    calibration_t m{};
    m.scan_id = id;
    ToMessage(c, &m);
    bus_.probe().Publish(channel::kCalibration, &m);
  }
  std::vector<correspondence_t> Chunks(int64_t id) {
    return ToMessages(id, SmallScanProducts().decoded, SmallScan().sequence.projector_size,
                      ScanContext::Of(SmallScan()), FirstStages(1));
  }
  void PublishChunks(std::vector<correspondence_t> chunks) {
    for (correspondence_t& m : chunks) bus_.probe().Publish(channel::kCorrespondence, &m);
  }

  TriangulatorNodeOptions options_;
  MemqBus bus_;
};

TEST_F(TriangulatorNodeTest, TriangulatesAScanAsTheStageDoesAndHandsItOn) {
  Node node("vellum-triangulator", &bus_.lcm(), &bus_.clock());
  TriangulatorNode triangulator(&node, options_);
  auto clouds = bus_.Record<point_cloud_t>(channel::kPointCloud);
  auto progress = bus_.Record<scan_progress_t>(channel::kScanProgress);
  PublishCalibration(5, QuickRig());
  // The calibration's rays are made as it is heard (while the scan is captured), before any
  // correspondence, and not again for the scan.
  ASSERT_TRUE(bus_.RunUntil([&] { return node.Counter("calibrations' rays made") == 1; }));
  PublishChunks(Chunks(5));
  ASSERT_TRUE(bus_.RunUntil([&] { return !progress->empty(); }));
  EXPECT_EQ(node.Counter("calibrations' rays made"), 1);
  EXPECT_EQ(progress->back().product, "POINT_CLOUD");
  cv::Mat points;
  for (const point_cloud_t& m : *clouds) ASSERT_TRUE(AddChunk(m, &points).ok());
  const cv::Mat& expected = SmallScanProducts().map.points;
  ASSERT_EQ(points.size(), expected.size());
  EXPECT_EQ(std::memcmp(points.data, expected.data, expected.total() * expected.elemSize()), 0);
  const std::string results = ScanFolder::For(options_.data_dir, 5).results();
  EXPECT_EQ(ReadBytes(results + "/points.ply"),
            ReadBytes(SmallScanProducts().results + "/points.ply"));
  std::vector<StageReport> stages;
  ASSERT_TRUE(FromMessages(clouds->back().stages, &stages).ok());
  ASSERT_EQ(stages.size(), 2u);
  EXPECT_EQ(stages[1].stage, "triangulate");
  EXPECT_EQ(stages[1].outputs, SmallScanProducts().stages[1].outputs);
  // Every file it wrote hashed once the points are handed on, in its own record beside the
  // scan's raw/ and results/, for the manifest: the SHA-256 the file has, its size, and its path
  // in the scan's folder.
  const std::string root = ScanFolder::For(options_.data_dir, 5).root;
  const std::string record_path = root + "/" + RecordedHashesName("triangulator");
  ASSERT_TRUE(bus_.RunUntil([&] { return fs::exists(record_path); }));  // Saved whole, renamed.
  std::ifstream record(record_path);
  std::map<std::string, std::string> recorded;  // path -> hash
  for (std::string hex, size, mtime, rel; record >> hex >> size >> mtime >> rel;) {
    recorded[rel] = hex;
    EXPECT_EQ(size, std::to_string(fs::file_size(root + "/" + rel))) << rel;
  }
  EXPECT_EQ(recorded.size(), stages[1].outputs.size());
  for (const std::string& file : stages[1].outputs) {
    std::string hex;
    ASSERT_TRUE(Sha256OfFile(results + "/" + file, &hex).ok()) << file;
    EXPECT_EQ(recorded["results/" + file], hex) << file;
  }
  // The scan's context came without the calibration's part and leaves with it: the points were
  // measured with this calibration. The decoder's count of lit pixels came typed, and judged.
  ScanContext context;
  ASSERT_TRUE(FromMessage(clouds->back().context, &context).ok());
  EXPECT_EQ(context.calibration_sha256, CalibrationSha256(QuickRig()));
  EXPECT_EQ(context.identity.shelfmark, SmallScan().identity.shelfmark);
  const ReportValue* of_lit = FindValue(stages, "pixels", "points_of_lit");
  ASSERT_NE(of_lit, nullptr);
  EXPECT_GT(of_lit->number, 0.5);
  EXPECT_TRUE(bus_.RunUntil(
      [&] { return node.Counter("scans triangulated") == 1; }));  // Counted after it is announced.
}

TEST_F(TriangulatorNodeTest, BadInputIsReportedAndTheNodeGoesOn) {
  Node node("vellum-triangulator", &bus_.lcm(), &bus_.clock());
  TriangulatorNode triangulator(&node, options_);
  bus_.Watch("vellum-triangulator");
  // A chunk whose values do not fill its rows.
  std::vector<correspondence_t> chunks = Chunks(6);
  chunks[0].n -= 1;
  chunks[0].projector_x.pop_back();
  chunks[0].projector_y.pop_back();
  chunks[0].valid.pop_back();
  PublishChunks({chunks[0]});
  EXPECT_TRUE(bus_.WaitForError("vellum-triangulator", "scan 6: CORRESPONDENCE:"))
      << bus_.Status("vellum-triangulator").last_error;
  // The calibration of another rig.
  PublishCalibration(7, DefaultRig());
  PublishChunks(Chunks(7));
  EXPECT_TRUE(bus_.WaitForError("vellum-triangulator", "the calibration is for a 1600x1200"))
      << bus_.Status("vellum-triangulator").last_error;
  // No calibration at all (none on the bus, on disk or configured).
  PublishChunks(Chunks(8));
  EXPECT_TRUE(bus_.WaitForError("vellum-triangulator", "scan 8: no CALIBRATION message"))
      << bus_.Status("vellum-triangulator").last_error;
  EXPECT_EQ(bus_.Status("vellum-triangulator").last_error_scan_id, 8);
  // And a good scan after all that.
  auto progress = bus_.Record<scan_progress_t>(channel::kScanProgress);
  PublishCalibration(9, QuickRig());
  PublishChunks(Chunks(9));
  EXPECT_TRUE(bus_.RunUntil([&] { return !progress->empty(); }));
  EXPECT_TRUE(bus_.RunUntil(
      [&] { return node.Counter("scans triangulated") == 1; }));  // Counted after it is announced.
}

TEST(TriangulatorNodeOptions, NonsenseIsRefusedByName) {
  TriangulatorNodeOptions o;
  std::string why;
  EXPECT_TRUE(o.Check(&why)) << why;
  o.fallback_calibration = Calibration();  // Camera and projector at one point.
  EXPECT_FALSE(o.Check(&why));
  o = TriangulatorNodeOptions();
  o.data_dir.clear();
  EXPECT_FALSE(o.Check(&why));
  EXPECT_NE(why.find("data_dir"), std::string::npos) << why;
}

}  // namespace
}  // namespace vellum::station
