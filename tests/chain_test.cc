// The four processing daemons' nodes in one process on one memq:// bus, fed a scan's captures as
// the camera sends them: what they write equals what `vellum process` writes for the same scan
// (RunPipeline), byte for byte, and their report.json has the same keys and option values.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "daemons/decoder/decoder_node.h"
#include "daemons/flattener/flattener_node.h"
#include "daemons/restorer/restorer_node.h"
#include "daemons/triangulator/triangulator_node.h"
#include "pipeline/process.h"
#include "station/scan_log.h"
#include "station/testing.h"
#include "vellum/restored_t.hpp"

namespace vellum::station {
namespace {

namespace fs = std::filesystem;
using testing::MemqBus;
using testing::ReadBytes;
using testing::SmallScan;

nlohmann::json ReadJson(const std::string& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

// The keys of a JSON object, recursively ("pixels/valid").
void Keys(const nlohmann::json& j, const std::string& prefix, std::set<std::string>* keys) {
  if (!j.is_object()) return;
  for (auto it = j.begin(); it != j.end(); ++it) {
    keys->insert(prefix + it.key());
    Keys(it.value(), prefix + it.key() + "/", keys);
  }
}

TEST(Chain, TheDaemonsInMemoryWriteWhatVellumProcessWrites) {
  const fs::path dir = testing::TestDir("chain");
  const std::string data = (dir / "scans").string();
  MemqBus bus;
  Node decoder_node("vellum-decoder", &bus.lcm()),
      triangulator_node("vellum-triangulator", &bus.lcm()),
      flattener_node("vellum-flattener", &bus.lcm()), restorer_node("vellum-restorer", &bus.lcm());
  DecoderNodeOptions d;
  d.data_dir = data;
  TriangulatorNodeOptions t;
  t.data_dir = data;
  FlattenerNodeOptions f;
  f.data_dir = data;
  RestorerNodeOptions r;
  r.data_dir = data;
  DecoderNode decoder(&decoder_node, d);
  TriangulatorNode triangulator(&triangulator_node, t);
  FlattenerNode flattener(&flattener_node, f);
  RestorerNode restorer(&restorer_node, r);
  auto restored = bus.Record<restored_t>(channel::kRestored);
  // The scan as the station receives it: its calibration, then the captures.
  calibration_t calibration{};
  calibration.scan_id = 3;
  ToMessage(QuickRig(), &calibration);
  bus.probe().Publish(channel::kCalibration, &calibration);
  for (int k = -1; k < static_cast<int>(SmallScan().frames.size()); ++k) {
    capture_t c = MakeCapture(SmallScan(), 3, k, NowUtime());
    bus.probe().Publish(channel::kCapture, &c);
  }
  ASSERT_TRUE(bus.RunUntil([&] { return !restored->empty(); }, 120))
      << "decoder: " << decoder_node.Counter("scans decoded")
      << ", triangulator: " << triangulator_node.Counter("scans triangulated")
      << ", flattener: " << flattener_node.Counter("scans flattened");
  const ScanFolder folder = ScanFolder::For(data, 3);

  // The same scan, as recorded, through `vellum process`'s pipeline.
  ProcessInput input;
  ASSERT_TRUE(ReadProcessInput(folder.raw(), folder.calibration(), &input).ok());
  const std::string process = (dir / "process").string();
  const ProcessResult result = RunPipeline(input, PipelineOptions(), process);
  ASSERT_TRUE(result.status.ok()) << result.status.message();
  for (const char* file : {"restored.tif", "restored.json", "points.ply", "depth.png", "mesh.ply",
                           "flat.ply", "report/texture.png", "report/valid.png", "report/depth.png",
                           "report/grid.png", "report/strain.png", "report/before_after.png"}) {
    const std::string a = ReadBytes(folder.results() + "/" + file),
                      b = ReadBytes(process + "/" + file);
    EXPECT_FALSE(a.empty()) << file;
    EXPECT_TRUE(a == b) << file << " differs between the daemons and vellum process";
  }
  const nlohmann::json station = ReadJson(folder.results() + "/report.json");
  const nlohmann::json cli = ReadJson(process + "/report.json");
  std::set<std::string> station_keys, cli_keys;
  Keys(station, "", &station_keys);
  Keys(cli, "", &cli_keys);
  EXPECT_EQ(station_keys, cli_keys);
  EXPECT_EQ(station["options"], cli["options"]);
  EXPECT_EQ(station["pixels"], cli["pixels"]);
  EXPECT_EQ(station["sheet"], cli["sheet"]);
  EXPECT_EQ(station["flattening"], cli["flattening"]);
  EXPECT_EQ(station["outputs"], cli["outputs"]);
  EXPECT_GE(station_keys.count("options/max_epipolar_error_px"), 1u);
  EXPECT_GE(station_keys.count("options/smooth_radius_px"), 1u);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace vellum::station
