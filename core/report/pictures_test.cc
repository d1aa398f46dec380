// The report's pictures of a point map: the depth map and the valid mask, each pixel checked
// against OpenCV's own way of making them (split, convertTo to 8 bits, the turbo colour map),
// on a map with invalid pixels and a height range that is not symmetric about zero.
#include "core/report/pictures.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>

namespace vellum {
namespace {

cv::Mat RandomPoints(uint64_t seed) {
  cv::RNG rng(seed);
  cv::Mat points(37, 53, CV_32FC3);
  for (int v = 0; v < points.rows; ++v) {
    for (int u = 0; u < points.cols; ++u) {
      const float nan = std::numeric_limits<float>::quiet_NaN();
      points.at<cv::Vec3f>(v, u) = rng.uniform(0, 5) == 0
                                       ? cv::Vec3f(nan, nan, nan)
                                       : cv::Vec3f(u, v, rng.uniform(-3.5f, 41.0f) + 0.1f * v);
    }
  }
  return points;
}

TEST(Pictures, TheDepthPictureAndValidMaskAreOpenCvsColourMapOfTheHeights) {
  for (uint64_t seed : {1u, 2u, 3u}) {
    const cv::Mat points = RandomPoints(seed);
    std::vector<cv::Mat> planes;
    cv::split(points, planes);
    const cv::Mat valid = planes[2] == planes[2];
    double lo = 0, hi = 0;
    cv::minMaxLoc(planes[2], &lo, &hi, nullptr, nullptr, valid);
    cv::Mat z8, want;
    planes[2].convertTo(z8, CV_8U, 255.0 / (hi - lo), -lo * 255.0 / (hi - lo));
    cv::applyColorMap(z8, want, cv::COLORMAP_TURBO);
    want.setTo(cv::Scalar::all(0), ~valid);

    double z_min = 0, z_max = 0;
    const cv::Mat depth = DepthPicture(points, &z_min, &z_max);
    EXPECT_EQ(z_min, lo);
    EXPECT_EQ(z_max, hi);
    EXPECT_EQ(cv::norm(depth, want, cv::NORM_INF), 0) << "seed " << seed;
    EXPECT_EQ(cv::norm(ValidMask(points), valid, cv::NORM_INF), 0);
    const cv::Mat with_bar = WithHeightBar(depth, z_min, z_max);
    EXPECT_GT(with_bar.cols, depth.cols);
    EXPECT_EQ(cv::norm(with_bar(cv::Rect(0, 0, depth.cols, depth.rows)), depth, cv::NORM_INF), 0);
  }
  // Nothing measured: black, and the range 0 to 1.
  const cv::Mat none(8, 8, CV_32FC3, cv::Scalar::all(std::numeric_limits<float>::quiet_NaN()));
  double z_min = -1, z_max = -1;
  EXPECT_EQ(cv::countNonZero(DepthPicture(none, &z_min, &z_max).reshape(1)), 0);
  EXPECT_EQ(z_min, 0);
  EXPECT_EQ(z_max, 1);
}

}  // namespace
}  // namespace vellum
