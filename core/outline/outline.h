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

#include "core/common/object_kind.h"
#include "core/common/status.h"
#include "core/common/view_sides.h"
#include "core/geometry/calibration.h"

namespace vellum {

// The surround: the planes the leaf lies on and among (FitSurround).
struct SurroundOptions {
  int max_planes = 3;          // Table, support, frame.
  double min_share = 0.08;     // A plane holds at least this share of the samples.
  double tolerance_mm = 0.05;  // Its inliers lie this close to it, mm (more where noisier).
  double max_tilt_deg = 20;    // A surround is near level, degrees.
  // Table, support and frame lie on one another: each plane after the first (the table) is
  // parallel to it within this, degrees (a folded leaf's flat halves are not).
  double max_relative_tilt_deg = 3;
  bool Check(std::string* why) const;
};

// Leaf against surround (CutLeaf): one energy over every cue, its terms in nats (natural log
// likelihood ratios). A block's height above the surround, d, is N(0, sigma) on the surround
// (sigma: the block's noise and plane_mm together); on a leaf, flush_share of it is so too (a
// leaf flush with what it rests on) and the rest spread evenly over 0 to thickness_mm (a leaf's
// thickness) and thinly beyond (its bends).
struct CutOptions {
  double plane_mm = 0.01;      // How far the surround itself strays from its plane, mm.
  double flush_share = 0.15;   // Share of a leaf lying flush with what it rests on.
  double thickness_mm = 0.5;   // A leaf's rim stands up to this high, mm.
  double max_off = 4;          // The height's evidence for leaf is clipped to this...
  double max_on = 2.5;         // ... and for surround to this.
  double look_weight = 1;      // The look's log-likelihood ratio per block, weighted by this...
  double max_look = 3;         // ... and clipped to this.
  double border_cost = 2;      // A block on the view's border costs this much to call leaf.
  double smooth = 1.0;         // The outline's cost between two blocks...
  double smooth_floor = 0.25;  // ... falling to this share of it across a rim or an edge.
  int rounds = 0;              // The look relearned from the last cut this many times.
  bool Check(std::string* why) const;
};

struct OutlineOptions {
  // The cues (MeasureCues).
  double step_mm = 0.08;        // A height step this high is a rim, mm.
  int scale_px = 3;             // Steps measured across 2 x this many pixels (the decoder's fit).
  double max_slope_deg = 80;    // A surface seen steeper than this is a silhouette (a rim).
  double edge_contrast = 0.05;  // A texture edge: brightness changing by this share of the
                                // paper's per pixel.
  // The cut (MakeBlocks, FitSurround, CutLeaf, RefineRim).
  int blocks_across = 400;  // The cut decides on blocks: the view's longer side in this many.
  SurroundOptions surround;
  CutOptions cut;
  // The rim (RefineRim, TrimRim).
  int band_px = 8;  // RefineRim moves the cut's outline by up to a block and this many pixels.
  // The surround seen in a well of the leaf (the table between an open book's pages, narrower
  // than the cut's blocks): a pixel within well_plane_mm of a surround plane (a dark table's
  // points are that noisy), with the leaf at least well_depth_mm above it within four pixels,
  // that looks like the surround by at least well_look nats.
  double well_plane_mm = 0.2;
  double well_depth_mm = 1.0;
  double well_look = 1.0;
  // A rim pixel off the leaf's surface by more than this (and what its slope gives over two
  // pixels) is a mixed pixel, half leaf and half what lies below: trimmed, mm.
  double trim_off_mm = 0.8;
  // A leaf on a support or in a frame (the cut again inside what was found): it stands at least
  // lies_on_mm (and three times its noise) off the plane along its outline, and lies_on_apart of
  // its outline is set apart there (a rim, an edge, unmeasured). What was found, lying on a plane
  // more than raised_plane_mm above the table with nothing standing on it, may be a support itself
  // (flagged).
  double lies_on_mm = 0.03;
  double lies_on_apart = 0.7;
  // A leaf in a frame's window lies below the frame's face along most of its outline, or rests on
  // the table (within cut.thickness_mm of it) along at least this share of it: a waved or creased
  // leaf rises above the face where its crests meet the window's edge.
  double window_resting_share = 0.15;
  double raised_plane_mm = 1.0;
  // ... unless at least this share of what lies just outside it is as high (within
  // raised_plane_mm): then it is a leaf on a support wider than itself.
  double wider_support_share = 0.25;
  // The leaf.
  double min_area = 0.02;        // A leaf covers at least this share of the image.
  double max_view_share = 0.85;  // A leaf covering more of the measured view is doubtful.
  cv::Rect hint;                 // Camera pixels inside the leaf (empty: the centre of the view).
  int border_px = 2;             // A leaf within this of the image border runs off the view.
  // So does one whose look runs on to the border beyond its outline (LookRunsOff: within
  // off_view_reach_share of the view's longer side from the border, along a stretch of at least
  // off_view_share of it): where the projector does not reach the view's edge, or where a flat
  // leaf's look alone sets it apart, the outline stops short of the border the leaf runs off.
  double off_view_reach_share = 0.08;
  double off_view_share = 0.005;
  // The rim's confidence (RimConfidence): set apart by its look where the brighter fifth of the
  // leaf and of what lies beside it, within rim_look_px of the outline, differ by this share of
  // the paper's brightness.
  int rim_look_px = 6;
  double rim_look_contrast = 0.04;
  // The leaf seen but not measured beside its outline (UnseenBeside: within unseen_reach_px of
  // it, at least unseen_look nats more like the leaf than the surround): over max_unseen_share
  // of the leaf's area is flagged (edge_unmeasured), as it is missing from the restored page.
  // Where the look cannot tell (a table of the paper's shade), a pixel beside the leaf without a
  // height is its leaf when the rig's projector lights the table behind it (ProjectorSight: the
  // line to the projector passing unmeasured_clear_mm or more over every point beneath it).
  int unseen_reach_px = 40;
  double unseen_look = 1.0;
  double max_unseen_share = 0.01;
  double unseen_clear_mm = 0.5;
  // The leaf's edge seen edge-on (EdgeOnShare): an outline pixel whose edge stands at least
  // edge_on_height_mm above the surround beneath it, where the surface 3 to edge_on_band_px
  // pixels inside is seen more than edge_on_deg from face-on (each pixel's patch of it
  // 1 / cos(edge_on_deg) times a face-on pixel's). Over max_edge_on_share of the outline is
  // flagged (edge_on): a curl rolled past the camera's line of sight shows only a sliver of its
  // edge and hides the leaf beneath it, and the measured surface does not tell the two apart
  // (on the scene family, a curl whose edge hides 11 mm of the leaf measured about 74 to 76
  // degrees along a third of its outline, as one that hides nothing; every other leaf was over
  // the angle along under a tenth of its outline).
  double edge_on_height_mm = 5;
  double edge_on_deg = 73;
  int edge_on_band_px = 6;
  double max_edge_on_share = 0.15;
  // The outline at the pixel leaving out more than this share of what the cut found well inside
  // its outline (its holes aside) is doubtful (outline_uncertain).
  double max_lost_share = 0.1;
  // Spreads (SplitAtGutter).
  bool find_spread = true;  // Look for two pages meeting at a gutter.
  // What the operator says lies there: a leaf is never split, a book always looked for as two
  // pages (a warning when they are not found), auto splits on strong evidence only.
  ObjectKind object = ObjectKind::kAuto;
  // A gutter (SplitAtGutter) is a valley from which each page rises gutter_rise_mm within
  // gutter_reach_mm, sharply: gutter_crease_mm within gutter_width_mm (a book's pages at 20
  // degrees rise 1.1 mm in 3 mm; a trough, a roll or a ripple rises gently from its lowest line
  // and stays one leaf).
  double gutter_rise_mm = 2;
  double gutter_reach_mm = 40;
  double gutter_width_mm = 3;
  double gutter_crease_mm = 0.6;
  // The gap between the pages is looked for within gutter_apart_px of the valley's line; a row
  // where it closed borrows the median of gutter_borrow_rows rows either side; where the pages
  // meet, the pixels within gutter_meet_px of the line are left out of both (the line is fitted
  // to the rows' lowest points to about a pixel).
  int gutter_apart_px = 12;
  int gutter_borrow_rows = 24;
  double gutter_meet_px = 1.5;

