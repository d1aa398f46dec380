// Triangulation of decoded pixels (Brown & Seales 2004, section 3.2): the 3D point M solves
// [u v 1]^T ~ P_cam M and [x y 1]^T ~ P_proj M in least squares. The camera pixel is the
// sample position, so M lies on its ray; along the ray we take the point whose projection is
// closest to the decoded projector pixel (x, y). The distance from (x, y) to the ray's image
// (the epipolar line) is the point's residual; inconsistent points are rejected.
#pragma once

#include <limits>
#include <opencv2/core.hpp>
#include <string>

#include "core/common/status.h"
#include "core/decode/decode.h"
#include "core/geometry/calibration.h"

namespace vellum {

struct TriangulateOptions {
  // Max residual, projector pixels (when rows are decoded); widened by half the step of a Gray
  // code alone that left out its finest bits (DecodeStats::step_px).
  double max_epipolar_error_px = 1.5;
  // Working volume, heights above the table, mm; NaN: the calibration's (Calibration::min_z_mm).
  double min_z_mm = std::numeric_limits<double>::quiet_NaN();
  double max_z_mm = std::numeric_limits<double>::quiet_NaN();
  // Flying points (flying.h): off the surface on both sides by more than this, mm (0: kept).
  double max_flying_mm = 0.5;
  int flying_reach_px = 4;  // Past the decoder's window (7 x 7: 3 px each side).

  bool Check(std::string* why) const;
};

struct PointMap {
  Status status = Status::Error("triangulation not run");
  cv::Mat points;    // CV_32FC3 world point per camera pixel, mm; NaN where invalid.
  cv::Mat residual;  // CV_32F epipolar residual, projector px; NaN where invalid.
  int valid = 0;
  int rejected_epipolar = 0;
  int rejected_volume = 0;  // Outside the working volume (of which below it:)
  int rejected_below = 0;
  int rejected_flying = 0;
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
