// Measuring a restored page against the virtual gantry's truth, for the accuracy tests: the
// paper's Experiment I (restored checkerboard corners against a control after a least-squares
// homography), the restored page against the true page in millimetres (rigid, no scale fitted;
// and mirrored, to catch a page restored back to front), and restored mask pixels off the leaf.
#pragma once

#include <opencv2/core.hpp>
#include <vector>

#include "core/geometry/rigid2d.h"
#include "core/sim/gantry.h"
#include "core/sim/page.h"
#include "core/sim/texture.h"
#include "pipeline/process.h"

namespace vellum {

// a * p: an affine map (a restored page's pixel_from_flat) applied to a point.
inline cv::Point2d ApplyAffine(const cv::Matx23d& a, const cv::Point2d& p) {
  return {a(0, 0) * p.x + a(0, 1) * p.y + a(0, 2), a(1, 0) * p.x + a(1, 1) * p.y + a(1, 2)};
}

// The true page coordinates (s, t), mm, of a checkerboard page's inner corners, row by row.
std::vector<cv::Point2d> TrueCorners(cv::Size2d page_mm,
                                     const TextureOptions& texture = TextureOptions());

// The page's flat frame onto the true page: the rigid fit of its sheet's measured nodes to the
// true page coordinates at their camera pixels (`truth.page` where `truth.on_page`).
Rigid2D FlatToTrue(const GroundTruth& truth, const PageResult& page);

// Calls visit(u, v, st) for every other restored leaf pixel (u, v) of `page` (rows and columns
// in steps of 2), with st its true page point (s, t), mm: the restored map back to the flat
// frame, then `to_true`.
template <typename Visit>
void ForLeafPixels(const PageResult& page, const Rigid2D& to_true, Visit&& visit) {
  const RestoreResult& r = page.restored;
  const cv::Matx22d inv = cv::Matx22d(r.pixel_from_flat(0, 0), r.pixel_from_flat(0, 1),
                                      r.pixel_from_flat(1, 0), r.pixel_from_flat(1, 1))
                              .inv();
  for (int v = 0; v < r.mask.rows; v += 2) {
    for (int u = 0; u < r.mask.cols; u += 2) {
      if (!r.mask.at<uint8_t>(v, u)) continue;
      const cv::Vec2d f = inv * cv::Vec2d(u - r.pixel_from_flat(0, 2), v - r.pixel_from_flat(1, 2));
      visit(u, v, to_true.Apply({f[0], f[1]}));
    }
  }
}

// The restored page's checkerboard corners, each refined to sub-pixel from where the page's true
// layout puts it (NaN where its neighbourhood is not all leaf: a hole, the edge). In `image` (an
// image registered to the restored page: another light's) when given.
std::vector<cv::Point2f> MeasureCorners(const PageResult& page, const Rigid2D& to_true,
                                        const std::vector<cv::Point2d>& truth,
                                        const cv::Mat& image = cv::Mat());

// A control that is the true layout itself: the corners at the restored page's dpi (a flat scan's
// corners, without its own few hundredths of a pixel of error).
std::vector<cv::Point2f> LayoutControl(const std::vector<cv::Point2d>& truth, double dpi);

struct Measured {
  double mean_px = 0, mean_mm = 0, rms_mm = 0, rms_mirrored_mm = 0;
  int corners = 0;
};

// Experiment I: the page's corners against the control's (homography) and the truth (rigid,
// in mm through the restored page's own map, no scale fitted), and the same against the truth
// mirrored.
Measured ExperimentOne(const PageResult& page, const std::vector<cv::Point2f>& got,
                       const std::vector<cv::Point2f>& control,
                       const std::vector<cv::Point2d>& truth);

// Restored leaf pixels (every other row and column) that lie on none of `page` within
// `tolerance_mm` (checked on a grid of a third of it); their places in `off` (the restored
// mask's size) when given. `leaf` counts the pixels looked at.
int MaskOffLeaf(const PageResult& result, const Rigid2D& to_true, const Page& page,
                double tolerance_mm, int* leaf = nullptr, cv::Mat* off = nullptr);

// A spread's gutter as the virtual gantry saw it: in each row across the middle 80% of the spread,
// the innermost pixel of each page that the camera sees and the projector lights; and, per
// millimetre of the page's height, how far from its outer edge the page was seen.
struct GutterTruth {
  double chord_mm = 0;  // Median straight line between those pixels' points (0: not a spread).
  // The page surface not seen at the gutter: both pages' widths from their gutter edge to where
  // they were seen, added, median over the middle 80% of the pages' height (0: not a spread).
  double hidden_mm = 0;
  // Per page and per millimetre of t: the seen s nearest the gutter (the left page's gutter is
  // its s = w edge, the right page's its s = 0 edge); NaN where none.
  std::vector<double> innermost[2];
};
GutterTruth TrueGutter(const VirtualGantry& gantry);

}  // namespace vellum
