// Photometric normals on the virtual gantry: four raking lights at 30 degrees over a
// curled leaf with an embossed line, against the normals the gantry lit it with.
#include "core/shading/photometric.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/sim/evaluate.h"
#include "core/sim/gantry.h"

namespace vellum {
namespace {

struct Lit {
  std::unique_ptr<VirtualGantry> gantry;
  std::vector<cv::Mat> images;
  std::vector<cv::Vec3d> directions;
};

Lit Light(const PageOptions& page, const std::vector<SceneLight>& lights) {
  Lit lit;
  TextureOptions texture;
  texture.kind = TextureKind::kPlain;
  lit.gantry = std::make_unique<VirtualGantry>(DefaultRig(), page, texture);
  for (const ScanLight& l : RenderLights(*lit.gantry, lights, 5)) {
    lit.images.push_back(l.image);
    lit.directions.push_back(l.direction);
  }
  return lit;
}

// Angles (degrees) between the solved normals and the gantry's over the solved page pixels.
std::vector<double> AngleErrors(const Lit& lit, const PhotometricResult& r) {
  const GroundTruth& truth = lit.gantry->truth();
  const Page& page = lit.gantry->pages().front();
  std::vector<double> out;
  for (int v = 0; v < r.valid.rows; v += 2) {
    for (int u = 0; u < r.valid.cols; u += 2) {
      if (!r.valid.at<uint8_t>(v, u) || !truth.on_page.at<uint8_t>(v, u)) continue;
      const cv::Vec2f st = truth.page.at<cv::Vec2f>(v, u);
      const cv::Vec3d n = page.Normal(st[0], st[1]);
      const cv::Vec3d m(r.normals.at<cv::Vec3f>(v, u));
      out.push_back(std::acos(std::clamp(n.dot(m), -1.0, 1.0)) * 180 / M_PI);
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

TEST(Photometric, RakingLightsGiveTheCurledLeafsNormals) {
  PageOptions page;
  page.shape = PageShape::kCurl;
  page.ridge_height_mm = 0.2;
  page.ridge_t_mm = 120;
  const Lit lit = Light(page, RakingLights(4, 30.0, 45.0));
  const PhotometricResult r = PhotometricNormals(lit.images, lit.directions, cv::Mat());
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  const std::vector<double> errors = AngleErrors(lit, r);
  ASSERT_GT(errors.size(), 50000u);
  const double median = errors[errors.size() / 2], p95 = errors[errors.size() * 95 / 100];
  std::printf("normals: %zu pixels, median %.2f deg, 95th %.2f deg\n", errors.size(), median, p95);
  // The lights' levels are 8-bit with 1.5 DN of noise at about 100 DN: a level 1.5% off tilts
  // the solved normal by about 1.5% of a radian over the lights' spread, under a degree; the
  // 8-bit steps and the curl's steep side (where a light grazes) spread the tail.
  EXPECT_LT(median, 1.0);
  EXPECT_LT(p95, 3.0);
  // Most of the leaf is lit by three or more of the lights: where the curl rises more than 60
  // degrees (its last 8 mm of 70) the light behind it sees its back, and the lights at the
  // sides graze it; the pixels are marked (87% solved).
  const int on_page = cv::countNonZero(lit.gantry->truth().on_page);
  EXPECT_GT(errors.size() * 4.0, 0.8 * on_page);
}

TEST(Photometric, APixelUnderTwoLightsIsMarked) {
  PageOptions page;  // Flat: from straight above, lights at 30 degrees.
  std::vector<SceneLight> lights = RakingLights(3, 30.0);
  // The third light below the table: it lights nothing, so every pixel has two.
  lights[2].direction = cv::Vec3d(0, 0.9, -0.43);
  const Lit lit = Light(page, lights);
  const PhotometricResult r = PhotometricNormals(lit.images, lit.directions, cv::Mat());
  ASSERT_TRUE(r.status.ok());
  EXPECT_EQ(r.solved, 0);
  EXPECT_EQ(cv::countNonZero(r.normals.reshape(1)), 0);
}

TEST(Photometric, RefusesTooFewLightsOrNoDirection) {
  const cv::Mat im(4, 4, CV_8U, cv::Scalar(100));
  EXPECT_FALSE(PhotometricNormals({im, im}, {cv::Vec3d(1, 0, 1), cv::Vec3d(0, 1, 1)}, cv::Mat())
                   .status.ok());
  const PhotometricResult r = PhotometricNormals(
      {im, im, im}, {cv::Vec3d(1, 0, 1), cv::Vec3d(0, 1, 1), cv::Vec3d(0, 0, 0)}, cv::Mat());
  ASSERT_FALSE(r.status.ok());
  EXPECT_NE(r.status.message().find("light 2"), std::string::npos) << r.status.message();
}

// A PTM: six lights at least, at two elevations or more (at one, lu^2 + lv^2 is a constant).
// Of synthetic levels that are a biquadratic in (lu, lv), it gives that biquadratic back.
TEST(Photometric, APtmNeedsSixLightsAtTwoElevationsAndFitsABiquadratic) {
  const cv::Mat right(2, 2, CV_32FC3, cv::Scalar(1, 0, 0)), up(2, 2, CV_32FC3, cv::Scalar(0, 1, 0));
  std::vector<cv::Vec3d> ring, rings;
  for (int k = 0; k < 6; ++k) {
    const double a = k * M_PI / 3;
    ring.push_back(cv::Vec3d(0.8 * std::cos(a), 0.8 * std::sin(a), 0.6));
    const double e = k % 2 ? 0.6 : 0.9;  // Two elevations.
    rings.push_back(cv::normalize(
        cv::Vec3d(std::sqrt(1 - e * e) * std::cos(a), std::sqrt(1 - e * e) * std::sin(a), e)));
  }
  rings.push_back(cv::Vec3d(0, 0, 1));
  const cv::Vec<float, 6> truth(0.1f, -0.05f, 0.02f, 0.2f, -0.1f, 0.5f);
  std::vector<cv::Mat> images;
  for (const cv::Vec3d& d : rings) {
    images.push_back(cv::Mat(2, 2, CV_16U, cv::Scalar(65535 * PtmLuminance(truth, d[0], d[1]))));
  }
  const PtmResult one =
      FitPtm(std::vector<cv::Mat>(images.begin(), images.begin() + 6), ring, right, up);
  ASSERT_FALSE(one.status.ok());
  EXPECT_NE(one.status.message().find("two or more elevations"), std::string::npos);
  EXPECT_FALSE(FitPtm({images[0], images[1]}, {rings[0], rings[1]}, right, up).status.ok());
  const PtmResult fit = FitPtm(images, rings, right, up);
  ASSERT_TRUE(fit.status.ok()) << fit.status.message();
  EXPECT_EQ(fit.solved, 4);
  const cv::Vec<float, 6> a = fit.coefficients.at<cv::Vec<float, 6>>(1, 1);
  for (int k = 0; k < 6; ++k) EXPECT_NEAR(a[k], truth[k], 1e-4) << k;
  EXPECT_NEAR(fit.rgb.at<cv::Vec3f>(0, 0)[1], 1.0f, 1e-6);  // Gray: white.
}

TEST(Photometric, NormalMapEncodesRightUpOut) {
  cv::Mat n = cv::Mat::zeros(1, 3, CV_32FC3);
  n.at<cv::Vec3f>(0, 0) = cv::Vec3f(0, 0, 1);
  n.at<cv::Vec3f>(0, 1) = cv::Vec3f(0.6f, -0.8f, 0);
  const cv::Mat im = NormalMapImage(n);
  ASSERT_EQ(im.type(), CV_16UC3);
  // BGR: B is z, G is y, R is x.
  EXPECT_EQ(im.at<cv::Vec3w>(0, 0), cv::Vec3w(65535, 32768, 32768));
  EXPECT_NEAR(im.at<cv::Vec3w>(0, 1)[2], 0.8 * 65535, 1);
  EXPECT_NEAR(im.at<cv::Vec3w>(0, 1)[1], 0.1 * 65535, 1);
  EXPECT_EQ(im.at<cv::Vec3w>(0, 2), cv::Vec3w(0, 0, 0));  // Marked.
}

// A light taken as clipped below the level it is taken as lighting: refused, not run.
TEST(PhotometricOptions, LevelsOutOfOrderAreRefused) {
  PhotometricOptions o;
  o.min_level = 0.5;
  o.max_level = 0.4;
  const std::vector<cv::Mat> images(3, cv::Mat::zeros(4, 4, CV_8U));
  const std::vector<cv::Vec3d> directions = {{0, 0, 1}, {1, 0, 1}, {0, 1, 1}};
  const PhotometricResult r = PhotometricNormals(images, directions, cv::Mat(), o);
  ASSERT_FALSE(r.status.ok());
  EXPECT_NE(r.status.message().find("min_level"), std::string::npos) << r.status.message();
  std::string why;
  EXPECT_TRUE(PhotometricOptions().Check(&why)) << why;
}

}  // namespace
}  // namespace vellum
