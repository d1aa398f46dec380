// Pictures for the operator's per-scan report (pure image making, no I/O): the depth map with
// a colour bar in mm, the valid-pixel mask, the flattening strain per quad, the flattened grid
// over the restored page, and matching before/after crops.
#pragma once

#include <functional>
#include <opencv2/core.hpp>
#include <vector>

#include "core/geometry/calibration.h"
#include "core/mesh/mesh.h"
#include "core/restore/restore.h"

namespace vellum {

// The height map of a point map (CV_32FC3, NaN where invalid) as a picture: z over the valid
// points' range in colour (turbo), black where invalid; sets the range in mm (0 to 1 when no
// point is valid). One pass to find the range, one to colour.
cv::Mat DepthPicture(const cv::Mat& points, double* z_min_mm, double* z_max_mm);

// A DepthPicture with its colour bar labelled in mm on the right (`z_min_mm`, `z_max_mm`: the
// range DepthPicture gave).
cv::Mat WithHeightBar(const cv::Mat& depth, double z_min_mm, double z_max_mm);

// 255 where the point map is valid, 0 elsewhere (CV_8U).
cv::Mat ValidMask(const cv::Mat& points);

// Where a flat-page point (mm) lands in the restored image: the orthographic map, or the
// camera's projection of (x, y, 0) in camera view.
std::function<cv::Point2d(const cv::Point2d&)> RestoredPixel(const RestoreResult& restored,
                                                             const CameraModel& camera);

// Each quad of the flattened sheet coloured by its residual strain (mean relative length error
// of its springs), on the restored image's frame, with a colour bar (0 .. the max strain).
cv::Mat StrainPicture(const Mesh& mesh, const std::vector<cv::Point2d>& flat,
                      const RestoreResult& restored, const CameraModel& camera);

// The camera's true sampling of the restored page (RestoreResult::sampling) in four bands, with
// their legend: >= 400 ppi, 300-400, 200-300, below 200; white off the page.
cv::Mat SamplingPicture(const cv::Mat& sampling);

// The flattened grid drawn over the restored page (every `step`-th grid line).
cv::Mat GridOverPage(const Mesh& mesh, const std::vector<cv::Point2d>& flat,
                     const RestoreResult& restored, const CameraModel& camera, int step = 4);

// The restored page for the report, at most `max_width` pixels wide; in orthographic view with
// a scale bar (a round length in mm, about a quarter of the page, in black and white segments)
// at its lower left. Sets *bar_mm to the bar's length (0 in camera view: no true scale).
cv::Mat RestoredWithScaleBar(const RestoreResult& restored, int max_width, double* bar_mm);

// The same part of the page before (texture) and after (restored), side by side: a window of
// `size_mm` around the sheet's central node.
cv::Mat BeforeAfter(const cv::Mat& texture, const Mesh& mesh, const std::vector<cv::Point2d>& flat,
                    const RestoreResult& restored, const CameraModel& camera, double size_mm = 50);

// Photometric normals on the flat page (CV_32FC3: x right, y up, z out; 0 where marked) as a
// relief lit from the top left at 30 degrees, the way fine relief is looked at: gray, 8-bit,
// marked pixels black.
cv::Mat ReliefPicture(const cv::Mat& normals);

}  // namespace vellum
