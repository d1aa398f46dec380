#include "core/mesh/mesh.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

#include "core/flatten/flatten.h"
#include "core/sim/gantry.h"

namespace vellum {
namespace {

// The default camera looking at the table plane z = 0 (or at z = f(x, y)): the point map a
// perfect scan would give, with a page mask over a rectangle.
struct Scene {
  Calibration rig = DefaultRig();
  cv::Mat points, mask;
  Scene() {
    const CameraModel& cam = rig.camera;
    points.create(cam.size, CV_32FC3);
    const cv::Vec3d c = cam.Center();
    for (int v = 0; v < cam.size.height; ++v) {
      for (int u = 0; u < cam.size.width; ++u) {
        const cv::Vec3d d = cam.RayDirection(cv::Point2d(u, v));
        points.at<cv::Vec3f>(v, u) = cv::Vec3f(c - (c[2] / d[2]) * d);
      }
    }
    mask = cv::Mat::zeros(cam.size, CV_8U);
    mask(cv::Rect(400, 200, 800, 800)).setTo(255);
  }
  Mesh Build(const MeshOptions& o = MeshOptions()) const {
    return BuildMesh(points, mask, o, [&](const cv::Vec3d& x) { return rig.camera.Project(x); });
  }
};

TEST(Mesh, PlaneGivesAFullGridOfSprings) {
  const Scene scene;
  MeshOptions o;
  o.grid = {20, 15};
  o.skirt_rings = 0;
  const Mesh m = scene.Build(o);
  ASSERT_TRUE(m.status.ok()) << m.status.message();
  EXPECT_EQ(m.measured, 20 * 15);
  EXPECT_EQ(m.quads.size(), 19u * 14u);
  // Structural: 19 x 15 + 20 x 14; shear: 2 x 19 x 14.
  EXPECT_EQ(m.springs.size(), 19u * 15 + 20u * 14 + 2u * 19 * 14);
  for (size_t k = 0; k < m.point.size(); ++k) EXPECT_NEAR(m.point[k][2], 0.0, 1e-4);
  o.bend_springs = true;
  EXPECT_EQ(scene.Build(o).springs.size(), m.springs.size() + 18u * 15 + 20u * 13);
}

TEST(Mesh, HolesAreFilledFromTheirNeighbours) {
  Scene scene;
  // A hole of 120 px radius (ink, a specular spot): no points there.
  cv::Mat hole = cv::Mat::zeros(scene.points.size(), CV_8U);
  cv::circle(hole, {800, 600}, 120, cv::Scalar(255), cv::FILLED);
  scene.points.setTo(cv::Scalar::all(NAN), hole);
  const Mesh m = scene.Build();
  ASSERT_TRUE(m.status.ok()) << m.status.message();
  EXPECT_GT(m.filled, 20);
  for (size_t k = 0; k < m.kind.size(); ++k) {
    if (m.kind[k] == NodeKind::kFilled) {
      EXPECT_NEAR(m.point[k][2], 0.0, 1e-6);
    }
  }
  EXPECT_EQ(m.quads.size(), 44u * 44u);  // The sheet stays whole.
}

// Where a node's window straddles the leaf's silhouette and what lies far behind it, its points
// are strewn along the camera's rays (here every other pixel 150 mm up, the rest on the plane):
// a fit would put the node in mid-air, 75 mm up, and the flattened sheet would throw it out as a
// spike. Inside the page, held by measured nodes on all sides, such a node is a hole filled from
// them; at the page's edge it is the edge, and the skirt extrapolates it from the page.
TEST(Mesh, ANodeWhosePointsAreStrewnIsNoSurface) {
  Scene scene;
  const CameraModel& cam = scene.rig.camera;
  const cv::Vec3d c = cam.Center();
  auto strew = [&](const cv::Rect& patch) {
    for (int v = patch.y; v < patch.y + patch.height; ++v) {
      for (int u = patch.x; u < patch.x + patch.width; ++u) {
        const double up = (u + v) % 2 ? 150.0 : 0.0;
        const cv::Vec3d d = cam.RayDirection(cv::Point2d(u, v));
        scene.points.at<cv::Vec3f>(v, u) = cv::Vec3f(c - ((c[2] - up) / d[2]) * d);
      }
    }
  };
  // Over the windows (23 x 23 px) of the node at the page's middle (800, 600) and of the one at
  // its left edge (400, 600); the windows of the nodes beside them (18 px away) see a few strewn
  // points, which their fits drop.
  strew(cv::Rect(789, 589, 23, 23));
  strew(cv::Rect(400, 589, 12, 23));
  const Mesh m = scene.Build();
  ASSERT_TRUE(m.status.ok()) << m.status.message();
  EXPECT_EQ(m.kind[22 * 45 + 22], NodeKind::kFilled);
  EXPECT_EQ(m.kind[22 * 45 + 0], NodeKind::kSkirt);
  for (size_t k = 0; k < m.kind.size(); ++k) {
    if (m.Active(static_cast<int>(k))) {
      EXPECT_NEAR(m.point[k][2], 0.0, 0.5) << "node " << k;
    }
  }
  const FlattenResult flat = Flatten(m);
  ASSERT_TRUE(flat.status.ok());
  EXPECT_LT(flat.max_strain, 0.01);
  EXPECT_EQ(flat.folded_quads, 0);
}

TEST(Mesh, SkirtCoversThePageEdge) {
  Scene scene;
  scene.mask.setTo(0);
  cv::circle(scene.mask, {800, 600}, 400, cv::Scalar(255), cv::FILLED);  // A round "page".
  const Mesh m = scene.Build();
  ASSERT_TRUE(m.status.ok());
  EXPECT_GT(m.skirt, 40);
  for (size_t k = 0; k < m.kind.size(); ++k) {
    if (m.kind[k] == NodeKind::kSkirt) {
      EXPECT_NEAR(m.point[k][2], 0.0, 1e-6);
    }
  }
}

TEST(Mesh, TinyGridAndBadInputGiveResultsOrClearErrors) {
  Scene scene;
  MeshOptions o;
  o.grid = {2, 2};
  Mesh m = scene.Build(o);
  ASSERT_TRUE(m.status.ok()) << m.status.message();
  EXPECT_EQ(m.quads.size(), 1u);
  o.grid = {1, 5};
  EXPECT_FALSE(scene.Build(o).status.ok());
  // No page.
  Scene empty;
  empty.mask.setTo(0);
  m = empty.Build();
  EXPECT_FALSE(m.status.ok());
  EXPECT_NE(m.status.message().find("no page"), std::string::npos) << m.status.message();
  // All points invalid.
  Scene invalid;
  invalid.points.setTo(cv::Scalar::all(NAN));
  m = invalid.Build();
  EXPECT_FALSE(m.status.ok());
  EXPECT_NE(m.status.message().find("no valid 3D points"), std::string::npos) << m.status.message();
  // Every point the same: the sheet would collapse.
  Scene collapsed;
  collapsed.points.setTo(cv::Scalar(1, 2, 3));
  m = collapsed.Build();
  EXPECT_FALSE(m.status.ok());
  EXPECT_NE(m.status.message().find("coincide"), std::string::npos) << m.status.message();
}

// A leaf creased into a ridge along the image's columns, `slope_deg` each side and rounded over
// 1 mm (a crease in paper is no sharper): z = g(x), the faces joined by an arc of that radius. A
// camera ray meets it where its height falls to g (found by bisection: the surface is never as
// steep as the rays). The leaf unrolled puts a point at its arc length from the ridge across it,
// so the true length between two points on the leaf is their distance in (unrolled x, y).
struct Ridge : Scene {
  double ridge_x = 0, slope = 0;
  static constexpr double kHeight = 30, kRadius = 1;  // mm
  explicit Ridge(double slope_deg) : slope(slope_deg * CV_PI / 180) {
    const CameraModel& cam = rig.camera;
    const cv::Vec3d c = cam.Center();
    const cv::Vec3d mid = cam.RayDirection(cv::Point2d(803.5, 600));  // Not on a grid line.
    ridge_x = c[0] - c[2] / mid[2] * mid[0];
    for (int v = 0; v < cam.size.height; ++v) {
      for (int u = 0; u < cam.size.width; ++u) {
        const cv::Vec3d d = cam.RayDirection(cv::Point2d(u, v));
        double lo = (c[2] - kHeight - 1) / -d[2], hi = (c[2] + 200) / -d[2];  // Above; below.
        for (int it = 0; it < 60; ++it) {
          const double t = 0.5 * (lo + hi);
          const cv::Vec3d x = c + t * d;
          (x[2] > Height(x[0]) ? lo : hi) = t;
        }
        points.at<cv::Vec3f>(v, u) = cv::Vec3f(c + 0.5 * (lo + hi) * d);
      }
    }
  }
  double Height(double x) const {
    const double u = std::fabs(x - ridge_x), edge = kRadius * std::sin(slope);
    if (u >= edge) return kHeight - std::tan(slope) * u;
    return kHeight - kRadius / std::cos(slope) + std::sqrt(kRadius * kRadius - u * u);
  }
  cv::Point2d Unrolled(const cv::Vec3d& x) const {
    const double u = x[0] - ridge_x, a = std::fabs(u), edge = kRadius * std::sin(slope);
    const double s = a <= edge ? kRadius * std::asin(a / kRadius)
                               : kRadius * slope + (a - edge) / std::cos(slope);
    return {ridge_x + (u < 0 ? -s : s), x[1]};
  }
};

TEST(Mesh, ASpringAcrossACreaseIsAsLongAsTheLeafBetweenItsNodes) {
  const Ridge ridge(20);
  MeshOptions o;
  o.skirt_rings = 0;
  for (bool along : {true, false}) {
    o.rest_along_surface = along;
    const Mesh m = ridge.Build(o);
    ASSERT_TRUE(m.status.ok()) << m.status.message();
    double worst = 0;
    int across = 0;
    for (const Spring& s : m.springs) {
      const double truth = cv::norm(ridge.Unrolled(m.point[s.a]) - ridge.Unrolled(m.point[s.b]));
      // On the leaf's first and last rows the pieces' fits see points on one side only and
      // fit planes, which cut the ridge's arc; the rows inside are held to the bar.
      const int ja = s.a / m.cols, jb = s.b / m.cols;
      if (std::min(ja, jb) == 0 || std::max(ja, jb) == m.rows - 1) continue;
      worst = std::max(worst, std::fabs(s.rest_mm - truth));
      across += (m.point[s.a][0] - ridge.ridge_x) * (m.point[s.b][0] - ridge.ridge_x) < 0;
    }
    ASSERT_GT(across, 40);
    if (along) {
      // Halved to pieces of 2 px (0.5 mm) about the ridge: the last piece's chord cuts the
      // corner by at most 0.5 mm (1 / cos 20 deg - 1) = 0.03 mm.
      EXPECT_LT(worst, 0.035);
    } else {
      EXPECT_GT(worst, 0.15);  // A cell of 4.5 mm across the ridge: up to 6% short.
    }
  }
}

TEST(Mesh, ALeafCreasedIntoARidgeFlattensToItsTrueWidth) {
  const Ridge ridge(25);
  for (bool along : {true, false}) {
    MeshOptions o;
    o.rest_along_surface = along;
    const Mesh m = ridge.Build(o);
    ASSERT_TRUE(m.status.ok()) << m.status.message();
    const FlattenResult flat = Flatten(m);
    ASSERT_TRUE(flat.status.ok()) << flat.status.message();
    // Across the middle row, from its first page node to its last.
    const int j = m.rows / 2;
    int first = -1, last = -1;
    for (int i = 0; i < m.cols; ++i) {
      if (m.kind[m.Index(i, j)] != NodeKind::kMeasured) continue;
      if (first < 0) first = m.Index(i, j);
      last = m.Index(i, j);
    }
    ASSERT_GE(first, 0);
    const double truth = cv::norm(ridge.Unrolled(m.point[first]) - ridge.Unrolled(m.point[last]));
    const double width = cv::norm(flat.flat[first] - flat.flat[last]);
    if (along) {
      // The ridge costs at most the last piece's 0.05 mm at 25 degrees (0.02 mm measured).
      EXPECT_NEAR(width, truth, 0.05);
    } else {
      EXPECT_LT(width, truth - 0.2);  // The chords cut the ridge's corner (0.23 mm measured).
    }
  }
}

TEST(SegmentPage, FindsABrightPageWithInkOnADarkTable) {
  cv::Mat texture(300, 400, CV_8U, cv::Scalar(70));
  texture(cv::Rect(100, 50, 200, 200)).setTo(200);
  texture(cv::Rect(150, 100, 40, 40)).setTo(15);  // Ink inside the page.
  const cv::Mat page = SegmentPage(texture);
  EXPECT_NEAR(cv::countNonZero(page), 200 * 200, 400);
  EXPECT_EQ(page.at<uint8_t>(120, 170), 255);  // The ink belongs to the page.
  EXPECT_EQ(page.at<uint8_t>(10, 10), 0);
}

}  // namespace
}  // namespace vellum
