// The four processing daemons' nodes in one process on one memq:// bus, fed a scan's captures as
// the camera sends them: what they write equals what `vellum process` writes for the same scan
// (RunPipeline), byte for byte, and their report.json has the same keys and option values.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <tuple>

#include "daemons/decoder/decoder_node.h"
#include "daemons/flattener/flattener_node.h"
#include "daemons/restorer/restorer_node.h"
#include "daemons/triangulator/triangulator_node.h"
#include "io/manifest.h"
#include "pipeline/process.h"
#include "station/scan_log.h"
#include "station/testing.h"
#include "tests/report_keys.h"
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

// A scene on the quick rig: a leaf on the dark table (the station tests' scan), an open book,
// a leaf in a paper frame; lit (under studio lamps and a projector whose light falls off as a
// real one's), with extra raking lights, processed with the projector's flat field (the
// albedo) and the lamps' studio field (the reflectance).
struct Scene {
  const char* name;
  bool spread, frame;
  int raking = 0;  // Extra raking lights.
  bool flat_field = false, studio_field = false;
  bool Lit() const { return raking > 0 || flat_field || studio_field; }
};

// The light of the lit scenes.
LightOptions StudioLight() {
  LightOptions light;
  light.projector_falloff = true;
  light.studio_lamps = {cv::Vec3d(-450, -250, 500), cv::Vec3d(450, -250, 500)};
  return light;
}

// The options of a scene's processing, the same for `vellum process` and the daemons: for a lit
// scene, the flat field and studio field measured on a white target of albedo 0.85 larger than
// the view under the same light (once per process), as `vellum calibrate flatfield` and
// `vellum calibrate studio` measure them.
PipelineOptions SceneOptionsFor(const Scene& scene) {
  PipelineOptions options;
  if (!scene.flat_field && !scene.studio_field) return options;
  static const PipelineOptions lit = [] {
    PipelineOptions o;
    const Status s = MeasureFieldsOnWhiteTarget(QuickRig(), StudioLight(), 0.85, 41, &o.flat_field,
                                                &o.studio_field);
    if (!s.ok()) throw std::runtime_error(s.message());
    return o;
  }();
  if (scene.flat_field) options.flat_field = lit.flat_field;
  if (scene.studio_field) options.studio_field = lit.studio_field;
  return options;
}

Scan SceneScan(const Scene& scene) {
  if (!scene.spread && !scene.frame && !scene.Lit()) return SmallScan();
  PageOptions page;
  page.shape = scene.spread ? PageShape::kFlat : PageShape::kCurl;
  if (scene.spread) page.size_mm = {170.0, 230.0};
  SceneOptions options;
  options.spread = scene.spread;
  options.frame = scene.frame;
  TextureOptions texture;
  if (scene.Lit()) texture.kind = TextureKind::kText;  // Ink: the albedo is not even.
  const LightOptions light = scene.Lit() ? StudioLight() : LightOptions();
  const SimulatedScan sim = SimulateScan(QuickRig(), page, texture, options, 7, light);
  Scan scan = AsScan(sim);
  if (scene.raking > 0) scan.lights = RenderLights(*sim.gantry, RakingLights(scene.raking), 7);
  scan.identity.shelfmark = "MS 5";
  scan.identity.folio = scene.spread ? "2v-3r" : "4";  // A spread names its opening.
  if (!scene.spread) scan.identity.side = "recto";
  // The operator says it is a book: its two pages meet in a gap of 2 mm, 2 pixels of this
  // camera, too narrow to part them as evidence; said, the station splits them as the command.
  if (scene.spread) scan.object = ObjectKind::kBook;
  return scan;
}

// Every file under `root`, relative to it.
std::set<std::string> Files(const fs::path& root) {
  std::set<std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(root)) {
    if (e.is_regular_file()) files.insert(fs::relative(e.path(), root).string());
  }
  return files;
}

class Chain : public ::testing::TestWithParam<Scene> {};

