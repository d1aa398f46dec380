#include <gtest/gtest.h>

#include <cmath>

#include "core/geometry/calibration.h"
#include "core/geometry/triangulate.h"
#include "core/sim/gantry.h"

namespace vellum {
namespace {

TEST(CameraModel, ProjectInvertsRayDirectionWithDistortion) {
  // A mild lens with tangential terms, and a wide one with strong barrel distortion (about
  // 60 px at the default camera's corners), out to the corners: Newton's inversion must
  // reproduce every pixel.
  for (const cv::Vec<double, 5>& distortion :
       {cv::Vec<double, 5>(-0.08, 0.03, 0.001, -0.0005, 0.002),
        cv::Vec<double, 5>(-0.3, 0.12, -0.002, 0.003, -0.02)}) {
    CameraModel cam = DefaultRig().camera;
    cam.distortion = distortion;
    const cv::Vec3d c = cam.Center();
    double worst = 0;
    for (double v = 0; v < cam.size.height + 97; v += 97) {
      for (double u = 0; u < cam.size.width + 89; u += 89) {
        const cv::Point2d q(std::min(u, cam.size.width - 1.0), std::min(v, cam.size.height - 1.0));
        const cv::Point2d p = cam.Project(c + 500.0 * cam.RayDirection(q));
        worst = std::max(worst, cv::norm(p - q));
      }
    }
    EXPECT_LT(worst, 1e-6) << "distortion " << distortion;
  }
}

// Started from a neighbour's shift, as the ray table and the triangulation do along a row, the
// inversion gives the cold start's point to its tolerance (1e-12 in the distorted coordinates:
// 1e-9 is a thousandth of a micrometre at a metre), and leaves this pixel's shift. A start that
// leads nowhere (a shift of 50, or not a number) gives way to the cold start.
TEST(CameraModel, NormalizeFromANeighboursShiftGivesTheSamePoint) {
  CameraModel cam = DefaultRig().camera;
  cam.distortion = cv::Vec<double, 5>(-0.3, 0.12, -0.002, 0.003, -0.02);
  double worst = 0;
  for (int v = 0; v < cam.size.height; v += 37) {
    cv::Point2d shift(0, 0);
    for (int u = 0; u < cam.size.width; ++u) {
      const cv::Point2d warm = cam.Normalize(cv::Point2d(u, v), &shift);
      const cv::Point2d cold = cam.Normalize(cv::Point2d(u, v));
      worst = std::max(worst, cv::norm(warm - cold));
      cv::Point2d from_zero(0, 0);
      cam.Normalize(cv::Point2d(u, v), &from_zero);
      ASSERT_LT(cv::norm(shift - from_zero), 1e-9)
          << "the shift is this pixel's, at " << u << ", " << v;
    }
  }
  EXPECT_LT(worst, 1e-9);
  const cv::Point2d corner(3, 4);
  for (const cv::Point2d bad : {cv::Point2d(50, -50), cv::Point2d(NAN, 0)}) {
    cv::Point2d shift = bad;
    EXPECT_LT(cv::norm(cam.Normalize(corner, &shift) - cam.Normalize(corner)), 1e-9);
    EXPECT_TRUE(std::isfinite(shift.x) && std::isfinite(shift.y)) << bad;
  }
}

// The ray table against each pixel's exact ray rounded to the float the table stores: the same
// float, or at a rounding's tie the next one (a float's step is some 1e-4 px of the default
// camera; the decoder's own precision some 0.02 px), for the default camera, a mild lens with
// tangential terms and a wide lens of strong barrel distortion, on both sides of the table's
// cells, out to the last row and column.
TEST(CameraModel, RayTableHoldsEveryPixelsRay) {
  for (const cv::Vec<double, 5>& distortion :
       {DefaultRig().camera.distortion, cv::Vec<double, 5>(-0.08, 0.03, 0.001, -0.0005, 0.002),
        cv::Vec<double, 5>(-0.3, 0.12, -0.002, 0.003, -0.02)}) {
    CameraModel cam = DefaultRig().camera;
    cam.distortion = distortion;
    const cv::Mat table = cam.RayTable();
    ASSERT_EQ(table.size(), cam.size);
    ASSERT_EQ(table.type(), CV_32FC3);
    int pixels = 0, ties = 0, off = 0;
    for (int v = 0; v < cam.size.height; v += (v % 8 == 7 ? 13 : 1)) {
      cv::Point2d shift(0, 0);
      for (int u = 0; u < cam.size.width; ++u, ++pixels) {
        const cv::Vec3f exact(cam.RayDirection(cv::Point2d(u, v), &shift));
        const cv::Vec3f held = table.at<cv::Vec3f>(v, u);
        if (held == exact) continue;
        ++ties;
        for (int k = 0; k < 3; ++k) {
          if (held[k] != exact[k] && held[k] != std::nextafter(exact[k], 2.0f) &&
              held[k] != std::nextafter(exact[k], -2.0f)) {
            ++off;
          }
        }
      }
    }
    EXPECT_EQ(off, 0) << "distortion " << distortion;
    EXPECT_LT(ties, pixels / 100) << "distortion " << distortion;
  }
}

TEST(CameraModel, CheckRejectsAMirroredRotation) {
  CameraModel cam = DefaultRig().projector;
  cam.rotation = cam.rotation * cv::Matx33d(-1, 0, 0, 0, 1, 0, 0, 0, 1);
  std::string why;
  EXPECT_FALSE(cam.Check(&why));
  EXPECT_NE(why.find("reflection"), std::string::npos) << why;
}

// Calibrations that are wrong but well formed are refused with what is wrong: a misplaced
// distortion coefficient (k1 = 50 moves the image's edge by hundreds of percent), a projector
// turned away from the table the camera sees. A real lens (k1 -0.08) passes.
TEST(Calibration, CheckRefusesAnImplausibleLensAndAProjectorBehindTheTable) {
  Calibration rig = DefaultRig();
  std::string why;
  ASSERT_TRUE(rig.Check(&why)) << why;
  rig.camera.distortion = cv::Vec<double, 5>(-0.08, 0.03, 0.001, -0.0005, 0.002);
  EXPECT_TRUE(rig.Check(&why)) << why;
  rig.camera.distortion = cv::Vec<double, 5>(50, 0, 0, 0, 0);
  EXPECT_FALSE(rig.Check(&why));
  EXPECT_NE(why.find("not a plausible lens"), std::string::npos) << why;
  rig = DefaultRig();
  // Turned half round about its own centre: it now faces away from the table.
  const cv::Vec3d centre = rig.projector.Center();
  rig.projector.rotation = cv::Matx33d(1, 0, 0, 0, -1, 0, 0, 0, -1) * rig.projector.rotation;
  rig.projector.translation = -(rig.projector.rotation * centre);
  EXPECT_FALSE(rig.Check(&why));
  EXPECT_NE(why.find("projector does not face the table"), std::string::npos) << why;
  // A wild focal length, either way, or pixels far from square: named, with the field of view.
  for (const double fx : {1e300, 1e-3}) {
    rig = DefaultRig();
    rig.camera.matrix(0, 0) = fx;
    EXPECT_FALSE(rig.Check(&why)) << fx;
    EXPECT_NE(why.find("camera: fx = "), std::string::npos) << why;
    EXPECT_NE(why.find("field of view"), std::string::npos) << why;
  }
  rig = DefaultRig();
  rig.projector.matrix(1, 1) *= 3;
  EXPECT_FALSE(rig.Check(&why));
  EXPECT_NE(why.find("projector: "), std::string::npos) << why;
}

// Exact correspondences of a known surface triangulate back to it, with and without rows and
// with projector distortion.
class TriangulateExact : public ::testing::TestWithParam<std::tuple<bool, bool>> {};

TEST_P(TriangulateExact, RecoversTheSurface) {
  const auto [rows, distorted] = GetParam();
  Calibration calib = DefaultRig();
  if (distorted) calib.projector.distortion = cv::Vec<double, 5>(0.04, -0.01, 0.0005, 0, 0);
  const CameraModel& cam = calib.camera;
  DecodeResult d;
  d.status = Status::Ok();
  d.has_columns = true;
  d.has_rows = rows;
  d.projector_x.create(cam.size, CV_32F);
  d.projector_y.create(cam.size, CV_32F);
  d.projector_x.setTo(NAN);
  d.projector_y.setTo(NAN);
  d.valid = cv::Mat::zeros(cam.size, CV_8U);
  cv::Mat truth(cam.size, CV_32FC3, cv::Scalar::all(NAN));
  const cv::Vec3d c = cam.Center();
  for (int v = 0; v < cam.size.height; v += 7) {
    for (int u = 0; u < cam.size.width; u += 7) {
      // Tilted plane z = 20 + 0.1 x + 0.05 y.
      const cv::Vec3d d_ = cam.RayDirection(cv::Point2d(u, v));
      const double t =
          (20 - c[2] + 0.1 * c[0] + 0.05 * c[1]) / (d_[2] - 0.1 * d_[0] - 0.05 * d_[1]);
      const cv::Vec3d x = c + t * d_;
      const cv::Point2d p = calib.projector.Project(x);
      if (!(p.x >= 0 && p.y >= 0 && p.x < 1023 && p.y < 767)) continue;
      d.projector_x.at<float>(v, u) = static_cast<float>(p.x);
      if (rows) d.projector_y.at<float>(v, u) = static_cast<float>(p.y);
      d.valid.at<uint8_t>(v, u) = 255;
      truth.at<cv::Vec3f>(v, u) = cv::Vec3f(x);
    }
  }
  const Triangulator tri(calib);
  const PointMap map = tri.Triangulate(d);
  ASSERT_TRUE(map.status.ok()) << map.status.message();
  EXPECT_EQ(map.valid, cv::countNonZero(d.valid));
  double worst = 0;
  for (int v = 0; v < cam.size.height; ++v) {
    for (int u = 0; u < cam.size.width; ++u) {
      if (!d.valid.at<uint8_t>(v, u)) continue;
      worst = std::max(worst, cv::norm(cv::Vec3d(map.points.at<cv::Vec3f>(v, u)) -
                                       cv::Vec3d(truth.at<cv::Vec3f>(v, u))));
    }
  }
  // float storage of projector coordinates (~3e-5 px at 1000) is ~3e-5 mm of depth.
  EXPECT_LT(worst, 1e-3);
}

INSTANTIATE_TEST_SUITE_P(RowsAndDistortion, TriangulateExact,
                         ::testing::Combine(::testing::Bool(), ::testing::Bool()));

TEST(Triangulate, RejectsPointsOffTheirEpipolarLine) {
  const Calibration calib = DefaultRig();
  DecodeResult d;
  d.status = Status::Ok();
  d.has_columns = d.has_rows = true;
  d.valid = cv::Mat::zeros(calib.camera.size, CV_8U);
  d.projector_x = cv::Mat(calib.camera.size, CV_32F, cv::Scalar(NAN));
  d.projector_y = d.projector_x.clone();
  const cv::Vec3d x(10, 20, 5);
  const cv::Point2d pc = calib.camera.Project(x), pp = calib.projector.Project(x);
  const cv::Point at(cvRound(pc.x), cvRound(pc.y));
  d.valid.at<uint8_t>(at) = 255;
  d.projector_x.at<float>(at) = static_cast<float>(pp.x);
  d.projector_y.at<float>(at) = static_cast<float>(pp.y + 5.0);  // 5 px off: inconsistent.
  const PointMap map = Triangulator(calib).Triangulate(d);
  EXPECT_EQ(map.valid, 0);
  EXPECT_EQ(map.rejected_epipolar, 1);
}

// A decode of the tilted plane z = 20 + 0.1 x + 0.05 y, every 7th pixel.
DecodeResult PlaneDecode(const Calibration& calib) {
  const CameraModel& cam = calib.camera;
  DecodeResult d;
  d.status = Status::Ok();
  d.has_columns = d.has_rows = true;
  d.projector_x = cv::Mat(cam.size, CV_32F, cv::Scalar(NAN));
  d.projector_y = d.projector_x.clone();
  d.valid = cv::Mat::zeros(cam.size, CV_8U);
  const cv::Vec3d c = cam.Center();
  for (int v = 0; v < cam.size.height; v += 7) {
    for (int u = 0; u < cam.size.width; u += 7) {
      const cv::Vec3d r = cam.RayDirection(cv::Point2d(u, v));
      const double t = (20 - c[2] + 0.1 * c[0] + 0.05 * c[1]) / (r[2] - 0.1 * r[0] - 0.05 * r[1]);
      const cv::Point2d p = calib.projector.Project(c + t * r);
      if (!(p.x >= 0 && p.y >= 0 && p.x < 1023 && p.y < 767)) continue;
      d.projector_x.at<float>(v, u) = static_cast<float>(p.x);
      d.projector_y.at<float>(v, u) = static_cast<float>(p.y);
      d.valid.at<uint8_t>(v, u) = 255;
    }
  }
  return d;
}

// The working volume comes from the calibration, a flag overrides it, and a scan with every
// point outside it is an error that says where they fell (not an empty page).
TEST(Triangulate, SaysWhenEveryPointFallsOutsideTheWorkingVolume) {
  Calibration calib = DefaultRig();
  const DecodeResult d = PlaneDecode(calib);
  const int decoded = cv::countNonZero(d.valid);
  ASSERT_GT(decoded, 1000);
  TriangulateOptions keep;
  keep.max_flying_mm = 0;  // Every 7th pixel: no neighbours to judge flying points by.
  calib.min_z_mm = 60;     // The plane lies within 20 +- 30 mm in the view: all of it below.
  calib.max_z_mm = 200;
  PointMap map = Triangulator(calib).Triangulate(d, keep);
  ASSERT_FALSE(map.status.ok());
  EXPECT_EQ(map.rejected_volume, decoded);
  EXPECT_EQ(map.rejected_below, decoded);
  const std::string& m = map.status.message();
  EXPECT_NE(m.find("outside the working volume (heights 60 to 200 mm"), std::string::npos) << m;
  EXPECT_NE(m.find(std::to_string(decoded) + " below it, 0 above"), std::string::npos) << m;
  // The flag's volume wins over the calibration's.
  keep.min_z_mm = -40;
  keep.max_z_mm = 80;
  map = Triangulator(calib).Triangulate(d, keep);
  ASSERT_TRUE(map.status.ok()) << map.status.message();
  EXPECT_EQ(map.valid, decoded);
  // Half outside: not an error, counted.
  keep.min_z_mm = 20;
  map = Triangulator(calib).Triangulate(d, keep);
  ASSERT_TRUE(map.status.ok()) << map.status.message();
  EXPECT_GT(map.rejected_below, 0);
  EXPECT_EQ(map.valid + map.rejected_volume, decoded);
}

TEST(Triangulate, RejectsAMismatchedCameraSize) {
  DecodeResult d;
  d.status = Status::Ok();
  d.valid = cv::Mat::zeros(100, 100, CV_8U);
  const PointMap map = Triangulator(DefaultRig()).Triangulate(d);
  EXPECT_FALSE(map.status.ok());
  EXPECT_NE(map.status.message().find("1600x1200"), std::string::npos) << map.status.message();
}

}  // namespace
}  // namespace vellum
