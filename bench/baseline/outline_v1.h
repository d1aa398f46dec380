// The outline as it stood before finding the leaf became one cut over every cue (vellum at
// e13f57b, core/outline/outline.cc): a height flood from the view's centre with a fixed rim
// step, then the brightness rule as a fallback. Kept, unchanged but for its namespace, as the
// baseline bench/outline_bench times FindLeaf against in the same run.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"

namespace vellum::baseline {

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

}  // namespace vellum::baseline
