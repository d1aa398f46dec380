#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <stdexcept>
#include <string>

#include "core/sim/evaluate.h"
#include "core/sim/gantry.h"
#include "core/sim/page.h"

namespace vellum {
namespace {

// The developable shapes are isometries of the flat page: short steps keep their length (a
// chord of an arc of radius R and length h is shorter by h^3 / 24 R^2, < 1e-9 relative at
// h = 0.01 mm), and no point goes below the table.
TEST(Page, DevelopableShapesAreIsometricAndAboveTheTable) {
  for (PageShape shape : {PageShape::kFlat, PageShape::kCurl, PageShape::kFold, PageShape::kCone}) {
    PageOptions o;
    o.shape = shape;
    const Page page(o);
    const double h = 0.01;
    double worst = 0, lowest = 0;
    for (double t = 0; t <= 240 - h; t += 7.3) {
      for (double s = 0; s <= 190 - h; s += 5.9) {
        const cv::Vec3d p = page.Point(s, t);
        worst = std::max(worst, std::fabs(cv::norm(page.Point(s + h, t) - p) - h) / h);
        worst = std::max(worst, std::fabs(cv::norm(page.Point(s, t + h) - p) - h) / h);
        worst =
            std::max(worst, std::fabs(cv::norm(page.Point(s + h, t + h) - p) - h * M_SQRT2) / h);
        lowest = std::min(lowest, p[2]);
      }
    }
    EXPECT_LT(worst, 1e-6) << ToString(shape);
    EXPECT_GT(lowest, -1e-9) << ToString(shape);
  }
}

TEST(Page, WarpedShapesLeaveTheTable) {
  for (PageShape shape : {PageShape::kCurl, PageShape::kFold, PageShape::kCone, PageShape::kBump}) {
    PageOptions o;
    o.shape = shape;
    const Page page(o);
    double highest = 0;
    for (double t = 0; t <= 240; t += 10) {
      for (double s = 0; s <= 190; s += 10) highest = std::max(highest, page.Point(s, t)[2]);
    }
    EXPECT_GT(highest, 2.9) << ToString(shape);
  }
}

class GantryTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    PageOptions page;
    page.shape = PageShape::kCurl;
    gantry_ = new VirtualGantry(DefaultRig(), page, TextureOptions());
  }
  static void TearDownTestSuite() { delete gantry_; }
  static VirtualGantry* gantry_;
};
VirtualGantry* GantryTest::gantry_ = nullptr;

// Ground truth is self-consistent: each page pixel's point projects to the pixel centre and
// is the page's point at the stored page coordinate.
TEST_F(GantryTest, TruthProjectsToItsPixel) {
  const GroundTruth& truth = gantry_->truth();
  const Page page([] {
    PageOptions o;
    o.shape = PageShape::kCurl;
    return o;
  }());
  int checked = 0;
  for (int v = 0; v < truth.points.rows; v += 13) {
    for (int u = 0; u < truth.points.cols; u += 11) {
      const cv::Vec3d x(truth.points.at<cv::Vec3f>(v, u));
      const cv::Point2d p = gantry_->rig().camera.Project(x);
      // float storage of the point: ~3e-5 mm at 600 mm is ~1e-4 px.
      ASSERT_LT(cv::norm(p - cv::Point2d(u, v)), 2e-3) << u << "," << v;
      if (truth.on_page.at<uint8_t>(v, u)) {
        const cv::Vec2f st = truth.page.at<cv::Vec2f>(v, u);
        ASSERT_LT(cv::norm(page.Point(st[0], st[1]) - x), 1e-3);
        ++checked;
      } else {
        EXPECT_NEAR(x[2], 0.0, 1e-3) << "off the page the camera sees the table";
      }
    }
  }
  EXPECT_GT(checked, 3000);
}

TEST_F(GantryTest, CurlCastsAProjectorShadowOnTheTable) {
  const GroundTruth& truth = gantry_->truth();
  int table_shadow = 0;
  for (int v = 0; v < truth.lit.rows; ++v) {
    for (int u = 0; u < truth.lit.cols; ++u) {
      table_shadow += !truth.on_page.at<uint8_t>(v, u) && !truth.lit.at<uint8_t>(v, u) &&
                      truth.points.at<cv::Vec3f>(v, u)[0] > 40;
    }
  }
  EXPECT_GT(table_shadow, 5000);
}

