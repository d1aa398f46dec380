// The restorer's node on an in-process bus: FLAT_MESH, TEXTURE and CALIBRATION in, the restored
// page and the scan's report on disk and RESTORED out, equal to the restore stage run directly,
// with report.json holding every stage's report; a sheet with an unknown node kind is reported,
// and the node goes on.
#include "daemons/restorer/restorer_node.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/common/text.h"
#include "station/daemon.h"
#include "station/scan_log.h"
#include "station/scan_store.h"
#include "station/testing.h"
#include "vellum/restored_t.hpp"

namespace vellum::station {
namespace {

namespace fs = std::filesystem;
using testing::FirstStages;
using testing::MemqBus;
using testing::ReadBytes;
using testing::SmallScan;
using testing::SmallScanContext;
using testing::SmallScanProducts;

class RestorerNodeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    options_.data_dir = testing::TestDir("restorer_node");
    options_.fallback_calibration = QuickRig();
  }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(options_.data_dir);
  }
  std::vector<mesh_t> Sheet(int64_t id) {
    const auto& p = SmallScanProducts();
    SheetPage page;
    page.mask = p.outline.pages[0];
    return ToMessages(id, p.mesh, MeshOptions().bend_springs, p.flat, SmallScanContext(),
                      FirstStages(5), page);
  }
  void Publish(int64_t id, std::vector<mesh_t> sheet) {
    for (texture_t& m : TextureMessages(id, SmallScan().texture)) {
      bus_.probe().Publish(channel::kTexture, &m);
    }
    for (mesh_t& m : sheet) bus_.probe().Publish(channel::kFlatMesh, &m);
  }

  RestorerNodeOptions options_;
  MemqBus bus_;
};

TEST_F(RestorerNodeTest, RestoresThePageAsTheStageDoesAndWritesTheWholeReport) {
  Node node("vellum-restorer", &bus_.lcm(), &bus_.clock());
  RestorerNode restorer(&node, options_);
  auto restored = bus_.Record<restored_t>(channel::kRestored);
  Publish(5, Sheet(5));
  ASSERT_TRUE(bus_.RunUntil([&] { return !restored->empty(); }));
  const std::string results = ScanFolder::For(options_.data_dir, 5).results();
  EXPECT_EQ(restored->back().results, results);
  for (const char* file : {"restored.tif", "restored_mask.png", "restored.json"}) {
    EXPECT_EQ(ReadBytes(results + "/" + file), ReadBytes(SmallScanProducts().results + "/" + file))
        << file;
  }
  EXPECT_GT(restored->back().preview.width, 100);
  std::ifstream in(results + "/report.json");
  const nlohmann::json report = nlohmann::json::parse(in);
  for (const char* stage : {"decode", "triangulate", "outline", "mesh", "flatten", "restore"}) {
    EXPECT_TRUE(report["stages_seconds"].contains(stage)) << stage;
  }
  EXPECT_EQ(report["options"]["decoder"], "phase");
  EXPECT_EQ(report["options"]["grid"], "auto");
  EXPECT_EQ(report["sheet"]["grid"],
            SizeText(cv::Size(SmallScanProducts().mesh.cols, SmallScanProducts().mesh.rows)));
  EXPECT_EQ(report["scan"], ScanFolder::For(options_.data_dir, 5).raw());
  // Every file it lists was written, the report's own included.
  ASSERT_TRUE(report["outputs"].is_array());
  for (const auto& file : report["outputs"]) {
    const std::string name = file.get<std::string>();
    const bool here = fs::exists(results + "/" + name);
    const bool upstream = name == "points.ply" || name == "depth.png" || name == "mesh.ply" ||
                          name == "flat.ply" || name == "report/valid.png" ||
                          name == "report/depth.png" || name == "report/texture.png" ||
                          name == "report/outline.png";  // Written by the stages before it.
    EXPECT_TRUE(here || upstream) << name;
  }
  EXPECT_NE(std::find(report["outputs"].begin(), report["outputs"].end(), "report.html"),
            report["outputs"].end());
  EXPECT_TRUE(bus_.RunUntil(
      [&] { return node.Counter("scans restored") == 1; }));  // Counted after it is announced.
}

