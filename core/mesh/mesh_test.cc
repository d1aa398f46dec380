#include "core/mesh/mesh.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

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