  bool Check(std::string* why) const;
};

// Why an outline is doubtful: a warning for the report, with its code (outline_uncertain,
// object_ambiguous, ...) and a message for the operator that says what to do.
struct OutlineDoubt {
  std::string code, message;
};

struct Outline {
  Status status = Status::Error("outline not found (not run)");
  cv::Mat mask;                 // CV_8U 255 on the leaf (on both pages of a spread), holes out.
  std::vector<cv::Mat> pages;   // One mask per page: the leaf, or a spread's left then right.
  double confidence = 0;        // Share of the rim where the leaf is set apart from its surround.
  bool touches_border = false;  // The leaf runs off the camera's view.
  std::string method;           // How it was found: "cut" (every cue at once).
  // Share of the leaf found (by any cue) that has a 3D point: what has none where it reaches the
  // leaf's outline (a shadow, a side seen edge-on) is not in `mask`, and holes filled are.
  double measured_share = 0;
  // Of the leaf's area, the share more of it seen beside the outline without a 3D point (a
  // curled edge turned edge-on to the projector): not in `mask`, not restored.
  double unseen_share = 0;
  // Share of the outline that is its edge standing off the surround seen edge-on (EdgeOnShare).
  double edge_on_share = 0;
  int holes = 0;                     // Holes in the leaf that show what is under it.
  cv::Vec4f gutter{0, 0, 0, 0};      // A spread's gutter line in the image: (vx, vy, x0, y0).
  std::vector<OutlineDoubt> doubts;  // What makes it doubtful (none: found with confidence).
};

// Whether `hint` (camera pixels) can be a leaf hint in a view of `view`: a box inside the view
// covering at most `max_share` of it (a hint is a box inside the leaf, not around it: a hint
// over the whole view seeds the table as the leaf). `why` gets the reason, in a few words that
// name the hint, when not. Every path a hint comes by (scan.yaml, --leaf-hint, the bus, the
// viewer) meets this check, in FindLeaf at the latest.
bool LeafHintFits(const cv::Rect& hint, cv::Size view, double max_share, std::string* why);
// Its rule on the share alone, for a hint given as fractions of a view not yet known (`vellum
// scan --leaf-hint`): `share` of the view, the hint as `name` in the reason.
bool LeafHintShareFits(double share, double max_share, const std::string& name, std::string* why);

// Finds the leaf in an organised point map (CV_32FC3, world mm, NaN where invalid) and its
// texture (the same size). `rig`, the calibration that measured the points, if given, tells the
// projector's shadows from the leaf unmeasured beside the outline where the look cannot.
Outline FindLeaf(const cv::Mat& points, const cv::Mat& texture,
                 const OutlineOptions& options = OutlineOptions(),
                 const Calibration* rig = nullptr);

// What a spread's gutter keeps from view: in each image row across the middle 80% of the
// spread, the straight line between the last points measured on either side of the gutter (the
// innermost point of the left page and of the right page). Deep in a gutter the camera or the
// projector does not reach the pages, and that part of them is not measured: the restored pages
// end there, and the line is the least page surface missing between them (the surface runs
// down into the gutter and back up). Where the pages part and what lies between them is measured
// (the table seen in the gap, off the leaf), each page is seen to its foot, and the gap is no
// page: the lines from each page's last point to the first point measured beside it instead,
// each no longer than the page's own length per pixel over the pixels between (the line runs
// down the page's edge to the table, and those pixels may be the page's shadow on the table).
// Where the pages do not part, each page's slope at its innermost point (over its last
// kSlopePx pixels) carried on down until the two meet bounds from above what a valley that bends
// one way can hide between them: that surface lies within the triangle of the two points and
// their meeting.
struct GutterGap {
  int rows = 0;          // Rows with a measured point on both sides.
  double median_mm = 0;  // The line's median length over those rows, mm.
  double p95_mm = 0;     // Its 95th percentile, mm.
  double bound_mm = 0;   // The median over the rows of the slopes' meeting (the line where none).
  static constexpr int kSlopePx = 3;
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

// The live preview's most width, camera pixels (vellum-camera sends it at most this wide).
inline constexpr int kPreviewWidth = 640;
// The camera's image as the live preview shows it: at most kPreviewWidth wide (by area).
cv::Mat PreviewOf(const cv::Mat& image);

// The leaf as a live preview shows it, before any scan, for placing it: by its look alone (the
// scan itself finds the leaf by its shape; core/outline/live.cc). A bright region set apart from
// a darker surround; within it, a solid part of another bright tone that it encloses, edged by
// a sharp step, when the region is a support or a mount about as bright as the leaf. Sets
// `touches_border` when it runs off the view. An error, in a few words for the viewer, when
// nothing sets a leaf apart: no bright region of min_area ("no leaf in view"), or only one that
// reaches three sides of the view, or two opposite ones, or covers most of it ("leaf as bright
// as its surround": a table or a support larger than the view, which only the scan tells apart).
Outline LeafInPreview(const cv::Mat& image, const OutlineOptions& options = OutlineOptions());

// The sides of the view (ViewSide bits, core/common/view_sides.h) a mask reaches within `border`
// pixels of the edge; every side for a mask too small to have an inside.
int ViewSidesReached(const cv::Mat& mask, int border);

// The texture with the outline drawn over it (each page in its own colour), for the report and
// the viewer.
cv::Mat DrawOutline(const cv::Mat& texture, const Outline& outline);

}  // namespace vellum
