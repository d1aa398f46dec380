// Real leaves and books on the virtual gantry (default rig and noise), through the whole
// pipeline of `vellum process` (RunPipeline): a leaf on a dark table, on a support as bright as
// the page, half lying flat on it, in a paper frame, burnt with holes, a steep ripple (no
// --grid given), and each page of an open book. On each, the paper's Experiment I (restored
// checkerboard corners against a flat control after a homography; in mm through the dpi against
// the true page), the flattened sheet against the true flat page, the restored mask against
// the true outline, and no warning on a clean scan.
//
// Why the bounds hold: the same as restoration_test (nodes good to ~0.01 mm, the warp's error
// below 0.05 px where the sheet's grid is chosen from the shape), so 0.15 px and 0.04 mm against
// the control and 0.08 mm RMS against the true page (our bars) leave a margin; corners
// are measured where the control's are (sub-pixel refinement from the page's true layout), so a
// hole in the leaf costs the corners it covers, not the measurement.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <map>
#include <opencv2/aruco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <tuple>

#include "core/common/depth.h"
#include "core/decode/decode.h"
#include "core/geometry/rigid2d.h"
#include "core/geometry/triangulate.h"
#include "core/shading/albedo.h"
#include "core/sim/evaluate.h"
#include "io/calibration_io.h"
#include "io/ptm.h"
#include "pipeline/process.h"
#include "pipeline/qc.h"
#include "tests/page_measure.h"

