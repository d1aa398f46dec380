// Image-space restoration (Brown & Seales 2004, section 3.10): every quad of the sheet is
// textured from its camera image m_i to its flattened position, either reprojected through the
// camera (3.10.1, the page as the camera would see it flat on the table) or orthographically
// at a chosen dpi (3.10.2, true scale). Sampling is bilinear where the warp magnifies and
// area-averaged (supersampled) where it shrinks, so stretched regions do not alias.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/geometry/calibration.h"
#include "core/mesh/mesh.h"

namespace vellum {

enum class RestoreView { kOrthographic, kCamera };

const char* ToString(RestoreView view);
bool ParseRestoreView(const std::string& text, RestoreView* view);

struct RestoreOptions {
  RestoreView view = RestoreView::kOrthographic;
  // Orthographic resolution, dots per inch; 0: what the camera truly sampled, at its finest on
  // this page (RestoreResult::finest_ppi, rounded to a whole dpi): coarser would throw away
  // detail the camera saw, finer would add none anywhere. The sampling map says where the page
  // was sampled less finely (a slope seen at a grazing angle).
  double dpi = 0;
  double margin_mm = 3.0;     // Orthographic: border around the flattened sheet (or leaf), mm.
  int max_supersampling = 8;  // Samples per pixel side where the warp shrinks, at most.
  // Orthographic, with the leaf's mask (Restore's `leaf`): turn the page so the leaf stands
  // upright (its straight edges along the image's axes, else its minimum-area rectangle's), and
  // crop to the leaf plus margin_mm.
  bool deskew = false;
  bool crop_to_leaf = false;

  bool Check(std::string* why) const;
};

struct RestorePlan;  // The warp of a restoration: its triangles, size and crop (restore.cc).

struct RestoreResult {
  Status status = Status::Error("restoration not run");
  cv::Mat image;  // Same type as the texture (8 or 16 bit, gray or BGR); 0 outside.
  cv::Mat mask;   // With a leaf mask: CV_8U, 255 where the restored pixel is leaf.
  RestoreView view = RestoreView::kOrthographic;
  double dpi = 0;                                      // Orthographic: the resolution used.
  cv::Matx23d pixel_from_flat = cv::Matx23d::zeros();  // Orthographic: flat mm -> pixel.
  double rotation_deg = 0;  // Orthographic: the turn applied to the flat page (deskew), degrees.
  // Orthographic: the camera's true sampling of the page at each restored pixel, in ppi (CV_32F,
  // the image's size; 0 off the sheet, and off the leaf when a leaf mask was given). It is the
  // warp's own: 25.4 times the smallest singular value of the map from flat-page millimetres to
  // camera pixels over each triangle of the sheet, so a slope seen at a grazing angle or a part
  // of the page far from the camera shows as coarser. It does not depend on the output dpi.
  cv::Mat sampling;
  // The sheet's finest true sampling, ppi: the 95th percentile by flat area (5% of the sheet is
  // sampled more finely).
  double finest_ppi = 0;
  // Restore's `extras`, each through the same warp as `image` (the same triangles and samples,
  // the same crop), so they register to it pixel for pixel; each of its own type.
  std::vector<cv::Mat> extras;
  // The warp itself, for RestoreMore.
  std::shared_ptr<const RestorePlan> plan;
};

// How finely a restored page was truly sampled (from RestoreResult::sampling, over its nonzero
// pixels).
struct SamplingSummary {
  double median_ppi = 0;
  double p5_ppi = 0;   // 95% of the page is sampled at least this finely.
  double p95_ppi = 0;  // 5% of the page is sampled more finely: its finest sampling.
  double share_400 = 0, share_300 = 0, share_200 = 0;  // Shares of the page at >= 400, 300, 200.
};
SamplingSummary SummarizeSampling(const cv::Mat& sampling);

// The camera's sampling of the table plane at the image centre, rounded to a whole dpi (so
// TIFF resolution tags, which OpenCV writes as integers, state it exactly). Restore's default
// when the sheet gives no sampling of its own.
double NativeDpi(const CameraModel& camera);

// `flat` holds the flattened (x, y) of every node, in mm, aligned to the page's original
// position (as Flatten returns it). `leaf` (optional, CV_8U of the texture's size, nonzero on
// the leaf) is restored alongside into RestoreResult::mask. `extras` (optional: other images of
// the same page from the same pose, of the texture's size, 8 or 16 bit or float, gray or
// three-channel: another light, the albedo, a mask, normals) are restored through the same warp
// into RestoreResult::extras.
RestoreResult Restore(const cv::Mat& texture, const Mesh& mesh,
                      const std::vector<cv::Point2d>& flat, const CameraModel& camera,
                      const RestoreOptions& options = RestoreOptions(),
                      const cv::Mat& leaf = cv::Mat(), const std::vector<cv::Mat>& extras = {});

// The sheet's own axes at each pixel of an orthographic restored page (`restored`, from
// Restore of this mesh and flat): the world directions in which the page runs to the image's
// right (along its columns) and up (against its rows), and its normal (towards the camera,
// right x up), each CV_32FC3, unit, from each triangle of the sheet smoothed over about one
// cell of its grid, zero off it. A
// world vector v reads (v . right, v . up, v . normal) in the flat page's own frame.
struct SheetFrame {
  cv::Mat right, up, normal;
};
SheetFrame RestoredSheetFrame(const Mesh& mesh, const std::vector<cv::Point2d>& flat,
                              const RestoreResult& restored);

// More images of the page from the same pose (as Restore's `extras`) through the warp of
// `restored`, after it: the same triangles, samples and crop, so they register to it pixel for
// pixel, without building the warp again. *out gets one image per input, each of its type, and
// `outside` (saturated to its type; NaN for a float image whose unmeasured pixels are NaN) off
// the sheet.
Status RestoreMore(const RestoreResult& restored, const std::vector<cv::Mat>& images,
                   std::vector<cv::Mat>* out, double outside = 0);

// The turn (degrees, in (-45, 45]) that sets a leaf upright from its restored mask: the sides of
// its minimum-area rectangle when it nearly fills it (a rectangular leaf, curled or not), else the
// direction of its straight edges when they make up most of its outline (a torn or burnt leaf
// with straight stretches), else the sides of that rectangle again.
double UprightAngle(const cv::Mat& mask);

}  // namespace vellum
