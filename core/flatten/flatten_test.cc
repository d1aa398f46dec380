#include "core/flatten/flatten.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/geometry/rigid2d.h"

namespace vellum {
namespace {

// A sheet sampled exactly from a developable surface: the page (s, t) rolled onto a cylinder of
// radius R about the t axis over its right part, like a binder curl. Pixels stand in for the
// camera view from above (u = x, v = -y).
Mesh CurledSheet(int cols, int rows, double radius, std::vector<cv::Point2d>* unrolled) {
  Mesh m;
  m.cols = cols;
  m.rows = rows;
  const int n = cols * rows;
  m.kind.assign(n, NodeKind::kMeasured);
  m.point.resize(n);
  m.pixel.resize(n);
  unrolled->resize(n);
  for (int j = 0; j < rows; ++j) {
    for (int i = 0; i < cols; ++i) {
      const double s = 100.0 * i / (cols - 1), t = 80.0 * j / (rows - 1);
      const double bend = std::max(0.0, s - 50.0);
      const double x = s < 50 ? s : 50 + radius * std::sin(bend / radius);
      const double z = s < 50 ? 0 : radius * (1 - std::cos(bend / radius));
      const int k = j * cols + i;
      m.point[k] = cv::Vec3d(x, t, z);
      m.pixel[k] = cv::Point2d(x, -t);
      (*unrolled)[k] = cv::Point2d(s, t);
    }
  }
  auto add = [&](int a, int b, SpringKind kind) {
    m.springs.push_back({a, b, cv::norm(m.point[a] - m.point[b]), kind});
  };
  for (int j = 0; j < rows; ++j) {
    for (int i = 0; i < cols; ++i) {
      const int k = j * cols + i;
      if (i + 1 < cols) add(k, k + 1, SpringKind::kStructural);
      if (j + 1 < rows) add(k, k + cols, SpringKind::kStructural);
      if (i + 1 < cols && j + 1 < rows) {
        add(k, k + cols + 1, SpringKind::kShear);
        add(k + 1, k + cols, SpringKind::kShear);
        m.quads.emplace_back(k, k + 1, k + cols + 1, k + cols);
      }
    }
  }
  m.measured = n;
  m.status = Status::Ok();
  return m;
}

double RigidError(const std::vector<cv::Point2d>& a, const std::vector<cv::Point2d>& b) {
  const Rigid2D r = FitRigid2D(a, b);
  double worst = 0;
  for (size_t k = 0; k < a.size(); ++k) worst = std::max(worst, cv::norm(r.Apply(a[k]) - b[k]));
  return worst;
}

// A chord of radius 40 mm over one 100 / 14 mm cell is shorter than the arc by 0.07%: the
// sheet's own springs are chords, so the flat sheet is that much shorter across the curl.
TEST(Flatten, GaussNewtonUnrollsACurl) {
  std::vector<cv::Point2d> truth;
  const Mesh m = CurledSheet(15, 12, 40.0, &truth);
  const FlattenResult r = Flatten(m);
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  EXPECT_LT(r.max_strain, 1e-6);  // Consistent springs: every one reaches its rest length.
  EXPECT_EQ(r.folded_quads, 0);
  EXPECT_LT(RigidError(r.flat, truth), 0.05);
  EXPECT_LE(r.iterations, 20);
}

// The paper's simulator, with either integrator, reaches the state the fast solver reaches
// (here a 57 degree curl on a coarse 7 mm grid; at 72 degrees this coarse sheet folds while
// falling, as the paper warns a mass-spring sheet can, and the simulator then says so).
TEST(Flatten, SimulatorAgreesWithGaussNewton) {
  std::vector<cv::Point2d> truth;
  const Mesh m = CurledSheet(15, 12, 50.0, &truth);
  const FlattenResult gn = Flatten(m);
  for (FlattenSolver solver : {FlattenSolver::kEuler, FlattenSolver::kRungeKutta4}) {
    FlattenOptions o;
    o.solver = solver;
    o.record_every = 100;
    const FlattenResult sim = Flatten(m, o);
    ASSERT_TRUE(sim.status.ok()) << ToString(solver) << ": " << sim.status.message();
    EXPECT_LT(RigidError(sim.flat, gn.flat), 0.05) << ToString(solver);
    EXPECT_EQ(sim.folded_quads, 0);
    // The trajectory starts on the curl and ends on the plane.
    ASSERT_GE(sim.trajectory.size(), 2u);
    double z_first = 0, z_last = 0;
    for (const cv::Vec3d& p : sim.trajectory.front()) z_first = std::max(z_first, p[2]);
    for (const cv::Vec3d& p : sim.trajectory.back()) z_last = std::max(z_last, p[2]);
    EXPECT_GT(z_first, 20.0);
    EXPECT_LT(z_last, o.plane_epsilon_mm);
  }
}

TEST(Flatten, TinyAndDegenerateSheetsNeverGiveNaN) {
  std::vector<cv::Point2d> truth;
  const Mesh tiny = CurledSheet(2, 2, 40.0, &truth);
  for (FlattenSolver solver :
       {FlattenSolver::kGaussNewton, FlattenSolver::kEuler, FlattenSolver::kRungeKutta4}) {
    FlattenOptions o;
    o.solver = solver;
    const FlattenResult r = Flatten(tiny, o);
    ASSERT_TRUE(r.status.ok()) << r.status.message();
    for (const cv::Point2d& p : r.flat) EXPECT_TRUE(std::isfinite(p.x) && std::isfinite(p.y));
  }
  // All nodes on one line: the sheet has no area; the result must still be finite.
  Mesh line = CurledSheet(6, 6, 40.0, &truth);
  for (size_t k = 0; k < line.point.size(); ++k) line.point[k] = cv::Vec3d(k * 1.0, 0, 0);
  for (Spring& s : line.springs) s.rest_mm = cv::norm(line.point[s.a] - line.point[s.b]);
  const FlattenResult r = Flatten(line);
  if (r.status.ok()) {
    for (const cv::Point2d& p : r.flat) EXPECT_TRUE(std::isfinite(p.x) && std::isfinite(p.y));
  }
  // An unbuilt mesh is refused.
  EXPECT_FALSE(Flatten(Mesh()).status.ok());
}

// One node whose rest lengths disagree with its neighbours' (its fit cut a crease's corner)
// strains its own four springs; a line of springs all too long (a crease the decoder rounded, the
// page short across it) strains every spring on the line. Only the line is widespread.
TEST(Flatten, WidespreadStrainTellsALineOfSpringsFromOneNode) {
  std::vector<cv::Point2d> truth;
  Mesh flat_sheet = CurledSheet(15, 12, 1e9, &truth);  // Radius beyond the page: flat.
  Mesh one_node = flat_sheet;
  const int node = 5 * 15 + 7;
  for (Spring& s : one_node.springs) {
    if (s.kind == SpringKind::kStructural && (s.a == node || s.b == node)) s.rest_mm *= 1.04;
  }
  FlattenResult r;
  MeasureStrain(one_node, truth, &r);
  EXPECT_NEAR(r.max_strain, 0.04 / 1.04, 1e-6);
  EXPECT_LT(r.widespread_strain, 1e-9);  // Four springs, fewer than kWidespreadSprings.

  Mesh line = flat_sheet;
  for (Spring& s : line.springs) {
    const int ia = s.a % 15, ib = s.b % 15;
    if (std::min(ia, ib) == 7 && std::max(ia, ib) == 8) s.rest_mm *= 1.04;  // Across column 7.
  }
  MeasureStrain(line, truth, &r);
  EXPECT_NEAR(r.max_strain, 0.04 / 1.04, 1e-6);
  EXPECT_NEAR(r.widespread_strain, 0.04 / 1.04, 1e-6);  // 12 structural + 22 shear springs.
}

}  // namespace
}  // namespace vellum
