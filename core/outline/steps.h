// The steps of finding the leaf (FindLeaf, outline.h), each on its own and tested on small
// synthetic maps (steps_test.cc):
//   MeasureCues      every cue per camera pixel: the heights, the rims (steps in the surface and
//                    silhouettes, not creases), the texture's edges
//   MakeBlocks       the cues gathered into blocks of a few pixels, for the cut
//   FitSurround      the planes the leaf lies on and among (table, support, frame), from the
//                    outermost measured blocks of the view
//   CutLeaf          leaf against surround over the blocks: one energy over every cue (the
//                    heights off the surround, the look learned from each side, the view's
//                    border, the rims and edges between blocks), minimised by a graph cut
//   RefineRim        the cut's outline brought to the pixel: a watershed on the rims and edges
//                    in a band around it
//   FillHoles        holes that show no other surface filled, the rest kept
//   SplitAtGutter    an open book's two pages at the valley between them
// Internal to core/outline; the public API is outline.h.
#pragma once

#include <array>
#include <cmath>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/geometry/calibration.h"
#include "core/outline/outline.h"

namespace vellum::outline {

constexpr float kNoData = -1e4f;  // Heights below -1e3 mean "no point".
inline bool Valid(float z) { return z > -1e3f; }

// `mask` (CV_8U) with its holes filled: what its outer outlines enclose.
cv::Mat Filled(const cv::Mat& mask);

// The median of `values` (reordered); 0 when empty.
double Median(std::vector<float>* values);

// ---- MeasureCues ----
struct Cues {
  cv::Mat gray;    // CV_8U, the texture's brightness.
  cv::Mat colour;  // CV_8UC3 (B, G, R), gray repeated for a gray texture.
  cv::Mat z;       // CV_32F heights, mm, robustly smoothed; kNoData where none.
  cv::Mat zn;      // The same with NaN where none.
  cv::Mat rim;     // CV_32F rim strength (steps, silhouettes) in units of the rim threshold there.
  cv::Mat edge;    // CV_32F the texture's edge strength in units of options.edge_contrast.
  double bright = 255;  // The paper's brightness: the level 95% of the texture lies at or below.
};
// Every pixel's cues from the point map (CV_32FC3, mm, NaN where none) and its texture.
Cues MeasureCues(const cv::Mat& points, const cv::Mat& texture, const OutlineOptions& options);

// Heights of the point map, each the median of its own and the means of its opposite
// neighbours where both have a point: an isolated outlier is dropped, a step stays sharp.
// kNoData where there is no height; `nan` (if given) gets NaN there instead.
cv::Mat SmoothHeights(const cv::Mat& points, cv::Mat* nan = nullptr);

// How strongly each pixel lies on a rim, mm: where the surface steps (it is not continuous: the
// surface on either side, extrapolated linearly, does not meet within `scale` pixels of the pixel;
// a crease or a bend, where it meets, is no rim), or turns nearly parallel to the camera's rays
// (steeper than max_slope_deg: a silhouette). Along rows, columns and both diagonals.
cv::Mat RimStrength(const cv::Mat& points, const cv::Mat& zn, int scale, double max_slope_deg);

// The texture's paper brightness: the level 95% of its pixels are at or below (gray levels).
double BrightLevel(const cv::Mat& gray);

// The height step that counts as a rim at each pixel, mm: `step` where the surface is at least
// half as bright as paper, more where it is darker (the decoder's noise goes as 1/brightness).
// `darkest`: judged by the darkest brightness near the pixel (cautious) rather than the mean.
// `in_steps` (if given) is divided by it in the same pass.
cv::Mat StepThreshold(const cv::Mat& gray, double bright, double step, int scale, bool darkest,
                      cv::Mat* in_steps = nullptr);

// ---- MakeBlocks ----
// The cues over square blocks of `size` pixels (the view's last partial row and column of
// blocks dropped): what the cut decides on.
struct Blocks {
  int size = 4;     // Pixels a side.
  cv::Size grid;    // Blocks across and down.
  cv::Mat valid;    // CV_32F share of the block's pixels with a height.
  cv::Mat x, y, z;  // CV_32F the mean world point of those pixels, mm (NaN without any).
  cv::Mat noise;    // CV_32F the standard error of z, mm (from the scatter within the block).
  cv::Mat colour;   // CV_8UC3 the block's mean colour.
  cv::Mat rim;      // CV_32F the strongest rim in the block (Cues::rim).
  cv::Mat edge;     // CV_32F the strongest texture edge in the block (Cues::edge).
};
// Block size: the view's longer side over `target` blocks, at least 2 px.
int BlockSize(cv::Size view, int target);
Blocks MakeBlocks(const Cues& cues, const cv::Mat& points, int size);

// ---- FitSurround ----
// A plane of the surround: z = a x + b y + c (world mm).
struct Plane {
  double a = 0, b = 0, c = 0;
  int inliers = 0;
  double At(double x, double y) const { return a * x + b * y + c; }
};
// The angle between two planes, degrees.
double TiltBetweenDeg(const Plane& p, const Plane& q);
// The surround's planes, from the samples: the outermost measured blocks of each row and column
// of the grid (within its outer quarter), by RANSAC (deterministic), one plane after another,
// each after the first parallel to it (SurroundOptions::max_relative_tilt_deg).
std::vector<Plane> FitSurround(const Blocks& blocks, const SurroundOptions& options);
// The planes fitted again over everything of the surround in view: the solidly measured blocks
// two or more from `leaf` (blocks), each on the plane it lies nearest and within tolerance of.
// Fitted to the view's outermost blocks alone, a plane can tilt by hundredths of a millimetre
// across the view, which the cut reads as a leaf's thickness. A plane keeps its fit where fewer
// blocks than before lie on it. Returns how far the planes moved (mm, the most at any of the
// blocks on them).
double RefitSurround(const Blocks& blocks, const cv::Mat& leaf, const SurroundOptions& options,
                     std::vector<Plane>* planes);
// Each block's signed height above the nearest of `planes` (mm, NaN where unmeasured; the
// block's height where there are no planes).
cv::Mat AboveSurround(const Blocks& blocks, const std::vector<Plane>& planes);

// ---- CutLeaf ----
// A look: a histogram of colours over 32 brightness levels and 4 x 4 hues (red and blue each
// against green), so a gray texture uses the brightness alone; CutLeaf learns one for the leaf
// and one for the surround.
class Look {
 public:
  static constexpr int kLevels = 32, kHues = 4, kBins = kLevels * kHues * kHues;
  static int Bin(const cv::Vec3b& c) {
    const int level = (c[0] + 2 * c[1] + c[2]) / 4 / (256 / kLevels);
    const int red = std::clamp((c[2] - c[1] + 256) * kHues / 512, 0, kHues - 1);
    const int blue = std::clamp((c[0] - c[1] + 256) * kHues / 512, 0, kHues - 1);
    return (level * kHues + red) * kHues + blue;
  }
  void Add(int bin, double weight) {
    counts_[bin] += weight;
    total_ += weight;
  }
  void Add(const Look& other) {  // Another look's samples (Finish again after).
    for (int b = 0; b < kBins; ++b) counts_[b] += other.counts_[b];
    total_ += other.total_;
  }
  // Log-probabilities: each bin's count smoothed with its brightness neighbours (weights 1, 2,
  // 1), with a floor of a fiftieth of an even share, normalised.
  void Finish() {
    std::array<double, kBins> smooth{};
    double sum = 0;
    for (int b = 0; b < kBins; ++b) {
      const int level = b / (kHues * kHues), hue = b % (kHues * kHues);
      double s = 2 * counts_[b], weight = 2;
      for (int d : {-1, 1}) {
        if (level + d < 0 || level + d >= kLevels) continue;
        s += counts_[(level + d) * kHues * kHues + hue];
        weight += 1;
      }
      smooth[b] = s / weight + 0.02 * total_ / kBins + 1e-6;
      sum += smooth[b];
    }
    for (int b = 0; b < kBins; ++b) log_[b] = std::log(smooth[b] / sum);
  }
  double Log(int bin) const { return log_[bin]; }
  bool empty() const { return total_ <= 0; }