// The archival master needs only the texture and the scan's identity: begun when both are here,
// while the scan is still captured, before any page; written once, as the archive stage writes
// it. A scan whose start this process did not hear gets it with its first page.
TEST_F(RestorerNodeTest, TheArchivalMasterIsWrittenFromTheTextureBeforeAnyPage) {
  Node node("vellum-restorer", &bus_.lcm(), &bus_.clock());
  RestorerNode restorer(&node, options_);
  auto restored = bus_.Record<restored_t>(channel::kRestored);
  scan_started_t started = MakeScanStarted(SmallScan(), 8, 1);
  bus_.probe().Publish(channel::kScanStarted, &started);
  const std::string master = ScanFolder::For(options_.data_dir, 8).results() + "/archival.tif";
  Publish(8, {});  // The texture alone, after the start (as on the bus).
  ASSERT_TRUE(bus_.RunUntil([&] { return fs::exists(master); }));  // Written whole, renamed.
  EXPECT_EQ(node.Counter("archival masters begun at the texture"), 1);
  EXPECT_TRUE(restored->empty());
  for (mesh_t& m : Sheet(8)) bus_.probe().Publish(channel::kFlatMesh, &m);
  ASSERT_TRUE(bus_.RunUntil([&] { return !restored->empty(); }));
  EXPECT_EQ(node.Counter("archival masters written again"), 0);
  // No start heard: with the first page.
  Publish(9, Sheet(9));
  ASSERT_TRUE(bus_.RunUntil([&] { return restored->size() == 2; }));
  EXPECT_EQ(node.Counter("archival masters begun at the texture"), 1);
  // The same master either way: the identity SCAN_STARTED gave is the scan's.
  const std::string with_page =
      ReadBytes(ScanFolder::For(options_.data_dir, 9).results() + "/archival.tif");
  EXPECT_GT(with_page.size(), 1000u);
  EXPECT_TRUE(ReadBytes(master) == with_page);
}

TEST_F(RestorerNodeTest, BadInputIsReportedAndTheNodeGoesOn) {
  Node node("vellum-restorer", &bus_.lcm(), &bus_.clock());
  RestorerNode restorer(&node, options_);
  bus_.Watch("vellum-restorer");
  std::vector<mesh_t> bad = Sheet(6);
  bad[0].kind[3] = 9;
  Publish(6, bad);
  EXPECT_TRUE(bus_.WaitForError("vellum-restorer", "FLAT_MESH: node 3 has unknown kind 9"))
      << bus_.Status("vellum-restorer").last_error;
  // A page mask claiming 65535 x 65535 pixels (4 GB, found by fuzz_messages): refused before
  // it is allocated.
  std::vector<mesh_t> huge = Sheet(9);
  for (mesh_t& m : huge) m.mask_width = m.mask_height = 65535;
  Publish(9, huge);
  EXPECT_TRUE(bus_.WaitForError("vellum-restorer", "FLAT_MESH: bad page mask (65535x65535"))
      << bus_.Status("vellum-restorer").last_error;
  std::vector<mesh_t> no_report = Sheet(7);
  for (mesh_t& m : no_report) m.stages[0].stage = "";
  Publish(7, no_report);
  EXPECT_TRUE(bus_.WaitForError("vellum-restorer", "a stage report without a stage name"))
      << bus_.Status("vellum-restorer").last_error;
  auto restored = bus_.Record<restored_t>(channel::kRestored);
  Publish(8, Sheet(8));
  EXPECT_TRUE(bus_.RunUntil([&] { return !restored->empty(); }));
  EXPECT_TRUE(bus_.RunUntil(
      [&] { return node.Counter("scans restored") == 1; }));  // Counted after it is announced.
}