TEST_F(GantryTest, RenderingIsDeterministicPerSeed) {
  const cv::Mat white(768, 1024, CV_8U, cv::Scalar(255));
  const cv::Mat a = gantry_->RenderFrame(white, 5), b = gantry_->RenderFrame(white, 5);
  const cv::Mat c = gantry_->RenderFrame(white, 6);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_INF), 0);
  EXPECT_GT(cv::norm(a, c, cv::NORM_INF), 0);
  EXPECT_EQ(gantry_->RenderTexture(5).type(), CV_8UC1);  // A gray page, a gray texture.
  // Paper under full light: 255 x 0.85 x (0.08 + 0.85 cos) stays below 8-bit saturation.
  double lo, hi;
  cv::minMaxLoc(a, &lo, &hi);
  EXPECT_LT(hi, 255);
}

// A colour page image gives a colour texture (the studio light sees each channel's albedo) and
// the same gray structured-light frames; a gray page gives a gray texture. The page's left half
// is red and its right half green, both of one gray level: only the texture tells them apart.
TEST(Gantry, AColourPageGivesAColourTextureAndGrayPatternFrames) {
  PageOptions page;
  page.shape = PageShape::kFlat;
  TextureOptions texture;
  texture.kind = TextureKind::kImage;
  texture.image = cv::Mat(240, 190, CV_8UC3, cv::Scalar(40, 40, 200));
  texture.image.colRange(95, 190).setTo(cv::Scalar(40, 120, 51));  // Gray 90; the red, 88.
  const VirtualGantry gantry(DefaultRig(), page, texture);
  const cv::Mat colour = gantry.RenderTexture(3);
  ASSERT_EQ(colour.type(), CV_8UC3);
  const cv::Mat white(768, 1024, CV_8U, cv::Scalar(255));
  EXPECT_EQ(gantry.RenderFrame(white, 3).type(), CV_8UC1);
  const GroundTruth& truth = gantry.truth();
  cv::Scalar left(0, 0, 0), right(0, 0, 0), table(0, 0, 0);
  int n_left = 0, n_right = 0, n_table = 0;
  for (int v = 0; v < colour.rows; v += 7) {
    for (int u = 0; u < colour.cols; u += 7) {
      const cv::Vec3b c = colour.at<cv::Vec3b>(v, u);
      const cv::Scalar bgr(c[0], c[1], c[2]);
      if (!truth.page_index.at<uint8_t>(v, u)) {
        table += bgr;
        ++n_table;
        continue;
      }
      const float s = truth.page.at<cv::Vec2f>(v, u)[0];
      if (s > 10 && s < 85) {
        left += bgr;
        ++n_left;
      } else if (s > 105 && s < 180) {
        right += bgr;
        ++n_right;
      }
    }
  }
  ASSERT_GT(n_left, 100);
  ASSERT_GT(n_right, 100);
  ASSERT_GT(n_table, 100);
  left /= n_left;
  right /= n_right;
  table /= n_table;
  // The image's hues, within the sensor's noise (1.5 DN, averaged over hundreds of pixels).
  EXPECT_GT(left[2], 3 * left[1]) << left;
  EXPECT_NEAR(left[0], left[1], 2) << left;
  EXPECT_GT(right[1], 2 * right[0]) << right;
  EXPECT_GT(right[1], 2 * right[2]) << right;
  EXPECT_NEAR(table[0], table[2], 2) << table;  // The table stays gray.
  EXPECT_NEAR(table[1], table[2], 2) << table;
}

// The virtual gantry refuses a scene it cannot draw, naming the option, rather than drawing
// something else.
TEST(SimOptions, AnImpossibleSceneIsRefusedByName) {
  auto refused = [](const std::function<void()>& make, const std::string& name) {
    try {
      make();
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(name), std::string::npos) << e.what();
      return true;
    }
    return false;
  };
  PageOptions page;
  page.size_mm = {0, 240};
  EXPECT_TRUE(refused([&] { Page p(page); }, "size_mm"));
  TextureOptions texture;
  texture.kind = TextureKind::kImage;  // And no image.
  EXPECT_TRUE(refused([&] { PageTexture t(texture, {100, 100}); }, "image"));
  LightOptions light;
  light.texture_bits = 12;
  EXPECT_TRUE(refused([&] { VirtualGantry g(QuickRig(), PageOptions(), TextureOptions(), light); },
                      "texture_bits"));
  SceneOptions scene;
  scene.support_albedo = 1.5;
  EXPECT_TRUE(refused(
      [&] { VirtualGantry g(QuickRig(), PageOptions(), TextureOptions(), LightOptions(), scene); },
      "support_albedo"));
}

}  // namespace
}  // namespace vellum