 private:
  std::array<double, kBins> counts_{}, log_{};
  double total_ = 0;
};

// The mean colour of the 3 x 3 pixels around (u, v) of a CV_8UC3 image (fewer at its edges): a
// pixel's look with the noise of one pixel averaged, where a whole blurred image is not needed.
inline cv::Vec3b Mean3x3(const cv::Mat& colour, int u, int v) {
  cv::Vec3i sum(0, 0, 0);
  int n = 0;
  for (int y = std::max(0, v - 1); y <= std::min(colour.rows - 1, v + 1); ++y) {
    const cv::Vec3b* row = colour.ptr<cv::Vec3b>(y);
    for (int x = std::max(0, u - 1); x <= std::min(colour.cols - 1, u + 1); ++x) {
      sum += cv::Vec3i(row[x]);
      ++n;
    }
  }
  return cv::Vec3b(sum[0] / n, sum[1] / n, sum[2] / n);
}
// Mean3x3 of every pixel of `box` (within the image) at once, as a CV_8UC3 image of its size:
// the same values, in separable passes, for a step that looks at most pixels of a region.
cv::Mat MeanColour3x3(const cv::Mat& colour, cv::Rect box);

// A cut: leaf (255) against surround (0) over the blocks, and the looks it learned.
struct Cut {
  cv::Mat leaf;
  Look look_leaf, look_surround;
};

// Leaf (255) against surround (0) over the blocks, from `above` (AboveSurround), the blocks'
// look, and `seed` (blocks where the leaf is expected: its look is learned there first, with the
// blocks well off the surround). The surround's first look is learned from `surround` (blocks);
// only blocks of `allowed` (all, when empty) may be leaf.
Cut CutLeaf(const Blocks& blocks, const cv::Mat& above, const cv::Mat& seed,
            const cv::Mat& surround, const cv::Mat& allowed, const CutOptions& options);
// The blocks a first cut learns the surround's look from: those on it (within twice their
// noise) in the grid's outer tenth, and those on its border without a height.
cv::Mat OuterSurround(const Blocks& blocks, const cv::Mat& above);

// A support or a frame found inside `leaf` (blocks): when the blocks along its outline lie on
// one plane (most of them within the tolerance) that is not one of `planes`, that plane (a
// support's top, a frame's face), with the blocks on it in *ring. False when there is none, or
// when it is the lowest of `planes` (the table: a leaf lying flush on it). When it is another of
// them (a frame the surround's samples caught, fitted there from a few blocks and a little
// tilted, so that its far side reads as a thin leaf), its index in *known (-1 when new), and the
// plane fitted along the outline in *plane.
bool PlaneAlongOutline(const Blocks& blocks, const cv::Mat& leaf, const std::vector<Plane>& planes,
                       const SurroundOptions& options, Plane* plane, cv::Mat* ring, int* known);

// ---- RefineRim ----
// Labels (1 leaf, 2 surround) spread from their seeds, lowest `level` first (a watershed: two
// floods meet on the crest between them). `labels` holds the seeds on input; pixels whose level
// is negative are not flooded.
void Flood(const cv::Mat& level, cv::Mat* labels);
// A block mask (CutLeaf's, blocks of `block` pixels) at the view's `size` (the view's last
// partial row and column of blocks as their neighbours).
cv::Mat BlocksToPixels(const cv::Mat& blocks, int block, cv::Size size);
// The cut `full` (CutLeaf's, at full size: BlocksToPixels), its outline moved to the crest of the
// rims and edges within a block and options.band_px pixels of it.
// Seeds of the surround also where a pixel inside the cut lies on one of `planes` and looks like
// the surround (by the cut's looks) with the leaf well above it close by (options.well_*): the
// table between an open book's pages, narrower than the blocks resolve; and over the pixels
// without a height outside the cut that join the surround's seeds (a dark table's). No seed of
// the leaf on a full step of a rim or an edge: where the cut strays past the rim, the floods
// still meet on it.
cv::Mat RefineRim(const cv::Mat& full, const Cues& cues, const cv::Mat& points,
                  const std::vector<Plane>& planes, const Look& leaf, const Look& surround,
                  int block, const OutlineOptions& options);

// The leaf's rim pixels whose heights do not continue its surface (off a plane through the leaf
// two or more pixels inside, in an 11 x 11 window, by more than `off_mm` and what its slope gives
// over two pixels) taken out, twice over: the mixed pixels of a raised edge, half leaf and half
// what lies below, that the restored page would carry beyond the leaf's edge.
void TrimRim(const cv::Mat& z, double off_mm, cv::Mat* leaf);

// ---- FillHoles ----
// Fills the holes of `leaf` that show no other surface (heights on the leaf's surface around
// them, or, without heights, looking like the leaf), and returns how many it keeps.
// Whether a pixel shows the surround by both cues: its point within `plane_mm` of one of
// `planes`, and its colour (its 3 x 3 mean) at least `look` nats more like that plane's own look
// than the leaf's and within the range of the plane's brightness (2nd to 98th percentile). Each
// plane's look is learned, when made, from every fourth pixel of the view on it clear of
// `leaf_mask` (the leaf with its holes: not what is to be judged; a frame's face and the table in
// its window look apart); a pixel is judged when asked. `points`, `colour` and `leaf_mask` are the
// whole view's.
class SurroundLook {
 public:
  SurroundLook(const cv::Mat& points, const cv::Mat& colour, const cv::Mat& leaf_mask,
               const std::vector<Plane>& planes, const Look& leaf, double plane_mm, double look);
  bool Shows(int u, int v) const;  // View pixels.