namespace vellum {
namespace {

namespace fs = std::filesystem;

struct Scene {
  const char* name;
  PageShape shape;
  bool support = false, frame = false, spread = false;
  OutlineKind outline = OutlineKind::kRectangle;
  double ink_albedo = 0.08;
  double texture_gain = 1;  // The studio-light texture over-exposed by this factor (clipped).
};

struct Scanned {
  SimulatedScan scan;
  ProcessResult result;
};

// Scans `page` on the virtual gantry `rig` and runs `vellum process`'s pipeline on it, the
// studio-light texture scaled by `texture_gain` (over-exposed and clipped above 1), under `light`.
Scanned ProcessOn(const Calibration& rig, const PageOptions& page, const TextureOptions& texture,
                  const SceneOptions& scene, uint64_t seed, const PipelineOptions& options,
                  const std::string& name, double texture_gain = 1,
                  const LightOptions& light = LightOptions(),
                  const std::vector<SceneLight>& lights = {}) {
  Scanned run;
  run.scan = SimulateScan(rig, page, texture, scene, seed, light);
  ProcessInput input;
  input.scan_dir = name;
  input.calibration_path = "the virtual gantry's rig";
  input.scan = AsScan(run.scan);
  input.scan.lights = RenderLights(*run.scan.gantry, lights, seed);
  if (texture_gain != 1) input.scan.texture.convertTo(input.scan.texture, -1, texture_gain);
  input.calibration = rig;
  const std::string out =
      (fs::temp_directory_path() / ("vellum_leaves_" + std::to_string(getpid()))).string();
  run.result = RunPipeline(input, options, out);
  if (getenv("LEAVES_DUMP")) {
    fs::copy(out, std::string(getenv("LEAVES_DUMP")) + "/" + name,
             fs::copy_options::recursive | fs::copy_options::overwrite_existing);
  }
  fs::remove_all(out);
  return run;
}

Scanned Process(const Scene& scene, uint64_t seed,
                const PipelineOptions& options = PipelineOptions(),
                cv::Vec2d centre_mm = {0.0, 0.0}) {
  PageOptions page;
  page.centre_mm = centre_mm;
  page.shape = scene.shape;
  page.outline = scene.outline;
  if (scene.spread) page.size_mm = {170.0, 230.0};
  SceneOptions s;
  s.support = scene.support;
  s.frame = scene.frame;
  s.spread = scene.spread;
  TextureOptions texture;
  texture.ink_albedo = scene.ink_albedo;
  return ProcessOn(DefaultRig(), page, texture, s, seed, options, scene.name, scene.texture_gain);
}

// The control: the same page lying flat on the dark table, scanned on its own.
const std::vector<cv::Point2f>& Control(cv::Size2d page_mm) {
  static std::map<double, std::vector<cv::Point2f>> cache;
  auto it = cache.find(page_mm.width);
  if (it != cache.end()) return it->second;
  PageOptions flat;
  flat.size_mm = page_mm;
  const Scanned run = ProcessOn(DefaultRig(), flat, TextureOptions(), SceneOptions(), 77,
                                PipelineOptions(), "control");
  EXPECT_TRUE(run.result.status.ok()) << run.result.status.message();
  const PageResult& page = run.result.pages.at(0);
  return cache[page_mm.width] =
             MeasureCorners(page, FlatToTrue(run.scan.gantry->truth(), page), TrueCorners(page_mm));
}

class Leaves : public ::testing::TestWithParam<Scene> {};

TEST_P(Leaves, RestoredAsTheFlatLeafWouldBe) {
  const Scene& scene = GetParam();
  // Restored at the rig's sampling of the table (102 dpi), where the bars in pixels were
  // set; the default, the page's finest true sampling, is 1-3% finer on raised
  // leaves, and the pixel figures with it (the ripple's 0.038 mm is 0.150 px at 102 dpi and
  // 0.154 px at 103). The bars in mm do not depend on it.
  PipelineOptions options;
  options.restore.dpi = NativeDpi(DefaultRig().camera);
  const Scanned run = Process(scene, 31, options);
  ASSERT_TRUE(run.result.status.ok()) << run.result.status.message();
  const GroundTruth& truth = run.scan.gantry->truth();
  const auto& pages = run.scan.gantry->pages();
  ASSERT_EQ(run.result.pages.size(), pages.size()) << "pages found";
  for (size_t k = 0; k < pages.size(); ++k) {
    const PageResult& page = run.result.pages[k];
    const cv::Size2d page_mm = pages[k].options().size_mm;
    SCOPED_TRACE(page.name.empty() ? std::string("the leaf") : page.name);
    // The sheet against the true flat page.
    const GroundTruth mine = OnePage(truth, static_cast<int>(k + 1));
    const FlatErrorStats flat = CompareFlat(mine, page.mesh, page.flat.flat);
    // Experiment I.
    const Rigid2D to_true = FlatToTrue(mine, page);
    const std::vector<cv::Point2d> corners = TrueCorners(page_mm);
    const std::vector<cv::Point2f> got = MeasureCorners(page, to_true, corners);
    const Measured m = ExperimentOne(page, got, Control(page_mm), corners);
    // The restored mask against the true outline: every leaf pixel of it lies on the page, or
    // within the rim's mixed pixels of it (the outline's 5 px at the camera's 0.25 mm: 1.25 mm;
    // checked on a 0.5 mm grid within 1.5 mm).
    int leaf = 0;
    const RestoreResult& r = page.restored;
    cv::Mat off_leaf;
    const int outside = MaskOffLeaf(page, to_true, pages[k], 1.5, &leaf, &off_leaf);
    if (getenv("LEAVES_DUMP")) {
      cv::Mat show = EightBitBgr(r.image).clone();
      cv::dilate(off_leaf, off_leaf, cv::Mat());
      show.setTo(cv::Scalar(0, 0, 255), off_leaf);
      cv::imwrite(std::string(getenv("LEAVES_DUMP")) + "/" + scene.name + page.name + ".png", show);
    }
    std::printf(
        "[leaves] %-22s %-5s grid %dx%d, warp %.3f px: nodes RMS %.4f mm; corners %d/%zu: "
        "vs control %.3f px = %.4f mm, vs truth %.4f mm RMS (mirrored %.1f); turned %.2f "
        "deg; mask %d px, %d off the leaf\n",
        scene.name, page.name.c_str(), page.mesh.cols, page.mesh.rows,
        run.result.report.Number("sheet", "warp_error_px", page.name), flat.rms_mm, m.corners,
        corners.size(), m.mean_px, m.mean_mm, m.rms_mm, m.rms_mirrored_mm,
        page.restored.rotation_deg, leaf, outside);
    EXPECT_LE(flat.rms_mm, 0.08);
    EXPECT_FALSE(flat.mirrored);
    EXPECT_GE(m.corners, static_cast<int>(corners.size()) * 3 / 4);
    EXPECT_LE(m.mean_px, 0.15);
    EXPECT_LE(m.mean_mm, 0.04);
    EXPECT_LE(m.rms_mm, 0.08);
    EXPECT_GT(m.rms_mirrored_mm, 10 * m.rms_mm) << "mirrored";
    EXPECT_EQ(outside, 0) << "restored mask pixels off the leaf";
    EXPECT_EQ(page.flat.folded_quads, 0);
  }
  // A clean scan: no warning.
  for (const Warning& w : run.result.report.Warnings())
    ADD_FAILURE() << w.code << ": " << w.message;
}

std::vector<std::string> WarningCodes(const Scanned& run) {
  std::vector<std::string> codes;
  for (const Warning& w : run.result.report.Warnings()) codes.push_back(w.code);
  return codes;
}

bool Has(const std::vector<std::string>& codes, const std::string& code) {
  return std::find(codes.begin(), codes.end(), code) != codes.end();
}

// A doubtful result is written and flagged, never silent. The leaf runs off the view: its
// centre 50 mm up puts its top edge 10 mm (40 px) past the camera's 150 mm half height.
TEST(Doubtful, ALeafRunningOffTheViewIsFlagged) {
  const Scanned run =
      Process(Scene{"cut_off", PageShape::kCurl}, 31, PipelineOptions(), cv::Vec2d(0.0, 50.0));
  ASSERT_TRUE(run.result.status.ok()) << run.result.status.message();
  const std::vector<std::string> codes = WarningCodes(run);
  EXPECT_TRUE(Has(codes, "page_cut_off")) << ::testing::PrintToString(codes);
  // Quality control fails it, on that check.
  const QcResult qc = AssessQuality(run.result.report);
  EXPECT_EQ(qc.verdict, QcVerdict::kFail);
  EXPECT_EQ(qc.checks[0].name, "leaf in view");
  EXPECT_EQ(qc.checks[0].verdict, QcVerdict::kFail);
}

// What the live view saw at the view's edge when the scan was asked (scan.yaml's live_off_view)
// keeps a scan from passing when the scan's own outline comes near that side but stays inside
// it: a flat leaf 6 mm (24 px) inside the view's edge nearest it. The same scan, told nothing,
// passes; told of the opposite side (far from the leaf: the live view took something else for
// it), passes too, with the claim recorded as not near.
TEST(Doubtful, WhatTheLiveViewSawRunOffTheViewKeepsTheScanFromPassing) {
  PageOptions page;
  page.shape = PageShape::kFlat;
  page.centre_mm = {0.0, 150.0 - 6.0 - page.size_mm.height / 2};
  const SimulatedScan scan = SimulateScan(DefaultRig(), page, TextureOptions(), SceneOptions(), 5);
  // The side of the view nearest the leaf, as the camera sees it (left, right, top, bottom).
  const cv::Mat& truth = scan.gantry->truth().on_page;
  const cv::Rect box = cv::boundingRect(truth);
  const int gap[kViewSideCount] = {box.x, truth.cols - box.br().x, box.y, truth.rows - box.br().y};
  const int nearest = static_cast<int>(std::min_element(gap, gap + kViewSideCount) - gap);
  ASSERT_GT(gap[nearest], 15) << "the leaf must lie inside the view";
  ASSERT_LT(gap[nearest], 35);
  const int opposite = nearest ^ 1;  // left <-> right, top <-> bottom.
  const std::string out =
      (fs::temp_directory_path() / ("vellum_live_edge_" + std::to_string(getpid()))).string();
  auto run = [&](int live_off_view) {
    ProcessInput input;
    input.scan_dir = "live_edge";
    input.calibration_path = "the virtual gantry's rig";
    input.scan = AsScan(scan);
    input.scan.live_off_view = live_off_view;
    input.calibration = DefaultRig();
    const ProcessResult result = RunPipeline(input, PipelineOptions(), out);
    fs::remove_all(out);
    EXPECT_TRUE(result.status.ok()) << result.status.message();
    return result;
  };
  const ProcessResult seen = run(1 << nearest);
  const QcResult qc = AssessQuality(seen.report);
  EXPECT_EQ(qc.verdict, QcVerdict::kWarn);
  EXPECT_EQ(qc.checks[0].name, "leaf in view");
  EXPECT_EQ(qc.checks[0].verdict, QcVerdict::kWarn);
  std::string said;
  for (const Warning& w : seen.report.Warnings()) {
    if (w.code == "seen_off_view") said = w.message;
  }
  EXPECT_NE(said.find("(" + std::string(kViewSideNames[nearest]) + ")"), std::string::npos) << said;
  EXPECT_EQ(seen.report.Text("operator", "live_off_view"), kViewSideNames[nearest]);

  const ProcessResult unseen = run(0);
  EXPECT_EQ(AssessQuality(unseen.report).verdict, QcVerdict::kPass);
  const ProcessResult far = run(1 << opposite);
  EXPECT_EQ(AssessQuality(far.report).verdict, QcVerdict::kPass);
  EXPECT_EQ(far.report.Text("outline", "live_off_view"), kViewSideNames[opposite]);
  EXPECT_EQ(far.report.Text("outline", "live_off_view_near"), "none");
}

// A spread's gutter: what the restored pages leave out of the pages there is reported (at
// least the straight line between the last points of either page), flagged past 5 mm, and
// never invented: each restored page ends where its page was last seen (TrueGutter).
// Restored leaf pixels of page k (0 left, 1 right) whose true point lies more than `slack_mm`
// past where the page was seen, towards the gutter, and the leaf pixels looked at.
std::pair<int, int> Invented(const Scanned& run, const GutterTruth& truth, size_t k,
                             double slack_mm) {
  const PageResult& page = run.result.pages.at(k);
  const std::vector<double>& bins = truth.innermost[k];
  int invented = 0, looked = 0;
  ForLeafPixels(page, FlatToTrue(run.scan.gantry->truth(), page),
                [&](int, int, const cv::Point2d& st) {
                  const int bin = static_cast<int>(std::floor(st.y));
                  if (bin < 0 || bin >= static_cast<int>(bins.size()) || std::isnan(bins[bin]))
                    return;
                  ++looked;
                  invented += k == 0 ? st.x > bins[bin] + slack_mm : st.x < bins[bin] - slack_mm;
                });
  return {invented, looked};
}

TEST(Doubtful, WhatTheGutterHidesIsReportedFlaggedAndNotInvented) {
  // A book opened wide (the pages turn 55 degrees down into the gutter) and one barely open
  // (88 degrees, a tighter bend): the camera and the projector reach all of the first, not the
  // depth of the second.
  for (const double angle : {55.0, 88.0}) {
    const bool deep = angle > 80;
    SCOPED_TRACE(deep ? "deep gutter" : "open wide");
    PageOptions page;
    page.size_mm = {170.0, 230.0};
    page.gutter_angle_deg = angle;
    if (deep) page.gutter_radius_mm = 25;
    SceneOptions scene;
    scene.spread = true;
    const Scanned run = ProcessOn(DefaultRig(), page, TextureOptions(), scene, 41,
                                  PipelineOptions(), deep ? "deep_gutter" : "open_wide");
    ASSERT_TRUE(run.result.status.ok()) << run.result.status.message();
    ASSERT_EQ(run.result.pages.size(), 2u) << "found as a spread";
    const GutterTruth truth = TrueGutter(*run.scan.gantry);
    const ProcessReport& report = run.result.report;
    const double unseen = report.Number("outline", "gutter_unseen_mm");
    std::printf(
        "[gutter] %-11s left out %.2f mm (p95 %.2f) reported; the true line between "
        "the last pages' points seen %.2f mm\n",
        deep ? "deep" : "open wide", unseen, report.Number("outline", "gutter_unseen_p95_mm"),
        truth.chord_mm);
    ASSERT_NE(report.Find("outline", "gutter_unseen_mm"), nullptr);
    // What the camera and the projector did not reach is left out: the line reported is at
    // least the true one, less the pages' 2 mm gap, whose floor (level with the pages' gutter
    // edges) may be taken as page.
    EXPECT_GE(unseen, truth.chord_mm - scene.spread_gap_mm);
    EXPECT_EQ(Has(WarningCodes(run), "gutter_hidden"), deep) << unseen << " mm";
    if (!deep) {
      EXPECT_LE(unseen, truth.chord_mm + 1.0) << "the open book's pages come out whole";
    }
    // Never invented: no restored leaf pixel lies past where its page was seen, by more than
    // the rim's mixed pixels (5 px at 0.25 mm, 1.25 mm on flat paper) and the gap's floor
    // taken as page (2 mm).
    for (size_t k = 0; k < 2; ++k) {
      const auto [invented, looked] = Invented(run, truth, k, 1.25 + scene.spread_gap_mm);
      std::printf("[gutter] %-11s %-5s %d of %d restored leaf pixels past what was seen\n",
                  deep ? "deep" : "open wide", run.result.pages[k].name.c_str(), invented, looked);
      EXPECT_GT(looked, 10000);
      EXPECT_EQ(invented, 0) << run.result.pages[k].name;
    }
  }
}

// An over-exposed texture (the studio light's frame twice as bright: the paper clips at the
// camera's maximum) is flagged, and fails quality control on exposure; the same scene at its
// exposure passes it.
TEST(Doubtful, AClippedTextureFailsQualityControl) {
  const Scanned clean = Process(Scene{"exposed", PageShape::kCurl}, 31);
  ASSERT_TRUE(clean.result.status.ok()) << clean.result.status.message();
  const QcResult fine = AssessQuality(clean.result.report);
  for (const QcCheck& c : fine.checks) {
    EXPECT_EQ(c.verdict, QcVerdict::kPass) << c.name << ": " << c.detail;
  }
  EXPECT_EQ(fine.verdict, QcVerdict::kPass);
  Scene bright{"exposed", PageShape::kCurl};
  bright.texture_gain = 2;
  const Scanned run = Process(bright, 31);
  ASSERT_TRUE(run.result.status.ok()) << run.result.status.message();
  EXPECT_TRUE(Has(WarningCodes(run), "exposure_clipped"))
      << ::testing::PrintToString(WarningCodes(run));
  const double clipped = run.result.report.Number("exposure", "clipped_highlights");
  std::printf("[doubtful] texture at twice its exposure: %.1f%% of the leaf clipped\n",
              100 * clipped);
  EXPECT_GT(clipped, 0.05);
  const QcResult qc = AssessQuality(run.result.report);
  EXPECT_EQ(qc.verdict, QcVerdict::kFail);
  const auto exposure = std::find_if(qc.checks.begin(), qc.checks.end(),
                                     [](const QcCheck& c) { return c.name == "exposure"; });
  ASSERT_NE(exposure, qc.checks.end());
  EXPECT_EQ(exposure->verdict, QcVerdict::kFail) << exposure->detail;
}

// The operator's expected size: a 190 x 240 mm leaf is flagged against 150 x 240 mm (27% off)
// either way round, and not against 240 x 190 mm (the leaf turned).
TEST(Doubtful, ALeafOfAnotherSizeThanExpectedIsFlagged) {
  PipelineOptions options;
  options.limits.expected_leaf_mm = {150.0, 240.0};
  const Scanned wrong = Process(Scene{"size", PageShape::kCurl}, 31, options);
  ASSERT_TRUE(wrong.result.status.ok()) << wrong.result.status.message();
  EXPECT_TRUE(Has(WarningCodes(wrong), "size_unexpected"))
      << ::testing::PrintToString(WarningCodes(wrong));
  EXPECT_EQ(AssessQuality(wrong.result.report).verdict, QcVerdict::kWarn);  // Scale: a warning.
  options.limits.expected_leaf_mm = {240.0, 190.0};
  const Scanned right = Process(Scene{"size", PageShape::kCurl}, 31, options);
  ASSERT_TRUE(right.result.status.ok()) << right.result.status.message();
  EXPECT_TRUE(WarningCodes(right).empty()) << ::testing::PrintToString(WarningCodes(right));
}

// A collection's target judges every page of a spread: each page short of it is named in the
// check, neither hides the other; a page that meets it adds nothing. The figures are a report's
// as the restore stage records them.
TEST(Quality, ATargetJudgesEachPageOfASpreadAndNamesEveryShortfall) {
  ProcessReport report;
  for (const auto& [page, p5, bits] : {std::tuple<const char*, double, double>{"left", 320, 8},
                                       std::tuple<const char*, double, double>{"right", 280, 8}}) {
    StageReport stage;
    stage.stage = "restore";
    stage.page = page;
    stage.Number("restored", "dpi", 300);
    stage.Number("restored", "bits_per_channel", bits);
    stage.Number("restored", "scale_error_percent", 0.5);
    stage.Number("sampling", "p5_ppi", p5);
    stage.Number("sampling", "median_ppi", p5 + 20);
    report.stages.push_back(stage);
  }
  EXPECT_EQ(AssessQuality(report).verdict, QcVerdict::kPass);  // No target: nothing judged.
  report.target.ppi = 300;
  report.target.bits = 16;
  const QcResult qc = AssessQuality(report);
  EXPECT_EQ(qc.verdict, QcVerdict::kFail);
  std::map<std::string, QcCheck> by_name;
  for (const QcCheck& c : qc.checks) by_name[c.name] = c;
  EXPECT_EQ(by_name["sampling"].verdict, QcVerdict::kFail);
  EXPECT_NE(by_name["sampling"].detail.find("right page: 280 ppi at 95% of the page"),
            std::string::npos)
      << by_name["sampling"].detail;
  EXPECT_EQ(by_name["sampling"].detail.find("left page"), std::string::npos)
      << "the left page meets 300 ppi: " << by_name["sampling"].detail;
  EXPECT_EQ(by_name["bit depth"].verdict, QcVerdict::kFail);
  for (const char* page : {"left page: 8 bits per channel", "right page: 8 bits per channel"}) {
    EXPECT_NE(by_name["bit depth"].detail.find(page), std::string::npos)
        << page << " in " << by_name["bit depth"].detail;
  }
  report.target = QcTarget();
  report.target.fadgi_stars = 1;  // 285 ppi, 8 bits, 5%: the left page meets it, the right not.
  const QcResult one = AssessQuality(report);
  std::map<std::string, QcCheck> stars;
  for (const QcCheck& c : one.checks) stars[c.name] = c;
  EXPECT_EQ(stars["sampling"].verdict, QcVerdict::kFail);
  EXPECT_NE(stars["sampling"].detail.find("right page"), std::string::npos);
  EXPECT_EQ(stars["bit depth"].verdict, QcVerdict::kPass);
  EXPECT_EQ(stars["scale error"].verdict, QcVerdict::kPass);
}

// Asking 600 dpi of the default rig (which samples the table at about 102 ppi) writes
// the page at 600 dpi, with a warning that names the true figure (the page's finest true
// sampling, as report.json states it), and the sampling check warns. Left to its default, the
// same scan is written at that true figure and nothing is flagged.
TEST(Doubtful, ADpiAboveTheTrueSamplingIsFlaggedWithTheTrueFigure) {
  PipelineOptions options;
  options.restore.dpi = 600;
  const Scanned run = Process(Scene{"dpi", PageShape::kCurl}, 31, options);
  ASSERT_TRUE(run.result.status.ok()) << run.result.status.message();
  const ProcessReport& report = run.result.report;
  const double finest = report.Number("sampling", "p95_ppi");
  EXPECT_NEAR(finest, 102, 3);  // 25.4 / 0.25 mm, the rig's sampling of the table.
  EXPECT_EQ(report.Number("restored", "dpi"), 600);
  std::string message;
  for (const Warning& w : report.Warnings())
    if (w.code == "dpi_above_sampling") message = w.message;
  char figure[32];
  std::snprintf(figure, sizeof(figure), "%.0f ppi", finest);
  EXPECT_NE(message.find("written at 600 dpi"), std::string::npos) << message;
  EXPECT_NE(message.find(std::string("truly sampled it at ") + figure), std::string::npos)
      << message;
  const QcResult qc = AssessQuality(report);
  EXPECT_EQ(qc.verdict, QcVerdict::kWarn);
  const Scanned plain = Process(Scene{"dpi", PageShape::kCurl}, 31);
  ASSERT_TRUE(plain.result.status.ok()) << plain.result.status.message();
  // The sheet's finest sampling (by flat area) sets the dpi; the map's is over the leaf's pixels.
  EXPECT_NEAR(plain.result.report.Number("restored", "dpi"),
              plain.result.report.Number("sampling", "p95_ppi"), 1.0);
  EXPECT_TRUE(WarningCodes(plain).empty()) << ::testing::PrintToString(WarningCodes(plain));
}

// Without its rims (the step asked for is absurd: none is ever found) the leaf on a support as
// bright as it is still found by its height off the support (the cut does not take the support
// with it, as a rim flood once did). With the look's contrast asked for absurd too, nothing sets
// its outline apart: it is said to be uncertain. At the default contrast, the support's 6% less
// brightness (albedo 0.80 to the paper's 0.85) sets it apart all round: no warning.
TEST(Doubtful, WithoutItsRimsALeafOnASupportIsFoundAndFlaggedUncertain) {
  PipelineOptions options;
  options.outline.step_mm = 1e3;
  options.outline.rim_look_contrast = 10;
  const Scanned run = Process(Scene{"support", PageShape::kCurl, true}, 31, options);
  ASSERT_TRUE(run.result.status.ok()) << run.result.status.message();
  const std::vector<std::string> codes = WarningCodes(run);
  std::printf("[doubtful] no rims, no look: %s\n", ::testing::PrintToString(codes).c_str());
  EXPECT_GE(MaskIoU(run.result.outline.mask, run.scan.gantry->truth().on_page), 0.98);
  EXPECT_TRUE(Has(codes, "outline_uncertain")) << ::testing::PrintToString(codes);
  EXPECT_FALSE(Has(codes, "page_cut_off")) << ::testing::PrintToString(codes);
  options.outline.rim_look_contrast = OutlineOptions().rim_look_contrast;
  const Scanned by_look = Process(Scene{"support", PageShape::kCurl, true}, 31, options);
  ASSERT_TRUE(by_look.result.status.ok()) << by_look.result.status.message();
  EXPECT_GE(MaskIoU(by_look.result.outline.mask, by_look.scan.gantry->truth().on_page), 0.98);
  EXPECT_GE(by_look.result.outline.confidence, 0.9);
  EXPECT_FALSE(Has(WarningCodes(by_look), "outline_uncertain"))
      << ::testing::PrintToString(WarningCodes(by_look));
}

// The page image the right way up: ArUco markers (asymmetric, and a mirrored marker does not
// decode) at the page image's four corners, 40 mm each, on a curled leaf. In the camera's
// texture and in the restored page each is found by its id in its own corner, upright (its own
// first corner up and left of its third), never mirrored.
TEST(Orientation, APageImageReadsTheRightWayInTheTextureAndTheRestoredPage) {
  const cv::Ptr<cv::aruco::Dictionary> dictionary =
      cv::aruco::getPredefinedDictionary(cv::aruco::DICT_4X4_50);
  const double px_per_mm = 5;
  const cv::Size2d page_mm(190, 240);
  cv::Mat image(cv::Size(cvRound(page_mm.width * px_per_mm), cvRound(page_mm.height * px_per_mm)),
                CV_8U, cv::Scalar(255));
  const int side = cvRound(40 * px_per_mm), inset = cvRound(20 * px_per_mm);
  // id 1 top left, 2 top right, 3 bottom left, 4 bottom right.
  const cv::Point at[4] = {{inset, inset},
                           {image.cols - inset - side, inset},
                           {inset, image.rows - inset - side},
                           {image.cols - inset - side, image.rows - inset - side}};
  for (int k = 0; k < 4; ++k) {
    cv::Mat marker;
    cv::aruco::drawMarker(dictionary, k + 1, side, marker, 1);
    marker.copyTo(image(cv::Rect(at[k], cv::Size(side, side))));
  }
  PageOptions page;
  page.shape = PageShape::kCurl;
  page.size_mm = page_mm;
  TextureOptions texture;
  texture.kind = TextureKind::kImage;
  texture.image = image;
  const Scanned run =
      ProcessOn(DefaultRig(), page, texture, SceneOptions(), 31, PipelineOptions(), "markers");
  const SimulatedScan& scan = run.scan;
  const ProcessResult& result = run.result;
  ASSERT_TRUE(result.status.ok()) << result.status.message();
  ASSERT_EQ(result.pages.size(), 1u);
  const cv::Mat restored = EightBit(result.pages[0].restored.image);
  for (const auto& [name, picture] :
       {std::pair<std::string, cv::Mat>{"texture", scan.texture}, {"restored page", restored}}) {
    SCOPED_TRACE(name);
    cv::Mat gray = picture;
    if (gray.channels() == 3) cv::cvtColor(gray, gray, cv::COLOR_BGR2GRAY);
    std::vector<std::vector<cv::Point2f>> corners;
    std::vector<int> ids;
    cv::aruco::detectMarkers(gray, dictionary, corners, ids);
    ASSERT_EQ(ids.size(), 4u) << "markers found: " << ::testing::PrintToString(ids);
    // The leaf's box in the picture: its markers' bounds.
    cv::Rect2f box = cv::boundingRect(corners[0]);
    for (const auto& c : corners) box |= cv::Rect2f(cv::boundingRect(c));
    const cv::Point2f middle(box.x + box.width / 2, box.y + box.height / 2);
    for (size_t k = 0; k < ids.size(); ++k) {
      const int id = ids[k];
      ASSERT_GE(id, 1);
      ASSERT_LE(id, 4);
      const cv::Point2f centre =
          0.25f * (corners[k][0] + corners[k][1] + corners[k][2] + corners[k][3]);
      const bool left = id == 1 || id == 3, top = id == 1 || id == 2;
      EXPECT_EQ(centre.x < middle.x, left) << "marker " << id;
      EXPECT_EQ(centre.y < middle.y, top) << "marker " << id;
      // Upright: the marker's own top-left corner is up and left of its bottom-right one.
      EXPECT_LT(corners[k][0].x, corners[k][2].x) << "marker " << id;
      EXPECT_LT(corners[k][0].y, corners[k][2].y) << "marker " << id;
    }
  }
}

// The demo's scene (scripts/record-demo.sh: the demo rig, a curled leaf of 56 x 70 mm whose page
// is tests/data/demo_page.png, on the dark table), scanned here with the default sequence: the
// restored mask covers the leaf only, never the table beyond its curled edge (the sheet's skirt
// once claimed a strip of it). Tolerance as in Leaves: a rim's mixed pixels, 1.5 mm.
TEST(Demo, TheRestoredMaskIsTheLeafAndNotTheTableBeyondItsCurl) {
  Calibration rig;
  const std::string rig_file = std::string(VELLUM_SOURCE_DIR) + "/config/demo_rig.yaml";
  ASSERT_TRUE(ReadCalibration(rig_file, &rig).ok()) << rig_file;
  PageOptions page;
  page.shape = PageShape::kCurl;
  page.size_mm = {56.0, 70.0};
  TextureOptions texture;
  texture.kind = TextureKind::kImage;
  texture.image = cv::imread(std::string(VELLUM_SOURCE_DIR) + "/tests/data/demo_page.png");
  ASSERT_FALSE(texture.image.empty());
  const Scanned run =
      ProcessOn(rig, page, texture, SceneOptions(), 31, PipelineOptions(), "demo_scene");
  ASSERT_TRUE(run.result.status.ok()) << run.result.status.message();
  ASSERT_EQ(run.result.pages.size(), 1u);
  for (const Warning& w : run.result.report.Warnings())
    ADD_FAILURE() << w.code << ": " << w.message;
  const PageResult& leaf = run.result.pages[0];
  const Rigid2D to_true = FlatToTrue(run.scan.gantry->truth(), leaf);
  int pixels = 0;
  const int off = MaskOffLeaf(leaf, to_true, run.scan.gantry->pages()[0], 1.5, &pixels, nullptr);
  std::printf("[demo] restored mask %d px (every other row and column), %d off the leaf\n", pixels,
              off);
  EXPECT_GT(pixels, 0);
  EXPECT_EQ(off, 0) << "restored mask pixels off the leaf";
}

// The library master: a curled leaf from the 24 MP camera (config/hires_rig.yaml: the
// default rig's projector and geometry, 0.0635 mm per camera pixel on the table, 400 ppi),
// restored at 400 ppi through the whole pipeline.
//
// Why these bounds hold physically:
// - Sampling: a slope of angle a at height h is seen at 400 cos(a) 600 / (600 - h) ppi across
//   its fall line, so 390 ppi needs slopes under about 13 degrees on the table and 15 at the
//   height such a slope reaches. The leaf's curl (200 mm radius over its last 50 mm) rises to
//   14.3 degrees and 6.2 mm: sampled at >= 391 ppi everywhere by that formula; >= 95% of it at
//   >= 390 ppi (the bar) leaves the sheet's edge cells their half-cell shortfall. The default
//   curl (60 mm radius, 67 degrees) falls to 267 ppi at its 5th percentile: no camera this
//   coarse can give 390 ppi there, and the report says so (FADGI's sampling figure).
// - Experiment I at 400 ppi: 0.15 px is 0.0095 mm. The projector is the default rig's, so a
//   point's depth noise is as there (~0.02 mm on paper), but each sheet node's local fit now
//   averages 16 times as many camera pixels (a 4x4 block per default-rig pixel): ~4 times less
//   noise, ~0.003 mm per node. The control is the page's true layout at 400 ppi (stricter than a
//   scanned flat page, which has its own noise).
// - Scale: the flattening keeps geodesic lengths to its residual strain (~3e-5 mean); the
//   similarity fitted to the true corners has its scale within 0.1% of 1 (the bar), and the
//   report's scale error (the mean strain) is below 0.1% too.
TEST(Masters, ACurledLeafFromThe24MpCameraAt400PpiMeetsTheBars) {
  Calibration rig;
  const std::string rig_file = std::string(VELLUM_SOURCE_DIR) + "/config/hires_rig.yaml";
  ASSERT_TRUE(ReadCalibration(rig_file, &rig).ok()) << rig_file;
  ASSERT_EQ(rig.camera.size, cv::Size(6000, 4000));
  PageOptions page;
  page.shape = PageShape::kCurl;
  page.size_mm = {190.0, 200.0};  // The camera's view is 381 x 254 mm.
  page.curl_radius_mm = 200;
  page.curl_length_mm = 50;
  PipelineOptions options;
  options.restore.dpi = 400;
  const Scanned run =
      ProcessOn(rig, page, TextureOptions(), SceneOptions(), 31, options, "hires_curl");
  ASSERT_TRUE(run.result.status.ok()) << run.result.status.message();
  ASSERT_EQ(run.result.pages.size(), 1u);
  const PageResult& leaf = run.result.pages[0];
  const RestoreResult& r = leaf.restored;
  EXPECT_EQ(r.dpi, 400);
  for (const Warning& w : run.result.report.Warnings())
    ADD_FAILURE() << w.code << ": " << w.message;

  // Experiment I against the true layout.
  const GroundTruth& truth = run.scan.gantry->truth();
  const Rigid2D to_true = FlatToTrue(truth, leaf);
  const std::vector<cv::Point2d> corners = TrueCorners(page.size_mm);
  const std::vector<cv::Point2f> got = MeasureCorners(leaf, to_true, corners);
  std::vector<cv::Point2f> control;
  const Rigid2D back{-to_true.angle, {0, 0}};
  for (const cv::Point2d& t : corners)
    control.emplace_back(ApplyAffine(r.pixel_from_flat, back.Apply(t - to_true.translation)));
  const Measured m = ExperimentOne(leaf, got, control, corners);

  // The scale: a similarity from the restored corners (mm, through the dpi) to the true ones.
  const cv::Matx23d& a = r.pixel_from_flat;
  const cv::Matx22d inv = cv::Matx22d(a(0, 0), a(0, 1), a(1, 0), a(1, 1)).inv();
  std::vector<cv::Point2d> mm, t;
  for (size_t k = 0; k < got.size(); ++k) {
    if (!std::isfinite(got[k].x)) continue;
    const cv::Vec2d d = inv * cv::Vec2d(got[k].x - a(0, 2), got[k].y - a(1, 2));
    mm.emplace_back(d[0], d[1]);
    t.push_back(corners[k]);
  }
  ASSERT_GE(mm.size(), corners.size() * 3 / 4);
  cv::Point2d mm_mean, t_mean;
  for (size_t k = 0; k < mm.size(); ++k) {
    mm_mean += mm[k] / static_cast<double>(mm.size());
    t_mean += t[k] / static_cast<double>(mm.size());
  }
  double mm_spread = 0, t_spread = 0;
  for (size_t k = 0; k < mm.size(); ++k) {
    mm_spread += std::pow(cv::norm(mm[k] - mm_mean), 2);
    t_spread += std::pow(cv::norm(t[k] - t_mean), 2);
  }
  const double scale_error = std::sqrt(mm_spread / t_spread) - 1;

  // The true sampling: the map's over the leaf's restored pixels, and the gantry's exact one.
  int leaf_pixels = 0, at_390 = 0;
  for (int v = 0; v < r.mask.rows; ++v) {
    for (int u = 0; u < r.mask.cols; ++u) {
      if (!r.mask.at<uint8_t>(v, u)) continue;
      ++leaf_pixels;
      at_390 += r.sampling.at<float>(v, u) >= 390;
    }
  }
  const std::vector<double> exact = TrueSampling(*run.scan.gantry, 2.0);
  const double exact_at_390 =
      std::count_if(exact.begin(), exact.end(), [](double ppi) { return ppi >= 390; }) /
      static_cast<double>(exact.size());
  const double map_at_390 = at_390 / static_cast<double>(leaf_pixels);
  std::printf(
      "[masters] 24 MP curl at 400 ppi: %dx%d px, corners %d/%zu: vs true layout %.3f px = "
      "%.4f mm mean, vs truth %.4f mm RMS (mirrored %.1f); scale error %.4f%% (report %.4f%%); "
      ">= 390 ppi: %.1f%% of the leaf (map), %.1f%% (exact)\n",
      r.image.cols, r.image.rows, m.corners, corners.size(), m.mean_px, m.mean_mm, m.rms_mm,
      m.rms_mirrored_mm, 100 * scale_error,
      run.result.report.Number("restored", "scale_error_percent"), 100 * map_at_390,
      100 * exact_at_390);
  EXPECT_LE(m.mean_px, 0.15);
  EXPECT_LE(m.rms_mm, 0.08);
  EXPECT_GT(m.rms_mirrored_mm, 10 * m.rms_mm) << "mirrored";
  EXPECT_LE(std::fabs(scale_error), 0.001);
  EXPECT_LE(run.result.report.Number("restored", "scale_error_percent"), 0.1);
  EXPECT_GE(map_at_390, 0.95);
  EXPECT_GE(exact_at_390, 0.95);
}

// Reflectance, not shading. The gantry's light as real lights give it: the projector's
// falls with the square of the distance and towards its image's corners, and two studio lamps
// shade the texture (a slope facing away from them is darker). The projector's flat field is
// measured on a white target (albedo 0.85) lying on the table, as `vellum calibrate flatfield`
// does; each plain white leaf (albedo 0.85), curled, folded or rolled into a cone, then goes
// through the whole pipeline with it. Its restored albedo is even where its restored texture
// is shaded.
//
// Why 1% holds: (white - black) has 2.1 DN of noise on ~160 DN of paper, 1.3% a camera pixel;
// the restoration takes 2 x 2 samples a restored pixel at the page's own sampling, which
// halves it where the page faces the projector; the normals come from 9 x 9 pixel windows of
// points good to ~0.02 mm, a few hundredths of a degree. The residue is the noise where the
// page turns from the projector (less light, more noise), under 1% (our bar) over the
// leaf. The texture's unevenness is the lamps' shading, 10-20%.
TEST(Shading, TheRestoredAlbedoOfAPlainLeafIsEvenWhereItsTextureIsShaded) {
  LightOptions light;
  light.projector_falloff = true;
  light.studio_lamps = {cv::Vec3d(-450, -250, 500), cv::Vec3d(450, -250, 500)};
  TextureOptions plain;
  plain.kind = TextureKind::kPlain;
  plain.paper_albedo = 0.85;
  // The fields measured on a white target under the same light, as `vellum calibrate
  // flatfield` and `vellum calibrate studio` measure them.
  PipelineOptions options;
  const Status s = MeasureFieldsOnWhiteTarget(DefaultRig(), light, plain.paper_albedo, 41,
                                              &options.flat_field, &options.studio_field);
  ASSERT_TRUE(s.ok()) << s.message();
  for (PageShape shape : {PageShape::kCurl, PageShape::kFold, PageShape::kCone}) {
    SCOPED_TRACE(ToString(shape));
    PageOptions page;
    page.shape = shape;
    const Scanned run = ProcessOn(DefaultRig(), page, plain, SceneOptions(), 7, options,
                                  std::string("albedo_") + ToString(shape), 1, light);
    ASSERT_TRUE(run.result.status.ok()) << run.result.status.message();
    ASSERT_EQ(run.result.pages.size(), 1u);
    const PageResult& leaf = run.result.pages[0];
    const cv::Mat& albedo = leaf.albedo.image;
    ASSERT_EQ(albedo.type(), CV_16U);
    ASSERT_EQ(albedo.size(), leaf.restored.image.size());
    const cv::Mat measured = albedo > 0;
    cv::Mat a, t;
    albedo.convertTo(a, CV_64F, 1.0 / 65535);
    leaf.restored.image.convertTo(t, CV_64F);
    cv::Scalar a_mean, a_sd, t_mean, t_sd;
    cv::meanStdDev(a, a_mean, a_sd, measured);
    cv::meanStdDev(t, t_mean, t_sd, measured);
    const double leaf_px = cv::countNonZero(leaf.restored.mask);
    std::printf(
        "[shading] %-5s restored albedo %.4f (true %.2f), non-uniformity %.2f%%; restored "
        "texture %.2f%%; marked %.1f%% of the leaf\n",
        ToString(shape), a_mean[0], plain.paper_albedo, 100 * a_sd[0] / a_mean[0],
        100 * t_sd[0] / t_mean[0], 100 * (1 - cv::countNonZero(measured) / leaf_px));
    EXPECT_NEAR(a_mean[0] / plain.paper_albedo, 1.0, 0.01);
    EXPECT_LE(a_sd[0] / a_mean[0], 0.01);
    EXPECT_GT(t_sd[0] / t_mean[0], 5 * a_sd[0] / a_mean[0]) << "the lamps should shade it";
    EXPECT_LT(cv::countNonZero(measured), leaf_px) << "the rim is marked";
    EXPECT_GT(cv::countNonZero(measured), 0.9 * leaf_px);
    // The studio-lit texture corrected by the same shape: as even (its noise is the texture's,
    // 1.5 DN on ~190, halved by the restoration's 2 x 2 samples).
    const cv::Mat& reflectance = leaf.reflectance.image;
    ASSERT_EQ(reflectance.type(), CV_16U);
    ASSERT_EQ(reflectance.size(), leaf.restored.image.size());
    const cv::Mat corrected = reflectance > 0;
    cv::Mat f;
    reflectance.convertTo(f, CV_64F, 1.0 / 65535);
    cv::Scalar f_mean, f_sd;
    cv::meanStdDev(f, f_mean, f_sd, corrected);
    std::printf("[shading] %-5s restored reflectance (studio field) %.4f, non-uniformity %.2f%%\n",
                ToString(shape), f_mean[0], 100 * f_sd[0] / f_mean[0]);
    EXPECT_NEAR(f_mean[0] / plain.paper_albedo, 1.0, 0.01);
    EXPECT_LE(f_sd[0] / f_mean[0], 0.01);
    EXPECT_GT(cv::countNonZero(corrected), 0.9 * leaf_px);
  }
}

// Several lights through one warp. A curled checkerboard leaf captured under three
// raking lights (30 degrees up, from three sides) and its UV fluorescence, in the pose of its
// scan: each restored light's corners against the restored texture's, all found the same way.
//
// Why 0.1 px holds: every image goes through the same triangles and samples, so what differs is
// only where cornerSubPix finds a corner in differently lit, differently noisy images: a raking
// light halves the board's contrast (cos 60) and shades it across a square, which moves a
// corner found on 1.5 DN of noise by a few hundredths of a pixel. A corner in a light's deep
// shade (the curl turned from it: under 12 DN between its squares) has no corner to find and
// is left out; at least 80% of the board is measured under each light.
TEST(Lights, RakingAndUvLightsRegisterToTheTextureWithinATenthOfAPixel) {
  PageOptions page;
  page.shape = PageShape::kCurl;
  std::vector<SceneLight> lights = RakingLights(3, 30.0, 90.0);
  lights.push_back(UvLight());
  const Scanned run = ProcessOn(DefaultRig(), page, TextureOptions(), SceneOptions(), 11,
                                PipelineOptions(), "lights_curl", 1, LightOptions(), lights);
  ASSERT_TRUE(run.result.status.ok()) << run.result.status.message();
  const PageResult& leaf = run.result.pages.at(0);
  ASSERT_EQ(leaf.lights.names.size(), 4u);
  EXPECT_FALSE(leaf.lights.normals.empty()) << "three raking lights of known direction";
  // Each image over its shading (its mean over two squares, which is the board's own mean where
  // the light is even), so a corner is found where the board has it, not where a light's slope
  // of shade across a square pulls the detector.
  auto unshaded = [](const cv::Mat& image) {
    cv::Mat level, mean;
    image.convertTo(level, CV_32F);
    cv::GaussianBlur(level, mean, cv::Size(), 20);
    cv::Mat out;
    cv::divide(level, cv::max(mean, 1.0), out, 128);
    out.convertTo(out, CV_8U);
    return out;
  };
  const std::vector<cv::Point2d> corners = TrueCorners(page.size_mm);
  const Rigid2D to_true = FlatToTrue(run.scan.gantry->truth(), leaf);
  const std::vector<cv::Point2f> white =
      MeasureCorners(leaf, to_true, corners, unshaded(leaf.restored.image));
  for (size_t k = 0; k < leaf.lights.names.size(); ++k) {
    SCOPED_TRACE(leaf.lights.names[k]);
    const cv::Mat& image = leaf.lights.images[k];
    ASSERT_EQ(image.size(), leaf.restored.image.size());
    const std::vector<cv::Point2f> got = MeasureCorners(leaf, to_true, corners, unshaded(image));
    double sum2 = 0, worst = 0;
    int measured = 0, board = 0;
    for (size_t c = 0; c < got.size(); ++c) {
      if (!std::isfinite(white[c].x) || !std::isfinite(got[c].x)) continue;
      ++board;
      // The contrast between the squares around the corner, in this light.
      const cv::Rect window(cvRound(white[c].x) - 6, cvRound(white[c].y) - 6, 13, 13);
      double lo = 0, hi = 0;
      cv::minMaxLoc(image(window), &lo, &hi);
      const double full = image.depth() == CV_16U ? 65535 : 255;
      if (hi - lo < 12 * full / 255) continue;
      const double d = cv::norm(got[c] - white[c]);
      sum2 += d * d;
      worst = std::max(worst, d);
      ++measured;
    }
    ASSERT_GT(board, 150);
    const double rms = std::sqrt(sum2 / std::max(1, measured));
    std::printf("[lights] %-10s %d of %d corners, %.3f px RMS from the texture's, worst %.3f\n",
                leaf.lights.names[k].c_str(), measured, board, rms, worst);
    EXPECT_GE(measured, 0.8 * board);
    EXPECT_LE(rms, 0.1);
  }
}

// Photometric normals. A plain curled leaf with an embossed line across it (a Gaussian
// ridge 0.2 mm high, sigma 0.5 mm, at t = 120 mm: across the flat part and up the curl) under
// four raking lights at 30 degrees. On the restored page, in the page's own frame, each column's
// ridge is where the normal's up component turns from its highest to its lowest; it must lie
// on the true line (within 0.5 mm), and the rest of the page must read flat (the curl itself
// taken out by the sheet's frame).
//
// Why these hold: the ridge tilts the normal by up to 13.7 degrees (0.2 / 0.5 * exp(-1/2))
// either side of its crest, 0.5 mm from it; at the page's 102 dpi (0.25 mm a pixel) those
// extremes are 4 pixels apart and found to a pixel, 0.25 mm. The page frame comes from the sheet
// (a 0.02 mm fit of the page, smoothed over a cell), so away from the ridge the normal reads
// within a few degrees of straight out.
// The RTI file: eight lamps in two rings (four at 30 degrees, four at 60, turned 45
// degrees) over a curled plain leaf give a PTM of the flat page (lights.ptm). Written and read
// back (8-bit coefficients), it relights the page as each lamp lit it: evaluated at each lamp's
// direction in the page's own frame, it gives that lamp's restored image over the leaf's pixels
// the lamp lit (not clipped, not turned away). Where the page lies flat (its normal within 5
// degrees of the table's) the eight lamps fall at two elevations, which the biquadratic fits
// exactly: what is left is the coefficients' 8 bits and the camera's noise, under 1% of full
// scale. On the curl the lamps' elevations in the page's own frame spread from grazing to high,
// and a biquadratic follows the cosine's fall only so far (PTM's own limit, which hemispherical
// harmonics ease): under 3% over the whole leaf.
TEST(Lights, APtmOfTheFlatPageRelightsItAsEachLampDid) {
  PageOptions page;
  page.shape = PageShape::kCurl;
  TextureOptions plain;
  plain.kind = TextureKind::kPlain;
  std::vector<SceneLight> lamps = RakingLights(4, 30.0, 0.0);
  for (SceneLight& l : RakingLights(4, 60.0, 45.0)) {
    l.name += "-high";
    lamps.push_back(l);
  }
  const Scanned run = ProcessOn(DefaultRig(), page, plain, SceneOptions(), 17, PipelineOptions(),
                                "ptm_curl", 1, LightOptions(), lamps);
  ASSERT_TRUE(run.result.status.ok()) << run.result.status.message();
  const PageResult& leaf = run.result.pages.at(0);
  ASSERT_TRUE(leaf.lights.ptm.status.ok()) << leaf.lights.ptm.status.message();
  bool listed = false;
  for (const StageReport& stage : run.result.report.stages) {
    for (const std::string& file : stage.outputs) listed = listed || file == "lights.ptm";
  }
  EXPECT_TRUE(listed) << "lights.ptm is not among the outputs";
  const int leaf_px = cv::countNonZero(leaf.restored.mask);
  EXPECT_GT(cv::countNonZero(leaf.lights.ptm.valid), 0.95 * leaf_px);
  // Through the file.
  const std::string file =
      (fs::temp_directory_path() / ("vellum_ptm_" + std::to_string(getpid()) + ".ptm")).string();
  ASSERT_TRUE(WritePtm(file, leaf.lights.ptm).ok());
  PtmResult back;
  const Status read = ReadPtm(file, &back);
  fs::remove(file);
  ASSERT_TRUE(read.ok()) << read.message();
  ASSERT_EQ(back.coefficients.size(), leaf.restored.image.size());
  EXPECT_EQ(back.solved, cv::countNonZero(leaf.lights.ptm.valid));
  const SheetFrame frame = RestoredSheetFrame(leaf.mesh, leaf.flat.flat, leaf.restored);
  for (size_t k = 0; k < lamps.size(); ++k) {
    const cv::Mat& image = leaf.lights.images[k];
    ASSERT_EQ(image.type(), CV_8U);
    double sum2 = 0, flat2 = 0;
    int n = 0, flat = 0;
    for (int v = 0; v < image.rows; v += 2) {
      for (int u = 0; u < image.cols; u += 2) {
        const uint8_t level = image.at<uint8_t>(v, u);
        if (!back.valid.at<uint8_t>(v, u) || level >= 250 || level < 8) continue;
        const cv::Vec3d d = lamps[k].direction;
        const double lu = d.dot(cv::Vec3d(frame.right.at<cv::Vec3f>(v, u)));
        const double lv = d.dot(cv::Vec3d(frame.up.at<cv::Vec3f>(v, u)));
        const double e =
            PtmLuminance(back.coefficients.at<cv::Vec<float, 6>>(v, u), lu, lv) - level / 255.0;
        sum2 += e * e;
        ++n;
        if (frame.normal.at<cv::Vec3f>(v, u)[2] > std::cos(5 * M_PI / 180)) flat2 += e * e, ++flat;
      }
    }
    ASSERT_GT(flat, 1000) << lamps[k].name;
    const double rms = std::sqrt(sum2 / n), flat_rms = std::sqrt(flat2 / flat);
    std::printf(
        "[ptm] %s: relit within %.4f of full scale where flat (%d px), %.4f over the leaf "
        "(%d px), RMS\n",
        lamps[k].name.c_str(), flat_rms, flat, rms, n);
    EXPECT_LT(flat_rms, 0.01) << lamps[k].name;
    EXPECT_LT(rms, 0.03) << lamps[k].name;
  }
}

TEST(Lights, PhotometricNormalsFindAnEmbossedLineOnACurledLeaf) {
  PageOptions page;
  page.shape = PageShape::kCurl;
  page.ridge_height_mm = 0.2;
  page.ridge_t_mm = 120;
  page.ridge_sigma_mm = 0.5;
  TextureOptions plain;
  plain.kind = TextureKind::kPlain;
  const Scanned run = ProcessOn(DefaultRig(), page, plain, SceneOptions(), 13, PipelineOptions(),
                                "ridge_curl", 1, LightOptions(), RakingLights(4, 30.0, 45.0));
  ASSERT_TRUE(run.result.status.ok()) << run.result.status.message();
  const PageResult& leaf = run.result.pages.at(0);
  const cv::Mat& normals = leaf.lights.normals;
  ASSERT_EQ(normals.type(), CV_32FC3);
  ASSERT_EQ(normals.size(), leaf.restored.image.size());
  // The true line on the restored page: two of its points through the page's flat frame.
  const Rigid2D to_true = FlatToTrue(run.scan.gantry->truth(), leaf);
  const Rigid2D back{-to_true.angle, {0, 0}};
  const cv::Point2d shift = back.Apply(-to_true.translation);
  auto pixel = [&](double s, double t) {
    return ApplyAffine(leaf.restored.pixel_from_flat, back.Apply(cv::Point2d(s, t)) + shift);
  };
  const cv::Point2d a = pixel(0, page.ridge_t_mm), b = pixel(page.size_mm.width, page.ridge_t_mm);
  const double px_per_mm = leaf.restored.dpi / 25.4;
  const int half = static_cast<int>(std::ceil(4 * px_per_mm));  // Search 4 mm either side.
  std::vector<double> off_mm;
  double tilt_max = 0;
  int columns = 0;
  for (int u = static_cast<int>(std::ceil(std::min(a.x, b.x))) + half;
       u < static_cast<int>(std::max(a.x, b.x)) - half; ++u) {
    const double expected = a.y + (b.y - a.y) * (u - a.x) / (b.x - a.x);
    const int r0 = cvRound(expected) - half, r1 = cvRound(expected) + half;
    if (r0 < 0 || r1 >= normals.rows) continue;
    double hi = -2, lo = 2;
    int at_hi = -1, at_lo = -1;
    bool whole = true;
    for (int v = r0; v <= r1; ++v) {
      const cv::Vec3f n = normals.at<cv::Vec3f>(v, u);
      if (n[2] <= 0) whole = false;
      if (n[1] > hi) hi = n[1], at_hi = v;
      if (n[1] < lo) lo = n[1], at_lo = v;
    }
    if (!whole) continue;
    ++columns;
    tilt_max = std::max(tilt_max, std::asin(std::min(1.0, (hi - lo) / 2)) * 180 / M_PI);
    off_mm.push_back(std::fabs(0.5 * (at_hi + at_lo) - expected) / px_per_mm);
  }
  ASSERT_GT(columns, 0.8 * page.size_mm.width * px_per_mm - 2 * half);
  std::sort(off_mm.begin(), off_mm.end());
  const double median = off_mm[off_mm.size() / 2], p95 = off_mm[off_mm.size() * 95 / 100];
  // Away from the ridge (more than 4 mm), the page reads flat in its own frame.
  std::vector<double> tilt;
  for (int v = 0; v < normals.rows; v += 3) {
    for (int u = 0; u < normals.cols; u += 3) {
      const cv::Vec3f n = normals.at<cv::Vec3f>(v, u);
      if (n[2] <= 0) continue;
      const double expected = a.y + (b.y - a.y) * (u - a.x) / (b.x - a.x);
      if (std::fabs(v - expected) < half) continue;
      tilt.push_back(std::acos(std::min(1.0f, n[2])) * 180 / M_PI);
    }
  }
  std::sort(tilt.begin(), tilt.end());
  const double flat_median = tilt[tilt.size() / 2], flat_p95 = tilt[tilt.size() * 95 / 100];
  std::printf(
      "[ridge] %d columns: found %.3f mm from the true line (median), %.3f (95th); tilt across "
      "it up to %.1f deg; elsewhere %.2f deg (median), %.2f (95th)\n",
      columns, median, p95, tilt_max, flat_median, flat_p95);
  EXPECT_LE(median, 0.25);
  EXPECT_LE(p95, 0.5);
  EXPECT_GT(tilt_max, 8.0);
  EXPECT_LT(flat_median, 2.0);
  EXPECT_LT(flat_p95, 5.0);
}

INSTANTIATE_TEST_SUITE_P(Scenes, Leaves,
                         ::testing::Values(Scene{"dark_table_curl", PageShape::kCurl},
                                           Scene{"support_curl", PageShape::kCurl, true},
                                           Scene{"support_fold", PageShape::kFold, true},
                                           Scene{"frame_curl", PageShape::kCurl, false, true},
                                           Scene{"burnt_support_curl", PageShape::kCurl, true,
                                                 false, false, OutlineKind::kBurnt, 0.3},
                                           Scene{"ripple", PageShape::kRipple},
                                           Scene{"spread", PageShape::kFlat, false, false, true}),
                         [](const ::testing::TestParamInfo<Scene>& info) {
                           return std::string(info.param.name);
                         });

}  // namespace
}  // namespace vellum