TEST_P(Chain, TheDaemonsInMemoryWriteWhatVellumProcessWrites) {
  const Scan scan = SceneScan(GetParam());
  const fs::path dir = testing::TestDir(std::string("chain_") + GetParam().name);
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
  const PipelineOptions options = SceneOptionsFor(GetParam());
  // Only the restorer is told of the fields: the other daemons hand on what it needs.
  r.pipeline.flat_field = options.flat_field;
  r.pipeline.studio_field = options.studio_field;
  DecoderNode decoder(&decoder_node, d);
  TriangulatorNode triangulator(&triangulator_node, t);
  FlattenerNode flattener(&flattener_node, f);
  RestorerNode restorer(&restorer_node, r);
  auto restored = bus.Record<restored_t>(channel::kRestored);
  // As at a station: the scan comes once every daemon has been heard (Node::Run's heartbeat,
  // which these in-memory nodes do not run, so each says its state once).
  for (Node* node : {&decoder_node, &triangulator_node, &flattener_node, &restorer_node}) {
    node->SetState("idle");
  }
  // The scan as the station receives it: SCAN_STARTED, its calibration, then the captures.
  const int64_t session = NewSession();
  scan_started_t started = MakeScanStarted(scan, 3, session);
  bus.probe().Publish(channel::kScanStarted, &started);
  calibration_t calibration{};
  calibration.scan_id = 3;
  calibration.session = session;
  ToMessage(QuickRig(), &calibration);
  bus.probe().Publish(channel::kCalibration, &calibration);
  // The patterns, then the extra lights.
  for (int k = -1; k < static_cast<int>(scan.frames.size() + scan.lights.size()); ++k) {
    capture_t c = MakeCapture(scan, 3, k, NowUtime());
    c.session = session;
    bus.probe().Publish(channel::kCapture, &c);
  }
  ASSERT_TRUE(bus.RunUntil([&] { return !restored->empty(); }, 120))
      << "decoder: " << decoder_node.Counter("scans decoded")
      << ", triangulator: " << triangulator_node.Counter("scans triangulated")
      << ", flattener: " << flattener_node.Counter("scans flattened");
  const ScanFolder folder = ScanFolder::For(data, 3);
  // The scan's manifest, in its folder: every file of raw/ and results/, whole.
  std::vector<std::string> problems;
  const Status manifest = CheckManifest(folder.root, &problems);
  EXPECT_TRUE(manifest.ok()) << manifest.message();
  EXPECT_TRUE(problems.empty()) << problems.front();

  // The same scan, as recorded, through `vellum process`'s pipeline.
  ProcessInput input;
  ASSERT_TRUE(ReadProcessInput(folder.raw(), folder.calibration(), &input).ok());
  const std::string process = (dir / "process").string();
  const ProcessResult result = RunPipeline(input, options, process);
  ASSERT_TRUE(result.status.ok()) << result.status.message();
  // Every product, each page's and the report's pictures, byte for byte (the reports hold run
  // times and are compared below).
  const std::set<std::string> files = Files(process);
  EXPECT_EQ(Files(folder.results()), files);
  const bool spread = GetParam().spread;
  std::vector<std::string> expected = {"restored.tif", "restored.json", "mesh.ply", "flat.ply"};
  // Every product of a lit scan: the albedo, the reflectance, each light, the normals.
  if (GetParam().flat_field) expected.push_back("restored_albedo.tif");
  if (GetParam().studio_field) expected.push_back("restored_reflectance.tif");
  if (GetParam().raking > 0) expected.push_back("lights/raking-000.tif");
  if (GetParam().raking >= 3) expected.push_back("normals.tif");
  for (const std::string& file : expected) {
    const std::string page = spread ? "pages/left/" + file : file;
    EXPECT_EQ(files.count(page), 1u) << page;
  }
  for (const std::string& file : files) {
    if (file == "report.json" || file == "report.html") continue;
    const std::string a = ReadBytes(folder.results() + "/" + file),
                      b = ReadBytes(process + "/" + file);
    EXPECT_FALSE(a.empty()) << file;
    EXPECT_TRUE(a == b) << file << " differs between the daemons and vellum process";
  }
  const nlohmann::json station = ReadJson(folder.results() + "/report.json");
  const nlohmann::json cli = ReadJson(process + "/report.json");
  const std::set<std::string> station_keys = ComparableReportKeys(station);
  EXPECT_EQ(station_keys, ComparableReportKeys(cli));
  // Every section the same (options, pixels, outline, each page's sheet and flattening,
  // warnings, outputs), but where, how long and in how much memory (each daemon measures its
  // own stages; a stage's report that came over the bus carries no memory figure).
  for (auto it = cli.begin(); it != cli.end(); ++it) {
    if (it.key() == "scan" || it.key() == "calibration" || it.key() == "stages_seconds" ||
        it.key() == "stages_peak_memory_mb") {
      continue;
    }
    ASSERT_TRUE(station.contains(it.key())) << it.key();
    EXPECT_EQ(station.at(it.key()), it.value()) << it.key();
  }
  EXPECT_EQ(cli.contains("pages"), GetParam().spread);
  // Each restored page knows which it is: a spread's left page is folio 2 verso, its right
  // folio 3 recto.
  if (spread) {
    for (const auto& [page, folio, side] :
         {std::tuple<std::string, std::string, std::string>{"left", "2", "verso"},
          {"right", "3", "recto"}}) {
      const nlohmann::json r = ReadJson(process + "/pages/" + page + "/restored.json");
      EXPECT_EQ(r["identity"]["shelfmark"], "MS 5") << page;
      EXPECT_EQ(r["identity"]["folio"], folio) << page;
      EXPECT_EQ(r["identity"]["side"], side) << page;
    }
  }
  EXPECT_GE(station_keys.count("options/max_epipolar_error_px"), 1u);
  EXPECT_GE(station_keys.count("options/smooth_radius_px"), 1u);
  fs::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(Scenes, Chain,
                         ::testing::Values(Scene{"leaf", false, false},
                                           Scene{"spread", true, false},
                                           Scene{"frame", false, true},
                                           Scene{"flat_field", false, false, 0, true, false},
                                           Scene{"studio_field", false, true, 0, false, true},
                                           Scene{"lights", false, false, 6, false, false},
                                           Scene{"lit_spread", true, false, 3, true, true}),
                         [](const auto& info) { return std::string(info.param.name); });

}  // namespace
}  // namespace vellum::station
