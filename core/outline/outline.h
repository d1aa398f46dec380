// Finding the leaf in a scan by its shape and its look together.
//
// Brown & Seales (2004) assume a bright page on a darker table. A real leaf lies on a support
// as bright as it is, in a paper frame, with burnt edges and holes, or is one of the two pages
// of an open book. What always sets it apart is its rim: a leaf has a thickness, so where it
// ends the measured surface steps down (by at least its thickness, 0.1-0.3 mm, far above the
// scanner's noise), or it curls away. The leaf is found as the surface that such steps enclose
// (slope-compensated height differences between neighbouring pixels, after a robust smoothing),
// around the centre of the view or an operator's hint; a strip that noise or unreadable ink cut
// off it, whose heights continue it, joins it; holes that show another surface stay holes, holes
// without data (shadows, ink) are filled. The brightness rule of the paper is the
// fallback, and a cross-check, when the shape finds nothing plausible. An open book is found as
// two pages meeting at a gutter: a valley from which the surface rises steeply on both sides.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"

namespace vellum {

struct OutlineOptions {
  double step_mm = 0.08;       // A height step this high is a rim, mm.
  int scale_px = 3;            // Steps measured across 2 x this many pixels (the decoder's fit).
  int gap_px = 4;              // Rims are closed over gaps of up to twice this, in pixels.
  double max_slope_deg = 80;   // A surface seen steeper than this is a silhouette (a rim).
  double min_area = 0.02;      // A leaf covers at least this share of the image.
  cv::Rect hint;               // Camera pixels inside the leaf (empty: the centre of the view).
  int border_px = 2;           // A leaf within this of the image border runs off the view.
  bool find_spread = true;     // Look for two pages meeting at a gutter.
  double gutter_rise_mm = 15;  // A spread's pages rise at least this much from the gutter, mm.
  // A gutter is a crease, not a trough: within gutter_width_mm of it each page rises at least
  // gutter_crease_mm (or is hidden in it). A leaf rolled into a trough (a cone, a roll) rises
  // gently from its lowest line and stays one leaf.
  double gutter_width_mm = 10;
  double gutter_crease_mm = 3;

  bool Check(std::string* why) const;
};

struct Outline {
  Status status = Status::Error("outline not found (not run)");
  cv::Mat mask;                  // CV_8U 255 on the leaf (on both pages of a spread), holes out.
  std::vector<cv::Mat> pages;    // One mask per page: the leaf, or a spread's left then right.
  double confidence = 0;         // Share of the rim where the leaf is set apart from its surround.
  bool touches_border = false;   // The leaf runs off the camera's view.
  std::string method;            // "shape", or "brightness" when the shape found no leaf.
  int holes = 0;                 // Holes in the leaf that show what is under it.
  cv::Vec4f gutter{0, 0, 0, 0};  // A spread's gutter line in the image: (vx, vy, x0, y0).
};

// Finds the leaf in an organised point map (CV_32FC3, mm, NaN where invalid) and its texture
// (the same size).
Outline FindLeaf(const cv::Mat& points, const cv::Mat& texture,
                 const OutlineOptions& options = OutlineOptions());

// What a spread's gutter keeps from view: in each image row across the middle 80% of the
// spread, the straight line between the last points measured on either side of the gutter (the
// innermost point of the left page and of the right page). Deep in a gutter the camera or the
// projector does not reach the pages, and that part of them is not measured: the restored pages
// end there, and the line is the least page surface missing between them (the surface runs
// down into the gutter and back up; the pages' own gap is part of it).
struct GutterGap {
  int rows = 0;          // Rows with a measured point on both sides.
  double median_mm = 0;  // The line's median length over those rows, mm.
  double p95_mm = 0;     // Its 95th percentile, mm.
};
// Rows 0 when the outline is not a spread.
GutterGap UnseenAtGutter(const cv::Mat& points, const Outline& outline);

// The largest hole of the leaf whose surface stands above the leaf around it. Through a hole
// one sees what the leaf lies on, lower than the leaf; a surface higher than the leaf around it
// (by at least `min_rise_mm`, a rim's step) is more likely the leaf itself, lying on a support
// that was taken for the leaf (the view's centre fell on the support). Area 0 when none.
struct RaisedHole {
  int area_px = 0;     // Its pixels.
  double rise_mm = 0;  // Its median height above the median of the leaf's ring around it.
  cv::Rect box;        // Where it is, camera pixels.
};
RaisedHole HighestRaisedHole(const cv::Mat& points, const cv::Mat& leaf_mask, double min_rise_mm);

// The leaf as a live preview shows it, before any scan, for placing it: by brightness alone
// (a leaf brighter than its surround; the scan itself finds the leaf by its shape). Sets
// `touches_border` when it runs off the view. An error, in a few words for the viewer, when
// nothing sets a leaf apart: no bright region of min_area ("no leaf in view"), or one covering
// most of the view (a support as bright as the leaf, which only the scan tells apart).
Outline LeafInPreview(const cv::Mat& image, const OutlineOptions& options = OutlineOptions());

// The texture with the outline drawn over it (each page in its own colour), for the report and
// the viewer.
cv::Mat DrawOutline(const cv::Mat& texture, const Outline& outline);

}  // namespace vellum