 private:
  int OnPlane(const cv::Vec3f& p) const;  // The plane a point lies on, or -1.
  static int Level(const cv::Vec3b& c) { return (c[0] + 2 * c[1] + c[2]) / 4; }
  cv::Mat points_, colour_;
  std::vector<Plane> planes_;
  Look leaf_;
  double plane_mm_, look_;
  std::vector<Look> looks_;
  std::vector<std::pair<int, int>> range_;
};
// `surround` (if given): a hole whose heights lie on the leaf's surface is kept all the same when
// most of it shows the surround (a leaf flush with what it lies on: the heights cannot tell its
// holes, the look can); `offset` is where `z`'s pixel (0, 0) lies in the view.
int FillHoles(const cv::Mat& z, const cv::Mat& gray, const cv::Mat& threshold, double bright,
              cv::Mat* leaf, const SurroundLook* surround = nullptr,
              cv::Point offset = cv::Point(0, 0));

// ---- the outline's figures ----
// The leaf the camera saw but the scan did not measure beside its outline: pixels without a
// height, within `reach_px` of the leaf (city-block distance) and joined to it, four pixels or
// more from it (nearer, the rim's mixed pixels), that look like the leaf (by `leaf` and
// `surround`, the cut's looks, over the texture's 3 x 3 mean: at least `min_look` nats more like
// the leaf). A curled edge turned nearly edge-on to the projector, a
// slope facing away from it: seen, but no 3D point to restore it from. A projector's shadow on
// the table looks like the table and is not counted. Where the look cannot tell the two apart (a
// table of the paper's own shade), a pixel is counted when `sight` (if given) finds the table
// behind it in the projector's light: had it shown the table, it would have been measured.
// Returns the pixels counted.
class ProjectorSight;
int UnseenBeside(const cv::Mat& leaf, const cv::Mat& measured, const cv::Mat& colour,
                 const Look& leaf_look, const Look& surround_look, int reach_px, double min_look,
                 const ProjectorSight* sight = nullptr);
// The share of the leaf's outline (its outer two pixels) that is an edge standing off the
// surround seen edge-on by `camera`: where the edge stands `height_mm` or more above the plane of
// `planes` beneath it (world z where there are none), and the surface within `band_px` of it,
// 3 to `band_px` pixels inside the outline, is seen more than `deg` from face-on (the patch of
// it one pixel sees, from the point map's slopes across four pixels, over 1 / cos(deg) times a
// face-on pixel's at that distance). The camera sees such an edge as a sliver: a curl rolled
// past its line of sight hides what lies beneath the sliver, and the point map cannot tell.
double EdgeOnShare(const cv::Mat& leaf, const cv::Mat& points, const std::vector<Plane>& planes,
                   const CameraModel& camera, double height_mm, double deg, int band_px);
// Whether the projector lights the surround behind a camera pixel: the camera's ray through the
// pixel meets the first of the surround's planes at T, and the line from T to the projector's
// centre passes over every point measured beneath it (by `clear_mm` or more) until it stands
// above the highest point measured. A pixel without a height whose T is lit showed the camera
// something other than that table: beside a leaf, the leaf itself, seen edge-on or facing away
// from the projector. Not lit where a measured surface stands in the way (the leaf's shadow),
// nor where the line passes over pixels without a height nearer the leaf (nothing can be
// said), nor off the view.
class ProjectorSight {
 public:
  ProjectorSight(const Calibration& rig, const cv::Mat& points, const std::vector<Plane>& planes,
                 double clear_mm);
  // `apart`: each pixel's distance from the leaf (CV_8U, city-block) over a box at `offset` in
  // the view; the line passes over pixels without a height only farther from the leaf than
  // `pixel` (the band it lies in, outward: what shades a pixel beside the leaf stands towards it).
  bool Lit(cv::Point pixel, const cv::Mat& apart, cv::Point offset) const;

