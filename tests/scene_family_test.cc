// The scene family (core/sim/scene_family.h) through `vellum process`'s pipeline (RunPipeline),
// each scan against the virtual gantry's truth: a property test over scenes nobody tuned for.
// Every scan either meets the bars or raises a warning (exit 3): a wrong and silent result is
// the one outcome not allowed. Each scan is counted as met and unflagged, met but flagged (a
// false alarm), missed but flagged, or missed and unflagged (silent and wrong); an error (no
// leaf found) is loud, and counts as missed but flagged.
//
// The bars, per page (a leaf, or each page of a spread), and why they hold:
// - the pages: one for a leaf, two for a book (left and right);
// - the outline: IoU >= 0.98 against the pixels that see the page (on a 600 x 800 px leaf, the
//   outline within about 3 px all round: the decoder's fit spreads a rim over 3 px);
// - the flattened sheet against the true flat page: RMS <= 0.08 mm after a rigid fit, not
//   mirrored (the sheet's nodes are good to about 0.01 mm where measured; the bar leaves room
//   for the rim's extrapolated cells);
// - Experiment I on a checkerboard page: its corners against the page's true layout after a
//   least-squares homography, mean <= 0.15 px and 0.04 mm, and against the true page (rigid, in
//   mm through the restored page's own map) RMS <= 0.08 mm, the mirrored fit at least ten times
//   worse; at least 3/4 of the corners measured (1/2 on a burnt leaf, whose edges eat corners);
// - the restored mask: no pixel farther than 1.5 mm from the leaf (the rim's mixed pixels: 5 px
//   of the camera's 0.25 mm, and a pixel of the restored page).
//
// The sample: VELLUM_FAMILY_SCENES scenes (default 20, what CI runs) from seed
// VELLUM_FAMILY_FIRST (default 1). With 200 or more (ctest -L family_full, by hand), the run must
// also meet at least 90% of its scans and raise false alarms on at most 5% of those it meets.
// VELLUM_FAMILY_TABLE=FILE writes the counts as a Markdown table; VELLUM_FAMILY_DUMP=DIR keeps
// each missed or flagged scan's results and a picture of its outline against the truth.
#include "core/sim/scene_family.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "core/common/depth.h"
#include "core/sim/evaluate.h"
#include "pipeline/process.h"
#include "pipeline/qc.h"
#include "tests/page_measure.h"

