// Triangulation of decoded pixels (Brown & Seales 2004, section 3.2): the 3D point M solves
// [u v 1]^T ~ P_cam M and [x y 1]^T ~ P_proj M in least squares. The camera pixel is the
// sample position, so M lies on its ray; along the ray we take the point whose projection is
// closest to the decoded projector pixel (x, y). The distance from (x, y) to the ray's image
// (the epipolar line) is the point's residual; inconsistent points are rejected.
#pragma once

#include <opencv2/core.hpp>
#include <string>

#include "core/common/status.h"
#include "core/decode/decode.h"
#include "core/geometry/calibration.h"

namespace vellum {

struct TriangulateOptions {
  double max_epipolar_error_px = 1.5;  // Max residual, projector pixels (when rows are decoded).
  double min_z_mm = -20.0;             // Working volume: lowest accepted height above table, mm.
  double max_z_mm = 300.0;             // Highest accepted height, mm.

  bool Check(std::string* why) const;
};

struct PointMap {
  Status status = Status::Error("triangulation not run");
  cv::Mat points;    // CV_32FC3 world point per camera pixel, mm; NaN where invalid.
  cv::Mat residual;  // CV_32F epipolar residual, projector px; NaN where invalid.
  int valid = 0;
  int rejected_epipolar = 0;
  int rejected_volume = 0;
};

// Holds a calibration and the camera's per-pixel rays (computed once), and triangulates scans.
class Triangulator {
 public:
  // The calibration must pass Check() (ReadCalibration and the bus's FromMessage check it).
  explicit Triangulator(const Calibration& calibration);

  const Calibration& calibration() const { return calibration_; }
  PointMap Triangulate(const DecodeResult& decoded,
                       const TriangulateOptions& options = TriangulateOptions()) const;
  // The same into *out, reusing its images when they already have the right size and type.
  void Triangulate(const DecodeResult& decoded, const TriangulateOptions& options,
                   PointMap* out) const;

 private:
  Calibration calibration_;
  cv::Mat rays_;  // CV_32FC3 unit world direction per camera pixel.
};

}  // namespace vellum
