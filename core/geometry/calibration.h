// The calibration model of the paper's section 3.2: a pinhole camera and a projector modelled
// as an inverse camera (the virtual, unmirrored one), both in a world frame on the table
// (mm, z = 0 on the table, +z towards the camera), with OpenCV's 5-term lens distortion.
#pragma once

#include <limits>
#include <opencv2/core.hpp>
#include <string>

namespace vellum {

struct CameraModel {
  cv::Size size;                                               // Image size, pixels.
  cv::Matx33d matrix = cv::Matx33d::eye();                     // Intrinsics K, pixels.
  cv::Vec<double, 5> distortion = cv::Vec<double, 5>::all(0);  // k1 k2 p1 p2 k3 (OpenCV).
  cv::Matx33d rotation = cv::Matx33d::eye();                   // camera_from_world rotation.
  cv::Vec3d translation = cv::Vec3d(0, 0, 0);                  // camera_from_world translation, mm.

  bool Check(std::string* why) const;
  bool HasDistortion() const;
  // Optical centre in world coordinates, mm.
  cv::Vec3d Center() const;
  // World point (mm) to image pixel, with distortion. Points behind the camera give NaN.
  cv::Point2d Project(const cv::Vec3d& world) const;
  // Image pixel to ideal (undistorted) normalised coordinates (x/z, y/z in the camera frame).
  cv::Point2d Normalize(const cv::Point2d& pixel) const;
  // The same, the distortion's inversion started from `shift`: the ideal point less the
  // distorted one of a nearby pixel (whose shift differs little from this one's), and left with
  // this pixel's. Along a row of pixels the inversion starts nearer its answer and takes fewer
  // Newton rounds; the result is the same to the inversion's tolerance (1e-12).
  cv::Point2d Normalize(const cv::Point2d& pixel, cv::Point2d* shift) const;
  // Unit ray direction in world coordinates through an image pixel (`shift` as above).
  cv::Vec3d RayDirection(const cv::Point2d& pixel) const;
  cv::Vec3d RayDirection(const cv::Point2d& pixel, cv::Point2d* shift) const;
  // Every pixel's RayDirection (CV_32FC3, `size`), on both cores. The distortion is inverted
  // from scratch at every kRayTableStep-th pixel across and down; between them each pixel's
  // inversion starts from the bilinear of those and takes one Newton round (from a start within
  // kRayTableStartPx the round leaves an error well under 1e-6 px). A cell whose bilinear strays
  // further at its centre is inverted pixel by pixel.
  cv::Mat RayTable() const;
  static constexpr int kRayTableStep = 8;
  static constexpr double kRayTableStartPx = 0.05;
};

struct Calibration {
  CameraModel camera;
  CameraModel projector;
  // The heights a scanned object may have, mm (world z, the table at 0): points outside are
  // rejected as mistriangulated. Calibration key `working_volume_z` (optional).
  double min_z_mm = -20.0, max_z_mm = 300.0;
  // How far the lengths this calibration measures are from the truth, %: measured by `vellum
  // calibrate` on its board (the corners triangulated against the board's own layout), NaN when
  // not measured. Calibration key `scale_error_percent` (optional).
  double scale_error_percent = std::numeric_limits<double>::quiet_NaN();

  bool Check(std::string* why) const;
};

// Builds a camera_from_world rotation for a device at `eye` looking at `target`, with the image
// x axis as close as possible to world direction `right` (all in world coordinates).
cv::Matx33d LookAt(const cv::Vec3d& eye, const cv::Vec3d& target, const cv::Vec3d& right);

}  // namespace vellum