 private:
  const Calibration& rig_;
  const cv::Mat& points_;
  std::vector<Plane> planes_;
  double clear_mm_;
  double top_mm_ = 0;  // The highest point measured, world z.
};
// The leaf's rim pixels (CV_8U, 255) where its look and that of what lies beside it differ: the
// brighter fifth of the pixels 2 to band_px inside the outline and of those outside it, within
// band_px of the rim pixel, differ by `contrast` of the paper's brightness `bright` or more. Text
// or a checkerboard on both sides of an outline drawn through the page does not set it apart (a
// texture edge would); a leaf a shade lighter than its table does. Only the rim pixels in
// `judge` (CV_8U, the view's size) are judged, when it is given.
cv::Mat LookApart(const cv::Mat& leaf, const cv::Mat& gray, double bright, int band_px,
                  double contrast, const cv::Mat& judge = cv::Mat());
// Share of the leaf's rim pixels set apart from what is beside them: on a rim (a height step),
// beside pixels without a height, or by its look (LookApart).
double RimConfidence(const cv::Mat& leaf, const Cues& cues, int band_px, double contrast);
// Whether the leaf runs off the view: leaf pixels within `border` of the image edge.
bool TouchesBorder(const cv::Mat& leaf, int border);
// How many of the view's four sides the mask reaches (within `border` pixels).
int SidesTouched(const cv::Mat& mask, int border);
// Where the leaf's look runs on to the view's edge beyond its outline: the longest stretch of
// positions along one of the view's sides (rows of the left and right sides, columns of the
// top and bottom; a gap of one bridged) whose pixels within `border` of the edge look like the
// leaf (`min_look` nats more likely under the leaf's look than under that of what lies beside
// it elsewhere, both learned here by their 3 x 3 mean colour) and are joined to the leaf,
// 8-connected, through pixels more like the leaf than what lies beside it, all within `reach`
// of that edge. The outline stops short of an edge the leaf runs off where the projector does
// not reach it (nothing measured there), or where a flat leaf's look alone sets it apart and
// the view's outer ring taught the cut the leaf's look as the table's; the leaf's look runs on.
// Zero at once when the leaf comes nowhere near an edge.
int LookRunsOff(const cv::Mat& leaf, const cv::Mat& colour, int border, int reach, double min_look);

// ---- SplitAtGutter ----
// An open book's gutter: a straight valley down the leaf (through each row's lowest point in the
// middle three fifths of the leaf), from which the surface rises at least gutter_rise_mm within
// gutter_reach_mm on both sides, and sharply: gutter_crease_mm within gutter_width_mm (or is
// hidden in it). A trough (a cone, a roll, a ripple) rises gently from its lowest line. Splits
// the leaf into its left and right pages; false if there is no such valley. `signs` (if given):
// what says the valley is a book's gutter and not a creased leaf's fold.
struct GutterSigns {
  // The two sides are parted along most of the valley (a gap, or a band out of view, between
  // them): two sheets.
  bool parted = false;
  // Along most of the valley, both sides level off beyond the bend (from gutter_reach_mm to
  // twice that, they rise less than half what they rose within it): pages lying on a book block.
  // A loose creased leaf's halves rise straight on, or curl further up, as nothing holds them.
  bool bound = false;
};
bool SplitAtGutter(const cv::Mat& points, const cv::Mat& z, const cv::Mat& leaf,
                   const OutlineOptions& options, cv::Vec4f* line, cv::Mat* left, cv::Mat* right,
                   GutterSigns* signs = nullptr);

}  // namespace vellum::outline