// With a studio field the reflectance is made from the point map, which the restorer hears as
// the flattener does: a page that comes before it waits for it, and is restored when it comes.
// With a flat field, a point map without the projector's light is refused by name, and counted
// as a product lost (the decoder's supervisor makes the scan again). Each restorer says on its
// status whether it wants the light: only one with a flat field does.
TEST_F(RestorerNodeTest, WithAFieldAPageWaitsForItsPointMapAndIsRestoredWhenItComes) {
  const Calibration rig = QuickRig();
  StudioField studio;
  studio.camera_size = rig.camera.size;
  studio.gain = cv::Mat(cv::Size(rig.camera.size.width / 8 + 1, rig.camera.size.height / 8 + 1),
                        CV_32FC(SmallScan().texture.channels()), cv::Scalar::all(250.0));
  studio.lamps = {cv::Vec3d(-450, -250, 500), cv::Vec3d(450, -250, 500)};
  options_.pipeline.studio_field = studio;
  Node node("vellum-restorer", &bus_.lcm(), &bus_.clock());
  RestorerNode restorer(&node, options_);
  bus_.Watch("vellum-restorer");
  auto restored = bus_.Record<restored_t>(channel::kRestored);
  Publish(9, Sheet(9));
  ASSERT_TRUE(bus_.RunUntil([&] {
    return bus_.Status("vellum-restorer").detail.find("waiting for the point map") !=
           std::string::npos;
  })) << bus_.Status("vellum-restorer").detail;
  EXPECT_TRUE(restored->empty());
  for (point_cloud_t& m : ToMessages(9, SmallScanProducts().map.points, cv::Mat(),
                                     SmallScanContext(), FirstStages(2))) {
    bus_.probe().Publish(channel::kPointCloud, &m);
  }
  ASSERT_TRUE(bus_.RunUntil([&] { return !restored->empty(); }));
  const std::string results = ScanFolder::For(options_.data_dir, 9).results();
  EXPECT_TRUE(fs::exists(results + "/restored_reflectance.tif"));
  EXPECT_EQ(ReadBytes(results + "/restored.tif"),
            ReadBytes(SmallScanProducts().results + "/restored.tif"));

  // A flat field asks for the projector's light too; this point map came without it.
  RestorerNodeOptions with_flat = options_;
  with_flat.pipeline.studio_field = StudioField();
  with_flat.pipeline.flat_field.projector_size = rig.projector.size;
  with_flat.pipeline.flat_field.gain = cv::Mat(8, 8, CV_32F, cv::Scalar(100.0));
  with_flat.data_dir = options_.data_dir + "/flat";
  Node flat_node("vellum-restorer-flat", &bus_.lcm(), &bus_.clock());
  RestorerNode flat_restorer(&flat_node, with_flat);
  bus_.Watch("vellum-restorer-flat");
  for (point_cloud_t& m : ToMessages(10, SmallScanProducts().map.points, cv::Mat(),
                                     SmallScanContext(), FirstStages(2))) {
    bus_.probe().Publish(channel::kPointCloud, &m);
  }
  Publish(10, Sheet(10));
  EXPECT_TRUE(bus_.WaitForError("vellum-restorer-flat", "came without the projector's light"))
      << bus_.Status("vellum-restorer-flat").last_error;
  EXPECT_EQ(StatusCounter(bus_.Status("vellum-restorer-flat"), counter::kProductsLost), 1);
  EXPECT_EQ(StatusCounter(bus_.Status("vellum-restorer-flat"), counter::kLightWanted, -1), 1);
  EXPECT_EQ(StatusCounter(bus_.Status("vellum-restorer"), counter::kLightWanted, -1), 0)
      << "a studio field alone needs no projector's light";
}

