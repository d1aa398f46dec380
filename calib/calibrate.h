// Calibration of the camera, the projector (as an inverse camera) and the table's world frame
// from structured-light scans of a checkerboard in several poses (Moreno & Taubin, "Simple,
// Accurate, and Robust Projector-Camera Calibration", 3DIMPVT 2012).
//
// Per pose: the board's inner corners are found in the texture (sub-pixel); each corner's
// projector coordinate is the image of the camera corner under a homography fitted, by least
// squares, to the decoded camera -> projector correspondences in a window around it (a local
// homography, unbiased by the blur of the stripes). Then the camera and the projector are each
// calibrated as cameras from the same board corners (OpenCV's calibrateCamera), and their
// relative pose by stereo calibration with both intrinsics fixed. The pose lying flat on the
// table defines the world frame: z = 0 on the board, +z towards the camera (the paper's 3.2).
//
// The calibration describes the virtual, unmirrored projector. A projector whose images reach
// the board mirrored (the projector daemon's --flip does not match the mirror) sees the board
// with the opposite handedness from the camera; that is detected and reported, since no
// camera model can absorb a reflection.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/decode/decode.h"
#include "core/geometry/calibration.h"
#include "core/patterns/scan.h"

namespace vellum {

struct BoardSpec {
  cv::Size inner_corners{16, 21};  // Inner corners across and down (COLSxROWS).
  double square_mm = 10.0;         // Square side, mm.
};

struct CalibrateOptions {
  // Half-size of the local homography's window, in board squares (Moreno & Taubin use about
  // half a square: the window then holds only the corner's own four squares).
  double window_squares = 0.5;
  int min_window_points = 40;         // Decoded pixels a corner's homography needs.
  int min_views = 4;                  // Usable poses needed to solve.
  double warn_reprojection_px = 0.5;  // Errors above this are reported as warnings.
  // Overall errors above this: the calibration is not written unless forced (`--force`).
  double max_reprojection_px = 1.0;
  // A pose whose camera corners lie within this of an earlier pose's (RMS) is the same pose
  // given twice: refused.
  double same_pose_px = 0.5;
  // Leave one pose out: solve without each pose (but the table pose); report how far the
  // projector's pose moves, and how well the others predict the pose's projector corners. A
  // pose predicted worse than outlier_factor times the median and outlier_floor_px is an
  // outlier: dropped from the solve (named) while min_views remain.
  bool leave_one_out = true;
  double outlier_factor = 3.0;
  double outlier_floor_px = 0.3;
  DecodeOptions decode;

  bool Check(std::string* why) const;
};

// One board pose: the corners in the camera and the projector, or why the pose is not usable.
struct BoardView {
  std::string name;  // The pose's scan directory, for messages.
  Status status = Status::Error("not detected");
  cv::Size camera_size, projector_size;
  std::vector<cv::Point2f> camera_corners;     // Row-major, inner_corners.width per row.
  std::vector<cv::Point2f> projector_corners;  // Same order.
};

// Finds the board and each corner's projector coordinate in one pose's scan.
BoardView DetectBoard(const Scan& scan, const BoardSpec& board, const std::string& name,
                      const CalibrateOptions& options = CalibrateOptions());

struct ViewReport {
  std::string name;
  Status status = Status::Error("not used");  // Ok when the pose was used; else why not.
  int corners = 0;
  double camera_rms_px = 0, projector_rms_px = 0;
};

struct CalibrationSolution {
  Status status = Status::Error("not solved");
  Calibration calibration;
  std::vector<ViewReport> views;  // One per input pose, in input order.
  int views_used = 0, corners_used = 0;
  // The board's inner corners as it lies on the table pose, across the camera's rows and down
  // (the size given, or transposed when it was given the wrong way round: see warnings).
  cv::Size board;
  double camera_rms_px = 0, projector_rms_px = 0, stereo_rms_px = 0;
  // Errors above CalibrateOptions::warn_reprojection_px, and outlier poses (dropped, named).
  std::vector<std::string> warnings;
  // Why the calibration should not be written (errors above max_reprojection_px); "" if none.
  std::string over_limits;
  // Leave one pose out: the largest change of the projector's pose relative to the camera, and
  // the pose whose absence moves it most.
  double leave_one_out_deg = 0, leave_one_out_mm = 0;
  std::string leave_one_out_pose;
  // The scale the calibration measures lengths at, against the board's: each pose's corners
  // triangulated (camera ray against projector ray) by the solve without that pose (leave one
  // out; the table pose, and every pose when leave-one-out is off, by the whole solve), a
  // similarity fitted to the board's layout; the RMS of its scale's departure from 1 over the
  // poses, % (also calibration.scale_error_percent), and the worst pose's.
  double scale_error_percent = 0, worst_scale_error_percent = 0;
  std::string worst_scale_pose;
};

// Solves from the detected poses; views[table] is the pose lying flat on the table.
CalibrationSolution SolveCalibration(const std::vector<BoardView>& views, size_t table,
                                     const BoardSpec& board,
                                     const CalibrateOptions& options = CalibrateOptions());

// The scale at which `calibration` measures one detected pose's board (its corners in `board`'s
// layout), triangulated: 1 when it measures lengths truly (CalibrationSolution's scale error).
double BoardScale(const Calibration& calibration, const BoardSpec& board, const BoardView& view);

// The solution as text for the operator: per-pose and overall errors, corners used, warnings.
std::string FormatCalibrationReport(const CalibrationSolution& solution);

}  // namespace vellum
