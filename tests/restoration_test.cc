// Flattening and restoration against the virtual gantry's ground truth (issue: flattening and
// restoration). Every page is decoded, triangulated, meshed 45 x 45, flattened and compared
// with its true flat page.
//
// Why the bounds hold: node positions come from local quadratic fits over ~19 x 23 pixels of
// points whose own noise is ~0.01-0.03 mm, so each node is good to ~0.01 mm; chords of the
// curved page are shorter than its arcs by h^2 / (24 R^2) (0.02% at R = 60 mm, 0.4% at the
// fold's 15 mm ridge over ~1.5 cells), a few hundredths of a mm over the page. RMS <= 0.08 mm
// and mean edge error <= 0.3% (our bars) leave a factor 3 or more.
#include <gtest/gtest.h>

#include <cstdio>
#include <map>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "core/decode/decode.h"
#include "core/flatten/flatten.h"
#include "core/geometry/rigid2d.h"
#include "core/geometry/triangulate.h"
#include "core/restore/restore.h"
#include "core/sim/evaluate.h"

namespace vellum {
namespace {

struct Pipeline {
  std::unique_ptr<VirtualGantry> gantry;
  cv::Mat texture;
  Mesh mesh;
  FlattenResult flat;
  RestoreResult restored;
};

Pipeline RunPipeline(PageShape shape, FlattenSolver solver = FlattenSolver::kGaussNewton,
                     uint64_t seed = 31, cv::Size grid = cv::Size(45, 45)) {
  Pipeline p;
  SimulatedScan scan = SimulateScan(DefaultRig(), shape, seed);
  p.gantry = std::move(scan.gantry);
  p.texture = scan.texture;
  const Triangulator tri(p.gantry->rig());
  const PointMap map = tri.Triangulate(Decode(scan.sequence, scan.frames));
  const CameraModel& cam = p.gantry->rig().camera;
  MeshOptions mo;
  mo.grid = grid;
  p.mesh = BuildMesh(map.points, SegmentPage(p.texture), mo,
                     [&](const cv::Vec3d& x) { return cam.Project(x); });
  EXPECT_TRUE(p.mesh.status.ok()) << p.mesh.status.message();
  FlattenOptions fo;
  fo.solver = solver;
  p.flat = Flatten(p.mesh, fo);
  EXPECT_TRUE(p.flat.status.ok()) << p.flat.status.message();
  RestoreOptions ro;
  p.restored = Restore(p.texture, p.mesh, p.flat.flat, cam, ro);
  EXPECT_TRUE(p.restored.status.ok()) << p.restored.status.message();
  return p;
}

class FlattenAccuracy : public ::testing::TestWithParam<PageShape> {};

TEST_P(FlattenAccuracy, NodesMatchTheTrueFlatPage) {
  const Pipeline p = RunPipeline(GetParam());
  const FlatErrorStats st = CompareFlat(p.gantry->truth(), p.mesh, p.flat.flat);
  std::printf(
      "[flatten] %-5s nodes %d: RMS %.4f mm, max %.4f mm, mean edge error %.4f%%, "
      "strain mean %.2e max %.2e, %d iterations, %d folds\n",
      ToString(GetParam()), st.nodes, st.rms_mm, st.max_mm, 100 * st.mean_edge_error,
      p.flat.mean_strain, p.flat.max_strain, p.flat.iterations, p.flat.folded_quads);
  EXPECT_GT(st.nodes, 1500);  // Most of the 45 x 45 grid lies on the page.
  EXPECT_LE(st.rms_mm, 0.08);
  EXPECT_LE(st.mean_edge_error, 0.003);
  EXPECT_FALSE(st.mirrored);
  EXPECT_EQ(p.flat.folded_quads, 0);
}

INSTANTIATE_TEST_SUITE_P(Developable, FlattenAccuracy,
                         ::testing::Values(PageShape::kFlat, PageShape::kCurl, PageShape::kFold,
                                           PageShape::kCone),
                         [](const auto& info) { return std::string(ToString(info.param)); });

// Fine sheets (we ask for up to at least 300 x 300): 200 x 150 (cells of about 1 mm)
// and 300 x 300, each with most of its nodes on the page.
struct FineSheet {
  cv::Size grid;
  int min_nodes;
};

class FlattenFine : public ::testing::TestWithParam<FineSheet> {};

TEST_P(FlattenFine, MeetsTheSameBar) {
  const cv::Size grid = GetParam().grid;
  const Pipeline p = RunPipeline(PageShape::kCurl, FlattenSolver::kGaussNewton, 31, grid);
  ASSERT_TRUE(p.flat.status.ok()) << p.flat.status.message();
  const FlatErrorStats st = CompareFlat(p.gantry->truth(), p.mesh, p.flat.flat);
  std::printf(
      "[flatten] curl %dx%d nodes %d: RMS %.4f mm, mean edge error %.4f%%, %d folds, %d "
      "iterations\n",
      grid.width, grid.height, st.nodes, st.rms_mm, 100 * st.mean_edge_error, p.flat.folded_quads,
      p.flat.iterations);
  EXPECT_GT(st.nodes, GetParam().min_nodes);
  EXPECT_LE(st.rms_mm, 0.08);
  EXPECT_LE(st.mean_edge_error, 0.003);
  EXPECT_EQ(p.flat.folded_quads, 0);
}

INSTANTIATE_TEST_SUITE_P(Sheets, FlattenFine,
                         ::testing::Values(FineSheet{{200, 150}, 25000},
                                           FineSheet{{300, 300}, 60000}),
                         [](const auto& info) {
                           return "A" + std::to_string(info.param.grid.width) + "x" +
                                  std::to_string(info.param.grid.height);
                         });

// Real vellum is not developable: a 3 mm bubble (sigma 25 mm) must flatten without folding,
// with its residual strain reported, and restore with no fold-over or tear (every quad keeps
// its orientation, so the warp is one-to-one).
TEST(FlattenBump, ConvergesWithoutFoldingAndReportsStrain) {
  const Pipeline p = RunPipeline(PageShape::kBump);
  std::printf("[flatten] bump: strain mean %.2e max %.2e, %d iterations, %d folds\n",
              p.flat.mean_strain, p.flat.max_strain, p.flat.iterations, p.flat.folded_quads);
  EXPECT_EQ(p.flat.folded_quads, 0);
  EXPECT_GT(p.flat.max_strain, 1e-5);  // Not developable: some strain must remain.
  EXPECT_LT(p.flat.max_strain, 0.05);
  double lo, hi;
  cv::minMaxLoc(p.restored.image, &lo, &hi);
  EXPECT_GT(hi, 100);
}

// The paper's simulator and the fast solver flatten the same measured sheet to the same state,
// on every page shape, developable or not.
class FlattenSolvers : public ::testing::TestWithParam<PageShape> {};

TEST_P(FlattenSolvers, SimulatorAgreesWithGaussNewton) {
  const Pipeline p = RunPipeline(GetParam());
  FlattenOptions o;
  o.solver = FlattenSolver::kEuler;
  const FlattenResult sim = Flatten(p.mesh, o);
  ASSERT_TRUE(sim.status.ok()) << sim.status.message();
  std::vector<cv::Point2d> a, b;
  for (size_t k = 0; k < p.mesh.kind.size(); ++k) {
    if (!p.mesh.Active(static_cast<int>(k))) continue;
    a.push_back(sim.flat[k]);
    b.push_back(p.flat.flat[k]);
  }
  const Rigid2D fit = FitRigid2D(a, b);
  double worst = 0;
  for (size_t k = 0; k < a.size(); ++k) worst = std::max(worst, cv::norm(fit.Apply(a[k]) - b[k]));
  std::printf("[solvers] %s: euler %d steps vs gauss-newton %d iterations: max %.4f mm apart\n",
              ToString(GetParam()), sim.iterations, p.flat.iterations, worst);
  EXPECT_LT(worst, 0.05);
  EXPECT_EQ(sim.folded_quads, 0);
}

INSTANTIATE_TEST_SUITE_P(Pages, FlattenSolvers,
                         ::testing::Values(PageShape::kFlat, PageShape::kCurl, PageShape::kFold,
                                           PageShape::kCone, PageShape::kBump),
                         [](const auto& info) { return std::string(ToString(info.param)); });

// Gray and colour, 8 and 16 bits: the same warp, the texture's type kept, values preserved
// (a 16-bit colour restoration scaled back down matches the 8-bit gray one within rounding).
TEST(Restore, KeepsTheTexturesTypeForGrayColourAnd16Bit) {
  const Pipeline p = RunPipeline(PageShape::kCurl);
  cv::Mat colour16;
  cv::cvtColor(p.texture, colour16, cv::COLOR_GRAY2BGR);
  colour16.convertTo(colour16, CV_16UC3, 257.0);
  const RestoreResult r16 = Restore(colour16, p.mesh, p.flat.flat, p.gantry->rig().camera);
  ASSERT_TRUE(r16.status.ok()) << r16.status.message();
  EXPECT_EQ(r16.image.type(), CV_16UC3);
  ASSERT_EQ(r16.image.size(), p.restored.image.size());
  cv::Mat back;
  cv::cvtColor(r16.image, back, cv::COLOR_BGR2GRAY);
  back.convertTo(back, CV_8U, 1.0 / 257.0);
  EXPECT_LE(cv::norm(back, p.restored.image, cv::NORM_INF), 1.0);
  // Camera view: the camera's frame size.
  RestoreOptions camera_view;
  camera_view.view = RestoreView::kCamera;
  const RestoreResult rc =
      Restore(p.texture, p.mesh, p.flat.flat, p.gantry->rig().camera, camera_view);
  ASSERT_TRUE(rc.status.ok());
  EXPECT_EQ(rc.image.size(), p.gantry->rig().camera.size);
  // A texture that is not an image type we restore gives an error, not a crash.
  EXPECT_FALSE(
      Restore(cv::Mat(10, 10, CV_32F), p.mesh, p.flat.flat, p.gantry->rig().camera).status.ok());
}

// Other images of the page from the same pose (another light, the albedo, a mask) go through the
// same warp as the texture: each extra comes out exactly as it would as the texture, of its own
// type, cropped and turned alike (a leaf mask given), so the restorations register pixel for
// pixel. An extra of another size is refused.
TEST(Restore, ExtrasGoThroughTheSameWarp) {
  const Pipeline p = RunPipeline(PageShape::kCurl);
  const CameraModel& camera = p.gantry->rig().camera;
  RestoreOptions options;
  options.deskew = options.crop_to_leaf = true;
  const cv::Mat leaf = SegmentPage(p.texture);
  cv::Mat flipped, wide;
  cv::flip(p.texture, flipped, 1);  // Any other image of the texture's size.
  p.texture.convertTo(wide, CV_16U, 257.0);
  const RestoreResult all =
      Restore(p.texture, p.mesh, p.flat.flat, camera, options, leaf, {flipped, wide});
  ASSERT_TRUE(all.status.ok()) << all.status.message();
  ASSERT_EQ(all.extras.size(), 2u);
  const RestoreResult alone = Restore(flipped, p.mesh, p.flat.flat, camera, options, leaf);
  ASSERT_EQ(all.extras[0].size(), alone.image.size());
  EXPECT_EQ(cv::norm(all.extras[0], alone.image, cv::NORM_INF), 0.0);
  ASSERT_EQ(all.extras[1].type(), CV_16U);
  cv::Mat back;
  all.extras[1].convertTo(back, CV_8U, 1.0 / 257.0);
  EXPECT_LE(cv::norm(back, all.image, cv::NORM_INF), 1.0);
  const RestoreResult bad =
      Restore(p.texture, p.mesh, p.flat.flat, camera, options, leaf, {cv::Mat(10, 10, CV_8U)});
  EXPECT_FALSE(bad.status.ok());
  EXPECT_NE(bad.status.message().find("extra image 0"), std::string::npos) << bad.status.message();
  // After the restoration, through its own warp (RestoreMore), exactly the same images; a float
  // image (normals) too; an image of another size is refused.
  std::vector<cv::Mat> more;
  cv::Mat real;
  flipped.convertTo(real, CV_32F, 0.5);
  ASSERT_TRUE(RestoreMore(all, {flipped, wide, real}, &more).ok());
  ASSERT_EQ(more.size(), 3u);
  EXPECT_EQ(cv::norm(more[0], all.extras[0], cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(more[1], all.extras[1], cv::NORM_INF), 0.0);
  ASSERT_EQ(more[2].type(), CV_32F);
  cv::Mat half;
  all.extras[0].convertTo(half, CV_32F, 0.5);
  EXPECT_LE(cv::norm(more[2], half, cv::NORM_INF), 0.5);  // The 8-bit one's rounding.
  EXPECT_FALSE(RestoreMore(all, {cv::Mat(10, 10, CV_8U)}, &more).ok());
  EXPECT_FALSE(RestoreMore(RestoreResult(), {flipped}, &more).ok());
}

double Percentile(std::vector<double> v, double q) {
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(q * v.size()));
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[k];
}

// The sampling map against the truth (a true sampling map). On a flat page it is the
// camera's sampling of the table; on a curl it falls where the page slopes away from the camera
// (a slope of angle a keeps cos a of it). The map's median and 95th percentile agree with the
// truth's within 2%: the sheet's triangles are 4 x 5 mm, over which the curl's slope changes by
// under 2 degrees at its steepest (cos changes by < 2%). Its 5th percentile, at the curl's steep
// edge, within 5% (the sheet ends up to half a cell short of the page's rim, where the slope is
// steepest). The default dpi is the finest true sampling, and a dpi asked above it is flagged
// by the pipeline (CliTest).
TEST(Restore, TheSamplingMapIsTheCamerasTrueSampling) {
  for (PageShape shape : {PageShape::kFlat, PageShape::kCurl}) {
    SCOPED_TRACE(ToString(shape));
    const Pipeline p = RunPipeline(shape);
    ASSERT_EQ(p.restored.sampling.size(), p.restored.image.size());
    const SamplingSummary map = SummarizeSampling(p.restored.sampling);
    const std::vector<double> truth = TrueSampling(*p.gantry, 2.0);
    const double median = Percentile(truth, 0.5), p5 = Percentile(truth, 0.05),
                 p95 = Percentile(truth, 0.95);
    std::printf("%s: true sampling p5 %.1f median %.1f p95 %.1f; map %.1f %.1f %.1f ppi\n",
                ToString(shape), p5, median, p95, map.p5_ppi, map.median_ppi, map.p95_ppi);
    EXPECT_NEAR(map.median_ppi / median, 1.0, 0.02);
    EXPECT_NEAR(map.p95_ppi / p95, 1.0, 0.02);
    EXPECT_NEAR(map.p5_ppi / p5, 1.0, 0.05);
    EXPECT_NEAR(p.restored.dpi, std::round(p.restored.finest_ppi), 0.5);
    EXPECT_NEAR(p.restored.finest_ppi / p95, 1.0, 0.02);
    if (shape == PageShape::kCurl) {
      EXPECT_LT(p5, 0.8 * median) << "the curl should slope";
    }
  }
}

// Board corners of a restored checkerboard page, ordered top row first, left to right.
std::vector<cv::Point2f> Corners(const cv::Mat& image, cv::Size inner) {
  std::vector<cv::Point2f> corners;
  const bool found = cv::findChessboardCornersSB(image, inner, corners, cv::CALIB_CB_ACCURACY);
  if (!found) return {};
  std::sort(corners.begin(), corners.end(), [](auto a, auto b) { return a.y < b.y; });
  for (int r = 0; r < inner.height; ++r) {
    std::sort(corners.begin() + r * inner.width, corners.begin() + (r + 1) * inner.width,
              [](auto a, auto b) { return a.x < b.x; });
  }
  return corners;
}

// The paper's Experiment I on the virtual gantry: restored corners of warped pages against the
// restored flat page (the control), after a least-squares homography; then, with no scale
// freedom, restored corners in mm (through the dpi) against the true page coordinates.
TEST(ExperimentOne, RestoredCornersMatchTheControl) {
  const TextureOptions tex;
  const cv::Size page_mm(190, 240);
  const int nx = static_cast<int>((page_mm.width - 2 * tex.margin_mm) / tex.square_mm);
  const int ny = static_cast<int>((page_mm.height - 2 * tex.margin_mm) / tex.square_mm);
  const cv::Size inner(nx - 1, ny - 1);
  // True page coordinates of the inner corners, in the same order (top row = largest t).
  const double x0 = 0.5 * (page_mm.width - nx * tex.square_mm);
  const double y0 = 0.5 * (page_mm.height - ny * tex.square_mm);
  std::vector<cv::Point2d> truth;
  for (int j = inner.height; j >= 1; --j) {
    for (int i = 1; i <= inner.width; ++i) {
      truth.emplace_back(x0 + i * tex.square_mm, y0 + j * tex.square_mm);
    }
  }
  // The control: the flat page scanned on its own (other noise than the flat page below).
  const Pipeline control = RunPipeline(PageShape::kFlat, FlattenSolver::kGaussNewton, 77);
  const std::vector<cv::Point2f> reference = Corners(control.restored.image, inner);
  ASSERT_EQ(reference.size(), truth.size()) << "control board not found";
  for (PageShape shape : {PageShape::kFlat, PageShape::kCurl, PageShape::kFold, PageShape::kCone}) {
    const Pipeline p = RunPipeline(shape);
    const std::vector<cv::Point2f> got = Corners(p.restored.image, inner);
    ASSERT_EQ(got.size(), truth.size()) << ToString(shape) << ": board not found";
    const cv::Mat h = cv::findHomography(got, reference, 0);
    std::vector<cv::Point2f> mapped;
    cv::perspectiveTransform(got, mapped, h);
    double mean_px = 0;
    for (size_t k = 0; k < got.size(); ++k) mean_px += cv::norm(mapped[k] - reference[k]);
    mean_px /= got.size();
    const double px_per_mm = p.restored.dpi / 25.4;
    // Pixels to flat mm through the dpi map (no scale fitted), then a rigid fit to the truth.
    const cv::Matx23d& a = p.restored.pixel_from_flat;
    std::vector<cv::Point2d> mm;
    for (const cv::Point2f& c : got) {
      mm.emplace_back((c.x - a(0, 2)) / a(0, 0), (c.y - a(1, 2)) / a(1, 1));
    }
    const Rigid2D fit = FitRigid2D(mm, truth);
    std::vector<cv::Point2d> truth_mirrored;
    for (const cv::Point2d& t : truth) truth_mirrored.emplace_back(t.x, -t.y);
    const Rigid2D fit_m = FitRigid2D(mm, truth_mirrored);
    double rms = 0, rms_m = 0;
    for (size_t k = 0; k < mm.size(); ++k) {
      rms += std::pow(cv::norm(fit.Apply(mm[k]) - truth[k]), 2);
      rms_m += std::pow(cv::norm(fit_m.Apply(mm[k]) - truth_mirrored[k]), 2);
    }
    rms = std::sqrt(rms / mm.size());
    rms_m = std::sqrt(rms_m / mm.size());
    std::printf(
        "[experiment I] %-5s %zu corners: vs control %.3f px = %.4f mm mean; "
        "vs true page %.4f mm RMS (mirrored fit %.2f mm)\n",
        ToString(shape), got.size(), mean_px, mean_px / px_per_mm, rms, rms_m);
    EXPECT_LE(mean_px, 0.15) << ToString(shape);
    EXPECT_LE(mean_px / px_per_mm, 0.04) << ToString(shape);
    EXPECT_LE(rms, 0.08) << ToString(shape);
    EXPECT_GT(rms_m, 10 * rms) << ToString(shape) << ": the restored image is mirrored";
  }
}

}  // namespace
}  // namespace vellum