// A page whose point map never comes (the bus lost it, the triangulator died) waits 30 s by the
// node's clock, no longer: the scan fails naming POINT_CLOUD, and the next is restored.
TEST_F(RestorerNodeTest, APageWhosePointMapNeverComesFailsItsScanAfterThirtySeconds) {
  StudioField studio;
  studio.camera_size = QuickRig().camera.size;
  studio.gain = cv::Mat(8, 8, CV_32FC(SmallScan().texture.channels()), cv::Scalar::all(250.0));
  studio.lamps = {cv::Vec3d(-450, -250, 500), cv::Vec3d(450, -250, 500)};
  options_.pipeline.studio_field = studio;
  Node node("vellum-restorer", &bus_.lcm(), &bus_.clock());
  RestorerNode restorer(&node, options_);
  bus_.AddTick([&] { restorer.Tick(); });
  bus_.Watch("vellum-restorer");
  auto restored = bus_.Record<restored_t>(channel::kRestored);
  Publish(11, Sheet(11));
  ASSERT_TRUE(bus_.RunUntil([&] {
    return bus_.Status("vellum-restorer").detail.find("waiting for the point map") !=
           std::string::npos;
  })) << bus_.Status("vellum-restorer").detail;
  bus_.StepFor(29, 0.5);
  EXPECT_EQ(bus_.Status("vellum-restorer").last_error, "");
  ASSERT_TRUE(bus_.StepUntil(
      [&] {
        return bus_.Status("vellum-restorer")
                   .last_error.find("scan 11: POINT_CLOUD never came whole") != std::string::npos;
      },
      0.5, 3))
      << bus_.Status("vellum-restorer").last_error;
  EXPECT_TRUE(restored->empty());
  // The next scan, its point map first, is restored.
  for (point_cloud_t& m : ToMessages(12, SmallScanProducts().map.points, cv::Mat(),
                                     SmallScanContext(), FirstStages(2))) {
    bus_.probe().Publish(channel::kPointCloud, &m);
  }
  Publish(12, Sheet(12));
  ASSERT_TRUE(bus_.RunUntil([&] { return !restored->empty(); }))
      << bus_.Status("vellum-restorer").last_error;
  EXPECT_EQ(restored->back().scan_id, 12);
}

// A station's target (its restorer's --target-ppi) judges every scan: the small rig's 41 ppi
// fails a target of 300 on "sampling", named on RESTORED and in report.json.
TEST_F(RestorerNodeTest, AStationTargetFailsAScanShortOfItOnSampling) {
  options_.pipeline.target.ppi = 300;
  Node node("vellum-restorer", &bus_.lcm(), &bus_.clock());
  RestorerNode restorer(&node, options_);
  auto restored = bus_.Record<restored_t>(channel::kRestored);
  Publish(14, Sheet(14));
  ASSERT_TRUE(bus_.RunUntil([&] { return !restored->empty(); }));
  EXPECT_EQ(restored->back().qc, "fail");
  std::ifstream in(ScanFolder::For(options_.data_dir, 14).results() + "/report.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  EXPECT_EQ(j["qc"]["target"], "300 ppi");
  std::string sampling;
  for (const auto& c : j["qc"]["checks"]) {
    if (c["name"] == "sampling" && c["verdict"] == "fail") sampling = c["detail"];
  }
  EXPECT_NE(sampling.find("the target (300 ppi) asks 300"), std::string::npos) << j["qc"].dump();
  // RESTORED says why: the shortfall, named by its check, beside the warnings.
  const std::vector<std::string>& said = restored->back().warnings;
  EXPECT_TRUE(std::any_of(said.begin(), said.end(), [](const std::string& w) {
    return w.rfind("sampling: ", 0) == 0 && w.find("asks 300") != std::string::npos;
  })) << ::testing::PrintToString(said);
}

TEST(RestorerNodeOptions, NonsenseIsRefusedByName) {
  RestorerNodeOptions o;
  std::string why;
  EXPECT_TRUE(o.Check(&why)) << why;
  o.preview_pixels = 0;
  EXPECT_FALSE(o.Check(&why));
  EXPECT_NE(why.find("preview_pixels"), std::string::npos) << why;
}

}  // namespace
}  // namespace vellum::station