namespace vellum {
namespace {

namespace fs = std::filesystem;

struct Outcome {
  bool met = false, flagged = false;
  std::string missed;    // Why the bars were not met.
  std::string warnings;  // The warning codes, or the error.
  double iou = 1, sheet_mm = 0, exp1_px = 0, exp1_mm = 0, rigid_mm = 0;
  int off_mask = 0;
  int holes = 0;        // Holes in the outline found.
  std::string figures;  // The pipeline's own figures, per page, for reading a run's table.
};

uint64_t EnvNumber(const char* name, uint64_t fallback) {
  const char* v = std::getenv(name);
  return v && *v ? std::strtoull(v, nullptr, 10) : fallback;
}

// A picture of the found outline (blue: leaf missed; red: taken beyond the leaf) on the texture.
void DumpOutline(const std::string& path, const cv::Mat& texture, const cv::Mat& found,
                 const cv::Mat& truth) {
  cv::Mat show = EightBitBgr(texture).clone();
  show.setTo(cv::Scalar(255, 0, 0), truth & ~found);
  show.setTo(cv::Scalar(0, 0, 255), found & ~truth);
  cv::imwrite(path, show);
}

// A family scene's scan as `vellum process` takes it (named `name`, the object said as drawn).
ProcessInput FamilyInput(const FamilyScene& s, const SimulatedScan& scan, const std::string& name) {
  ProcessInput input;
  input.scan_dir = name;
  input.calibration_path = "the virtual gantry's rig";
  input.scan = AsScan(scan);
  input.scan.object = s.said;
  input.calibration = scan.gantry->rig();
  return input;
}

Outcome ScanAndMeasure(const FamilyScene& s) {
  Outcome o;
  const SimulatedScan scan =
      SimulateScan(DefaultRig(), s.page, s.texture, s.scene, s.seed, s.light);
  const ProcessInput input = FamilyInput(s, scan, "family-" + std::to_string(s.seed));
  const std::string out =
      (fs::temp_directory_path() / ("vellum_family_" + std::to_string(getpid()))).string();
  fs::remove_all(out);
  const char* dump = std::getenv("VELLUM_FAMILY_DUMP");
  const ProcessResult result = RunPipeline(input, PipelineOptions(), out);
  auto finish = [&] {
    if (dump && (!o.met || o.flagged)) {  // Misses and false alarms.
      const std::string dir = std::string(dump) + "/" + std::to_string(s.seed);
      fs::create_directories(dir);
      // A failed run leaves no results folder (they are written whole or not at all).
      if (fs::exists(out))
        fs::copy(out, dir, fs::copy_options::recursive | fs::copy_options::overwrite_existing);
      if (!result.outline.mask.empty()) {
        DumpOutline(dir + "/outline_vs_truth.png", input.scan.texture, result.outline.mask,
                    scan.gantry->truth().on_page);
      }
    }
    fs::remove_all(out);
    return o;
  };
  if (!result.status.ok()) {
    o.flagged = true;  // An error is loud.
    o.missed = "error";
    o.warnings = result.status.message();
    return finish();
  }
  o.holes = result.outline.holes;
  for (const Warning& w : result.report.Warnings())
    o.warnings += (o.warnings.empty() ? "" : ",") + w.code;
  o.flagged = !o.warnings.empty();
  for (const std::string& page : result.report.Pages()) {
    char figures[200];
    std::snprintf(figures, sizeof(figures),
                  "%s%sstrain %.4f/%.4f/%.4f warp %.2f px grid %s sampling %.0f/%.0f ppi",
                  o.figures.empty() ? "" : "; ", page.empty() ? "" : (page + " ").c_str(),
                  result.report.Number("flattening", "mean_strain", page),
                  result.report.Number("flattening", "widespread_strain", page),
                  result.report.Number("flattening", "max_strain", page),
                  result.report.Number("sheet", "warp_error_px", page),
                  result.report.Text("sheet", "grid", page).c_str(),
                  result.report.Number("sampling", "p5_ppi", page),
                  result.report.Number("sampling", "median_ppi", page));
    o.figures += figures;
  }
  o.figures += "; unseen beside " + std::to_string(result.outline.unseen_share) + ", edge-on " +
               std::to_string(result.outline.edge_on_share);
  const GroundTruth& truth = scan.gantry->truth();
  const std::vector<Page>& pages = scan.gantry->pages();
  std::ostringstream missed;
  if (result.pages.size() != pages.size()) {
    missed << result.pages.size() << " pages found of " << pages.size() << "; ";
  }
  // What the gutter keeps from view is no part of the restored pages, and no outline on camera
  // pixels shows it: past the station's own limit the pages are not restored whole.
  if (pages.size() == 2) {
    const double hidden = TrueGutter(*scan.gantry).hidden_mm;
    o.figures += "; gutter hides " + std::to_string(hidden) + " mm, measured " +
                 std::to_string(result.report.Number("outline", "gutter_unseen_mm")) + " to " +
                 std::to_string(result.report.Number("outline", "gutter_unseen_bound_mm"));
    if (hidden > PipelineOptions().limits.max_gutter_unseen_mm) {
      missed << "the gutter keeps " << hidden << " mm of the pages from view; ";
    }
  }
  for (size_t k = 0; k < std::min(pages.size(), result.pages.size()); ++k) {
    const PageResult& page = result.pages[k];
    const std::string name = page.name.empty() ? "" : page.name + " page: ";
    const GroundTruth mine = OnePage(truth, static_cast<int>(k + 1));
    const double iou =
        k < result.outline.pages.size() ? MaskIoU(result.outline.pages[k], mine.on_page) : 0.0;
    o.iou = std::min(o.iou, iou);
    if (iou < 0.98) missed << name << "outline IoU " << iou << "; ";
    const FlatErrorStats flat = CompareFlat(mine, page.mesh, page.flat.flat);
    o.sheet_mm = std::max(o.sheet_mm, flat.rms_mm);
    if (flat.rms_mm > 0.08) missed << name << "sheet " << flat.rms_mm << " mm RMS; ";
    if (flat.mirrored) missed << name << "sheet mirrored; ";
    const Rigid2D to_true = FlatToTrue(mine, page);
    cv::Mat off_leaf;
    const int off = MaskOffLeaf(page, to_true, pages[k], 1.5, nullptr, &off_leaf);
    o.off_mask += off;
    if (off > 0) {
      missed << name << off << " restored mask pixels off the leaf; ";
      if (dump) {
        // The restored page with its mask's pixels off the leaf in red.
        cv::Mat show = EightBitBgr(page.restored.image).clone();
        cv::dilate(off_leaf, off_leaf, cv::Mat::ones(5, 5, CV_8U));
        show.setTo(cv::Scalar(0, 0, 255), off_leaf);
        fs::create_directories(std::string(dump) + "/" + std::to_string(s.seed));
        cv::imwrite(std::string(dump) + "/" + std::to_string(s.seed) + "/off_leaf" +
                        (page.name.empty() ? "" : "_" + page.name) + ".png",
                    show);
      }
    }
    if (s.texture.kind == TextureKind::kCheckerboard) {
      const std::vector<cv::Point2d> corners = TrueCorners(pages[k].options().size_mm, s.texture);
      const Measured m = ExperimentOne(page, MeasureCorners(page, to_true, corners),
                                       LayoutControl(corners, page.restored.dpi), corners);
      o.exp1_px = std::max(o.exp1_px, m.mean_px);
      o.exp1_mm = std::max(o.exp1_mm, m.mean_mm);
      o.rigid_mm = std::max(o.rigid_mm, m.rms_mm);
      const bool burnt = s.page.outline == OutlineKind::kBurnt;
      if (m.corners < static_cast<int>(corners.size()) * (burnt ? 2 : 3) / 4) {
        missed << name << m.corners << " of " << corners.size() << " corners; ";
      } else if (m.mean_px > 0.15 || m.mean_mm > 0.04 || m.rms_mm > 0.08 ||
                 !(m.rms_mirrored_mm > 10 * m.rms_mm)) {
        missed << name << "Experiment I " << m.mean_px << " px, " << m.mean_mm << " mm, rigid "
               << m.rms_mm << " mm (mirrored " << m.rms_mirrored_mm << "); ";
      }
    }
  }
  o.missed = missed.str();
  o.met = o.missed.empty();
  return finish();
}

// The scenes we name, each to meet every bar with no warning: a curled, folded, waved and
// coned leaf lying with its rim 0, 0.05 and 0.1 mm above a dark table (albedo 0.15: the rim's
// step at 0 mm is nothing, at 0.05 mm a tenth of a millimetre's noise on the table; the leaf's
// look sets it apart), a 0.1 mm leaf on a support as bright as paper (0.8) and in a paper frame
// (the step alone sets it apart), a burnt folded leaf 0.1 mm thick (whole, every hole kept), and
// open books whose pages rise 70 and 30 degrees into a gutter 2 mm wide (two pages). Checkerboard
// pages, for Experiment I; the default renderer (noise 1.5 DN, no blur).
struct Named {
  std::string name;
  FamilyScene scene;
};

std::vector<Named> MustShow() {
  std::vector<Named> out;
  auto base = [](uint64_t seed) {
    FamilyScene s;
    s.seed = seed;
    s.texture.kind = TextureKind::kCheckerboard;
    s.light.table_albedo = 0.15;
    s.said = ObjectKind::kAuto;
    return s;
  };
  const struct {
    const char* name;
    PageShape shape;
  } shapes[] = {{"curl", PageShape::kCurl},
                {"fold", PageShape::kFold},
                {"wave", PageShape::kRipple},
                {"cone", PageShape::kCone}};
  uint64_t seed = 100;
  for (const auto& shape : shapes) {
    for (double rim : {0.0, 0.05, 0.1}) {
      FamilyScene s = base(seed++);
      s.shape = shape.name;
      s.page.shape = shape.shape;
      if (shape.shape == PageShape::kRipple) s.page.ripple_slope_deg = 20;  // A wave.
      s.page.thickness_mm = rim;
      char name[64];
      std::snprintf(name, sizeof(name), "%s_rim_%03.0f_um_dark_table", shape.name, rim * 1000);
      out.push_back({name, s});
    }
  }
  FamilyScene support = base(seed++);
  support.shape = "curl";
  support.page.shape = PageShape::kCurl;
  support.page.thickness_mm = 0.1;
  support.scene.support = true;
  support.scene.support_albedo = 0.8;
  out.push_back({"curl_rim_100_um_light_support", support});
  FamilyScene frame = support;
  frame.seed = seed++;
  frame.scene.support = false;
  frame.scene.frame = true;
  out.push_back({"curl_rim_100_um_paper_frame", frame});
  FamilyScene burnt = base(seed++);
  burnt.shape = "fold";
  burnt.page.shape = PageShape::kFold;
  burnt.page.thickness_mm = 0.1;
  burnt.page.outline = OutlineKind::kBurnt;
  out.push_back({"burnt_fold_rim_100_um_dark_table", burnt});
  for (double angle : {70.0, 30.0}) {
    FamilyScene book = base(seed++);
    book.shape = "spread";
    book.page.size_mm = {170.0, 230.0};
    book.scene.spread = true;
    book.page.gutter_angle_deg = angle;
    book.light.table_albedo = 0.35;
    out.push_back({"spread_" + std::to_string(static_cast<int>(angle)) + "_deg", book});
  }
  return out;
}

class MustShowScenes : public ::testing::TestWithParam<Named> {};

TEST_P(MustShowScenes, MeetTheBarsWithNoWarning) {
  const Named& named = GetParam();
  const Outcome o = ScanAndMeasure(named.scene);
  std::printf(
      "[must] %-34s %s IoU %.4f sheet %.3f mm, Exp I %.3f px %.4f mm rigid %.3f mm, "
      "mask off %d | %s%s%s\n",
      named.name.c_str(), o.met ? "met " : "MISS", o.iou, o.sheet_mm, o.exp1_px, o.exp1_mm,
      o.rigid_mm, o.off_mask, o.warnings.c_str(), o.missed.empty() ? "" : " | ", o.missed.c_str());
  EXPECT_TRUE(o.met) << o.missed;
  EXPECT_FALSE(o.flagged) << o.warnings;
  if (named.scene.page.outline == OutlineKind::kBurnt) {
    EXPECT_EQ(o.holes, named.scene.page.holes) << "every hole kept, none added";
  }
}

INSTANTIATE_TEST_SUITE_P(Named, MustShowScenes, ::testing::ValuesIn(MustShow()),
                         [](const ::testing::TestParamInfo<Named>& info) {
                           return info.param.name;
                         });

// Scenes of the full run that were missed and are met now, each by the change named: drawn by
// their seed, met without a warning, so that the change cannot be lost unseen between full runs.
std::vector<Named> OnceMissed() {
  return {
      // A frame taken with the leaf: its face judged along its outer outline, not along the
      // leaf's dark squares cut out of it (PlaneAlongOutline).
      {"seed_177_developable_flush_in_a_light_frame", DrawFamilyScene(177)},
      // A folded leaf's flat halves on a dark support are not the surround (FitSurround keeps
      // planes parallel to the table's).
      {"seed_145_fold_on_a_dark_support", DrawFamilyScene(145)},
      // A frame the surround's samples caught, tilted, fitted again along its outline; the table
      // showing in the window beside the leaf known by its look (FindLeaf's InWindow cut).
      {"seed_118_curl_in_a_frame_it_nearly_fills", DrawFamilyScene(118)},
      // A creased and a waved leaf in a frame's window, rising above its face away from where
      // they rest on the table (InWindow: resting on the table along a share of the rim).
      {"seed_1_crease_in_a_dark_frame", DrawFamilyScene(1)},
      {"seed_101_wave_in_a_dark_frame", DrawFamilyScene(101)},
      // A cone 0.1 mm thick on a table nearly its shade, whose cut strayed three blocks past its
      // rim: no leaf seed on the rim, so the leaf keeps to it (RefineRim).
      {"seed_184_cone_on_a_table_of_its_shade", DrawFamilyScene(184)},
  };
}

INSTANTIATE_TEST_SUITE_P(Family, MustShowScenes, ::testing::ValuesIn(OnceMissed()),
                         [](const ::testing::TestParamInfo<Named>& info) {
                           return info.param.name;
                         });

// A curl whose edge rolls past the camera's line of sight (seed 105: the last 11 mm of the page
// hidden under a sliver of its edge, the sheet 0.46 mm off the true page there) is never
// restored silently: it is flagged edge_on, seen edge-on along a third of its outline. A curl
// that measures alike but hides nothing (seed 142) is flagged too, and still met.
TEST(SceneFamily, ACurlRolledPastTheCamerasSightIsFlagged) {
  const Outcome hides = ScanAndMeasure(DrawFamilyScene(105));
  std::printf("[edge-on] seed 105: %s | %s | %s\n", hides.met ? "met" : "MISS",
              hides.warnings.c_str(), hides.figures.c_str());
  if (!hides.met) {
    EXPECT_NE(hides.warnings.find("edge_on"), std::string::npos) << hides.missed;
  }
  const Outcome shows = ScanAndMeasure(DrawFamilyScene(142));
  std::printf("[edge-on] seed 142: %s | %s | %s\n", shows.met ? "met" : "MISS",
              shows.warnings.c_str(), shows.figures.c_str());
  EXPECT_TRUE(shows.met) << shows.missed;
}

// A leaf at the view's edge (DrawEdgeScene: the family's scenes moved square to one side of the
// view, half running off it by 2 to 40 mm, half lying 2 to 15 mm inside it), judged against the
// virtual gantry's truth: the camera pixels that see the page (truth.on_page).
// - Where the page reaches the view's outermost line of pixels along 10 px or more (2.5 mm of
//   its edge, more than the rim's blur and noise can fake), part of the leaf is not in the
//   restored page: the scan must not PASS (an error, "no leaf found", is loud too). The check
//   that should say so, "leaf in view", is counted apart.
// - Where the page lies 8 px (2 mm) or more inside every side, the leaf is wholly in view:
//   "leaf in view" must pass when the leaf was found (its outline's IoU with the truth 0.9 or
//   more). A warning that cries wolf there is a defect too. An outline that took something else
//   (a frame) must not pass.
// Between the two (the page's edge within 2 mm of the border) either answer is allowed.
TEST(SceneFamily, ALeafAtTheViewsEdgeNeverPassesWhenItRunsOffAndIsInViewWhenInside) {
  const uint64_t count = EnvNumber("VELLUM_EDGE_SCENES", 16);
  const uint64_t first = EnvNumber("VELLUM_EDGE_FIRST", 1);
  int off = 0, off_in_view_failed = 0, inside = 0, between = 0;
  for (uint64_t seed = first; seed < first + count; ++seed) {
    const FamilyScene s = DrawEdgeScene(seed);
    const SimulatedScan scan =
        SimulateScan(DefaultRig(), s.page, s.texture, s.scene, s.seed, s.light);
    const cv::Mat& truth = scan.gantry->truth().on_page;
    // The page on the view's outermost line, per side, and its least distance from each side.
    const cv::Rect lines[4] = {
        cv::Rect(0, 0, 1, truth.rows), cv::Rect(truth.cols - 1, 0, 1, truth.rows),
        cv::Rect(0, 0, truth.cols, 1), cv::Rect(0, truth.rows - 1, truth.cols, 1)};
    int on_border = 0;
    for (const cv::Rect& line : lines)
      on_border = std::max(on_border, cv::countNonZero(truth(line)));
    const cv::Rect inner = cv::Rect(8, 8, truth.cols - 16, truth.rows - 16);
    ASSERT_GT(cv::countNonZero(truth), 0) << "the page is out of sight: " << s.Describe();
    const bool runs_off = on_border >= 10;
    const bool well_inside = cv::countNonZero(truth) == cv::countNonZero(truth(inner));
    const ProcessInput input = FamilyInput(s, scan, "edge-" + std::to_string(seed));
    const std::string out =
        (fs::temp_directory_path() / ("vellum_edge_" + std::to_string(getpid()))).string();
    fs::remove_all(out);
    const ProcessResult result = RunPipeline(input, PipelineOptions(), out);
    fs::remove_all(out);
    if (const char* dump = std::getenv("VELLUM_EDGE_DUMP"); dump && !result.outline.mask.empty()) {
      DumpOutline(std::string(dump) + "/edge_" + std::to_string(seed) + ".png", input.scan.texture,
                  result.outline.mask, truth);
    }
    std::string verdict = "error", in_view = "-", warnings;
    for (const Warning& w : result.report.Warnings()) warnings += w.code + " ";
    if (result.status.ok()) {
      const QcResult qc = AssessQuality(result.report);
      verdict = VerdictName(qc.verdict);
      for (const QcCheck& check : qc.checks) {
        if (check.name == "leaf in view") in_view = VerdictName(check.verdict);
        if (check.verdict != QcVerdict::kPass) warnings += check.name + ": " + check.detail + "; ";
      }
    }
    std::printf("[edge] %-7s %-5s leaf in view %-4s | %s | %s%s\n",
                runs_off      ? "off"
                : well_inside ? "inside"
                              : "between",
                verdict.c_str(), in_view.c_str(), s.Describe().c_str(), warnings.c_str(),
                result.status.ok() ? "" : result.status.message().c_str());
    std::fflush(stdout);
    if (runs_off) {
      ++off;
      off_in_view_failed += in_view == "fail";
      EXPECT_NE(verdict, "pass") << "a leaf running off the view (" << on_border
                                 << " px of its page on the border) passed: " << s.Describe();
    } else if (well_inside) {
      ++inside;
      // Against the leaf found (a frame taken for the leaf runs off the view: a wrong outline,
      // which must not pass either).
      const cv::Mat& found = result.outline.mask;
      const double iou = found.empty() ? 0.0 : MaskIoU(found, truth);
      if (iou >= 0.9) {
        EXPECT_NE(in_view, "fail")
            << "a leaf inside the view failed \"leaf in view\": " << s.Describe();
      } else {
        EXPECT_NE(verdict, "pass")
            << "an outline " << iou << " IoU off the leaf passed: " << s.Describe();
      }
    } else {
      ++between;
    }
  }
  std::printf(
      "[edge] %d ran off the view (%d failed on \"leaf in view\"), %d lay inside it, %d "
      "within 2 mm of its border\n",
      off, off_in_view_failed, inside, between);
}

// The live outline (LeafInPreview: what vellum-viewer draws while the leaf is placed, and the
// sides it sends with the scan, where it runs off the view) over the family and the edge family,
// against the truth at the preview's size (640 x 480, by area, as vellum-camera sends it).
// No outline ("as bright as its surround") is allowed: the scan finds the leaf by its shape. An
// outline drawn must be the leaf: one claiming more than it (under 70% of what it outlines is
// the leaf: a support or a mount taken with it) in at most 5% of the outlines drawn; a side of
// the view the leaf does not reach, claimed as one it runs off (which would flag the scan), in at
// most 1% of the scenes. A support of the leaf's very tone cannot be told from it by look: the
// bars leave room for it. VELLUM_LIVE_SCENES seeds (default 16, each drawn whole and at the edge)
// from VELLUM_LIVE_FIRST (default 1); VELLUM_LIVE_DUMP=DIR keeps each outline against the truth.
TEST(SceneFamily, TheLiveOutlineIsTheLeafAndRunsOffOnlyWhereTheLeafDoes) {
  const uint64_t count = EnvNumber("VELLUM_LIVE_SCENES", 16);
  const uint64_t first = EnvNumber("VELLUM_LIVE_FIRST", 1);
  int scenes = 0, drawn = 0, wrong = 0, false_off = 0, seen_off = 0, truly_off = 0;
  for (uint64_t seed = first; seed < first + count; ++seed) {
    for (const FamilyScene& s : {DrawFamilyScene(seed), DrawEdgeScene(seed)}) {
      const VirtualGantry gantry(DefaultRig(), s.page, s.texture, s.light, s.scene);
      const cv::Mat preview = PreviewOf(gantry.RenderTexture(s.seed));
      cv::Mat truth;
      cv::resize(gantry.truth().on_page, truth, preview.size(), 0, 0, cv::INTER_AREA);
      truth = truth > 127;
      const Outline live = LeafInPreview(preview);
      const int truth_sides = ViewSidesReached(truth, OutlineOptions().border_px);
      ++scenes;
      truly_off += truth_sides != 0;
      double precision = 1;
      int sides = 0;
      if (live.status.ok()) {
        ++drawn;
        const int leaf = cv::countNonZero(live.mask & truth);
        precision = static_cast<double>(leaf) / std::max(1, cv::countNonZero(live.mask));
        sides = live.touches_border ? ViewSidesReached(live.mask, OutlineOptions().border_px) : 0;
        wrong += precision < 0.7;
        false_off += (sides & ~truth_sides) != 0;
        seen_off += (sides & truth_sides) != 0;
      }
      std::printf("[live] %-5s precision %.2f sides %-12s truth %-12s %s | %s\n",
                  s.edge_side < 0 ? "whole" : "edge", precision, ViewSidesText(sides).c_str(),
                  ViewSidesText(truth_sides).c_str(),
                  live.status.ok() ? "" : live.status.message().c_str(), s.Describe().c_str());
      std::fflush(stdout);
      if (const char* dump = std::getenv("VELLUM_LIVE_DUMP"); dump && live.status.ok()) {
        DumpOutline(std::string(dump) + "/live_" + std::to_string(seed) +
                        (s.edge_side < 0 ? "" : "_edge") + ".png",
                    preview, live.mask, truth);
      }
    }
  }
  std::printf(
      "[live] %d scenes: %d outlines drawn, %d claiming more than the leaf; %d saw the "
      "leaf off the view of %d that run off, %d claimed a side the leaf does not reach\n",
      scenes, drawn, wrong, seen_off, truly_off, false_off);
  EXPECT_LE(wrong, 0.05 * drawn) << "outlines claiming a support or a mount with the leaf";
  EXPECT_LE(false_off, 0.01 * scenes) << "sides claimed that the leaf does not reach";
  EXPECT_GT(seen_off, 0) << "the live outline never saw a leaf run off the view";
}

TEST(SceneFamily, EveryScanMeetsTheBarsOrIsFlagged) {
  const uint64_t count = EnvNumber("VELLUM_FAMILY_SCENES", 20);
  const uint64_t first = EnvNumber("VELLUM_FAMILY_FIRST", 1);
  int met_clean = 0, met_flagged = 0, missed_flagged = 0, missed_silent = 0;
  for (uint64_t seed = first; seed < first + count; ++seed) {
    const FamilyScene scene = DrawFamilyScene(seed);
    const Outcome o = ScanAndMeasure(scene);
    (o.met ? (o.flagged ? met_flagged : met_clean)
           : (o.flagged ? missed_flagged : missed_silent))++;
    std::printf(
        "[family] %-4s %-7s IoU %.4f sheet %.3f mm, Exp I %.3f px %.4f mm rigid %.3f mm, "
        "mask off %d | %s | %s%s%s | %s\n",
        o.met ? "met" : "MISS", o.flagged ? "flagged" : "clean", o.iou, o.sheet_mm, o.exp1_px,
        o.exp1_mm, o.rigid_mm, o.off_mask, scene.Describe().c_str(), o.warnings.c_str(),
        o.missed.empty() ? "" : " | ", o.missed.c_str(), o.figures.c_str());
    std::fflush(stdout);
    if (!o.met && !o.flagged) {
      ADD_FAILURE() << "silent and wrong: " << scene.Describe() << ": " << o.missed;
    }
  }
  const int met = met_clean + met_flagged;
  char table[1024];
  std::snprintf(table, sizeof(table),
                "| scenes | met, unflagged | met, flagged (false alarms) | missed, flagged | "
                "missed, unflagged (silent) |\n|---|---|---|---|---|\n| %llu (seeds %llu-%llu) | "
                "%d | %d | %d | %d |\n",
                static_cast<unsigned long long>(count), static_cast<unsigned long long>(first),
                static_cast<unsigned long long>(first + count - 1), met_clean, met_flagged,
                missed_flagged, missed_silent);
  std::printf("%s", table);
  if (const char* path = std::getenv("VELLUM_FAMILY_TABLE")) std::ofstream(path) << table;
  EXPECT_EQ(missed_silent, 0);
  if (count >= 200) {
    EXPECT_GE(met, 0.9 * count) << "met";
    EXPECT_LE(met_flagged, 0.05 * met) << "false alarms";
  }
}

}  // namespace
}  // namespace vellum
