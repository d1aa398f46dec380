#include "core/outline/outline.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "core/common/depth.h"
#include "core/common/text.h"
#include "core/mesh/mesh.h"
#include "core/outline/steps.h"

namespace vellum {

namespace outline {

double Median(std::vector<float>* values) {
  if (values->empty()) return 0;
  std::nth_element(values->begin(), values->begin() + values->size() / 2, values->end());
  return (*values)[values->size() / 2];
}

}  // namespace outline

using outline::Median;

bool OutlineOptions::Check(std::string* why) const {
  if (!(step_mm > 0) || scale_px < 1 || scale_px > 16 || !(max_slope_deg > 0) ||
      !(edge_contrast > 0) || blocks_across < 16 || band_px < 0 ||
      !(min_area > 0 && min_area < 1) || !(max_view_share > 0 && max_view_share <= 1) ||
      border_px < 0 || !(gutter_rise_mm > 0) || !(gutter_reach_mm > 0) || !(gutter_width_mm > 0) ||
      !(gutter_crease_mm >= 0) || rim_look_px < 2 || rim_look_px > 64 || !(rim_look_contrast > 0)) {
    *why =
        "step_mm, max_slope_deg, edge_contrast, rim_look_contrast and the gutter's rise, reach and "
        "width must be > 0, scale_px in [1, 16], rim_look_px in [2, 64], blocks_across >= 16, "
        "band_px, border_px and gutter_crease_mm >= 0, "
        "min_area in (0, 1), max_view_share in (0, 1]";
    return false;
  }
  if (!(well_plane_mm > 0) || !(well_depth_mm > 0) || !(well_look >= 0) || !(trim_off_mm > 0) ||
      !(lies_on_mm >= 0) || !(lies_on_apart >= 0 && lies_on_apart <= 1) ||
      !(window_resting_share > 0 && window_resting_share <= 1) || !(raised_plane_mm > 0)) {
    *why =
        "well_plane_mm, well_depth_mm, trim_off_mm and raised_plane_mm must be > 0, well_look and "
        "lies_on_mm >= 0, lies_on_apart in [0, 1], window_resting_share in (0, 1]";
    return false;
  }
  if (gutter_apart_px < 1 || gutter_borrow_rows < 1 || !(gutter_meet_px >= 0)) {
    *why = "gutter_apart_px and gutter_borrow_rows must be >= 1, gutter_meet_px >= 0";
    return false;
  }
  if (!(off_view_reach_share > 0 && off_view_reach_share <= 0.5) ||
      !(off_view_share > 0 && off_view_share <= 1)) {
    *why = "off_view_reach_share must be in (0, 0.5], off_view_share in (0, 1]";
    return false;
  }
  if (unseen_reach_px < 1 || !(unseen_look >= 0) || !(unseen_clear_mm > 0) ||
      !(max_unseen_share >= 0 && max_unseen_share <= 1) ||
      !(max_lost_share >= 0 && max_lost_share <= 1) ||
      !(wider_support_share >= 0 && wider_support_share <= 1)) {
    *why =
        "unseen_reach_px must be >= 1, unseen_look >= 0, unseen_clear_mm > 0, max_unseen_share, "
        "max_lost_share and wider_support_share in [0, 1]";
    return false;
  }
  if (!(edge_on_height_mm >= 0) || !(edge_on_deg > 0 && edge_on_deg < 90) || edge_on_band_px < 4 ||
      !(max_edge_on_share >= 0 && max_edge_on_share <= 1)) {
    *why =
        "edge_on_height_mm must be >= 0, edge_on_deg in (0, 90), edge_on_band_px >= 4, "
        "max_edge_on_share in [0, 1]";
    return false;
  }
  return surround.Check(why) && cut.Check(why);
}

namespace {

// The seed: the hint, or the middle fifth of the view either way, in blocks.
cv::Mat SeedBlocks(const outline::Blocks& blocks, cv::Size view, const cv::Rect& hint) {
  cv::Rect seed = hint & cv::Rect(0, 0, view.width, view.height);
  if (seed.area() == 0) {
    seed = cv::Rect(view.width * 2 / 5, view.height * 2 / 5, view.width / 5, view.height / 5);
  }
  const int b = blocks.size;
  cv::Rect in_blocks(seed.x / b, seed.y / b, std::max(1, seed.width / b),
                     std::max(1, seed.height / b));
  in_blocks &= cv::Rect(0, 0, blocks.grid.width, blocks.grid.height);
  cv::Mat out(blocks.grid, CV_8U, cv::Scalar(0));
  out(in_blocks).setTo(255);
  return out;
}

// The parts of `mask` (8-connected) that cover much of `seed`: each at least a quarter of the
// best's cover and a tenth of the seed. Empty when none covers it.
cv::Mat AtSeed(const cv::Mat& mask, const cv::Mat& seed) {
  cv::Mat out(mask.size(), CV_8U, cv::Scalar(0));
  // Within the mask's bounding box: every part lies in it, and a seed outside it votes for none.
  const cv::Rect box = cv::boundingRect(mask);
  if (box.empty()) return out;
  cv::Mat labels;
  const int count = cv::connectedComponents(mask(box), labels, 8, CV_32S);
  std::vector<int> votes(count, 0);
  for (int v = 0; v < box.height; ++v) {
    const uint8_t* s = seed.ptr<uint8_t>(box.y + v) + box.x;
    const int* l = labels.ptr<int>(v);
    for (int u = 0; u < box.width; ++u) {
      if (s[u]) ++votes[l[u]];
    }
  }
  votes[0] = 0;
  const int most = *std::max_element(votes.begin(), votes.end());
  const int seed_area = cv::countNonZero(seed);
  if (most == 0) return out;
  std::vector<uint8_t> keep(count, 0);
  for (int l = 1; l < count; ++l) {
    keep[l] = votes[l] >= std::max(1, most / 4) && votes[l] * 10 >= seed_area;
  }
  for (int v = 0; v < box.height; ++v) {
    const int* l = labels.ptr<int>(v);
    uint8_t* o = out.ptr<uint8_t>(box.y + v) + box.x;
    for (int u = 0; u < box.width; ++u) o[u] = keep[l[u]] ? 255 : 0;
  }
  return out;
}

// The largest 8-connected part of `mask`.
cv::Mat Largest(const cv::Mat& mask) {
  cv::Mat labels, stats, centroids;
  const int count = cv::connectedComponentsWithStats(mask, labels, stats, centroids, 8, CV_32S);
  int best = 0;
  for (int l = 1; l < count; ++l) {
    if (!best || stats.at<int>(l, cv::CC_STAT_AREA) > stats.at<int>(best, cv::CC_STAT_AREA))
      best = l;
  }
  return best ? labels == best : cv::Mat(mask.size(), CV_8U, cv::Scalar(0));
}

// The largest 8-connected part of `found` (blocks) not touching the grid's border; a doubt in
// `out` when the next largest is at least half its size.
cv::Mat LargestWithin(const cv::Mat& found, Outline* out) {
  cv::Mat labels, stats, centroids;
  const int count = cv::connectedComponentsWithStats(found, labels, stats, centroids, 8, CV_32S);
  int best = 0, second = 0;
  auto area = [&](int l) { return l ? stats.at<int>(l, cv::CC_STAT_AREA) : 0; };
  for (int l = 1; l < count; ++l) {
    const cv::Rect box(stats.at<int>(l, cv::CC_STAT_LEFT), stats.at<int>(l, cv::CC_STAT_TOP),
                       stats.at<int>(l, cv::CC_STAT_WIDTH), stats.at<int>(l, cv::CC_STAT_HEIGHT));
    if (box.x == 0 || box.y == 0 || box.br().x == found.cols || box.br().y == found.rows) continue;
    if (area(l) > area(best)) {
      second = best;
      best = l;
    } else if (area(l) > area(second)) {
      second = l;
    }
  }
  if (best && 2 * area(second) >= area(best)) {
    out->doubts.push_back(
        {"leaf_ambiguous",
         "nothing lies at the centre of the view, and two objects of like size lie off it: the "
         "larger was taken for the leaf; check the outline in the report, or draw a leaf hint "
         "over the leaf in the viewer (or give --leaf-hint) and scan again"});
  }
  return best ? labels == best : cv::Mat(found.size(), CV_8U, cv::Scalar(0));
}

// The share of what lies just outside `found` (blocks) that is as high as `plane` (within
// `tolerance_mm`): of the measured blocks two and three blocks out (the one beside the outline
// mixes both sides). A leaf on a support wider than itself has the support's top beside it along
// much of its outline; a support or a box taken for the leaf has the table, far below, all round.
double ShareOutsideAtPlane(const outline::Blocks& blocks, const cv::Mat& found,
                           const outline::Plane& plane, double tolerance_mm) {
  cv::Mat near, far;
  cv::dilate(found, near, cv::Mat::ones(3, 3, CV_8U));
  cv::dilate(found, far, cv::Mat::ones(7, 7, CV_8U));
  const cv::Mat band = far & ~near;
  int measured = 0, level = 0;
  for (int by = 0; by < band.rows; ++by) {
    for (int bx = 0; bx < band.cols; ++bx) {
      const float z = blocks.z.at<float>(by, bx);
      if (!band.at<uint8_t>(by, bx) || std::isnan(z)) continue;
      ++measured;
      level += std::fabs(plane.At(blocks.x.at<float>(by, bx), blocks.y.at<float>(by, bx)) - z) <=
               tolerance_mm;
    }
  }
  return measured ? static_cast<double>(level) / measured : 0.0;
}

// The share of `cut`'s pixels more than `inset` pixels inside its outline (along rows and
// columns) that `leaf`, its holes filled, leaves out.
double LostInside(const cv::Mat& cut, const cv::Mat& leaf, int inset) {
  // Within the cut's box, framed by a pixel off it as the view's edge is; a square's inset
  // (erosion by a rectangle is separable: two passes of a running minimum).
  const cv::Rect box = cv::boundingRect(cut);
  if (box.empty()) return 0;
  cv::Mat deep;
  cv::erode(cut(box), deep, cv::Mat::ones(2 * inset + 1, 2 * inset + 1, CV_8U), cv::Point(-1, -1),
            1, cv::BORDER_CONSTANT, cv::Scalar(0));
  const int total = cv::countNonZero(deep);
  if (total == 0) return 0;
  return static_cast<double>(cv::countNonZero(deep & ~outline::Filled(leaf(box)))) / total;
}

// Whether `inner` (blocks) stands off what lies around it inside `outer` at its rim, as a leaf on
// a support does by its thickness: at half or more of its rim blocks that can be judged, the
// block one inside stands at least `least_mm` above the surface outside extrapolated to it (from
// the blocks two and three out, past the rim's mixed block and the one beside it), along a row
// or a column. A part of the leaf itself (a curl rising off its flat part) continues the
// surface outside it.
bool StandsOffAtRim(const outline::Blocks& blocks, const cv::Mat& outer, const cv::Mat& inner,
                    double least_mm) {
  const cv::Rect grid(0, 0, inner.cols, inner.rows);
  auto at = [&](cv::Point p, const cv::Mat& m) {
    return grid.contains(p) && m.at<uint8_t>(p) != 0;
  };
  auto z = [&](cv::Point p) { return blocks.z.at<float>(p); };
  int judged = 0, standing = 0;
  const cv::Point directions[4] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}};
  for (int by = 0; by < inner.rows; ++by) {
    for (int bx = 0; bx < inner.cols; ++bx) {
      const cv::Point b(bx, by);
      if (!at(b, inner)) continue;
      for (const cv::Point& d : directions) {
        const cv::Point in = b - d, o1 = b + 2 * d, o2 = b + 3 * d;
        if (at(b + d, inner) || !at(in, inner) || at(o1, inner) || at(o2, inner) ||
            !at(o1, outer) || !at(o2, outer)) {
          continue;
        }
        const float zi = z(in), z1 = z(o1), z2 = z(o2);
        if (std::isnan(zi) || std::isnan(z1) || std::isnan(z2)) continue;
        ++judged;
        standing += zi - (z1 + 3 * (z1 - z2)) >= least_mm;
        break;
      }
    }
  }
  return judged == 0 || 2 * standing >= judged;
}

// Whether `inner` (blocks), of at least `min_blocks` and at most 90% of `outer`, has its outline
// inside outer's (four fifths of it at least two blocks in) and set apart there
// (options.lies_on_apart of it by a rim, a texture edge or unmeasured blocks).
bool SetApartInside(const outline::Blocks& blocks, const cv::Mat& outer, const cv::Mat& inner,
                    int min_blocks, const OutlineOptions& options) {
  const int area = cv::countNonZero(inner);
  if (area < std::max(1, min_blocks) || area > 0.9 * cv::countNonZero(outer)) return false;
  cv::Mat eroded, deep, apart;
  cv::erode(outline::Filled(inner), eroded, cv::Mat(), cv::Point(-1, -1), 1, cv::BORDER_CONSTANT,
            cv::Scalar(0));
  const cv::Mat rim = inner & ~eroded;
  cv::erode(outline::Filled(outer), deep, cv::Mat::ones(5, 5, CV_8U), cv::Point(-1, -1), 1,
            cv::BORDER_CONSTANT, cv::Scalar(0));
  cv::dilate((blocks.rim > 0.5f) | (blocks.edge > 1.0f) | (blocks.valid < 0.5f), apart, cv::Mat());
  const int total = cv::countNonZero(rim);
  return total > 0 && cv::countNonZero(rim & deep) >= 0.8 * total &&
         cv::countNonZero(rim & apart) >= options.lies_on_apart * total;
}

// Whether `inner` (blocks) is a leaf lying on `outer` (a support or a frame around it, whose
// plane `above` is measured from): set apart inside it (SetApartInside), and standing off that
// plane (its median height off it at least options.lies_on_mm and three times the blocks'
// noise). A region of a flat leaf's own texture (its dark squares, a miniature) lies on the
// leaf's plane.
bool LiesOn(const outline::Blocks& blocks, const cv::Mat& outer, const cv::Mat& inner,
            const cv::Mat& above, int min_blocks, const OutlineOptions& options) {
  if (!SetApartInside(blocks, outer, inner, min_blocks, options)) return false;
  const int area = cv::countNonZero(inner);
  std::vector<float> off, noise;
  for (int by = 0; by < inner.rows; ++by) {
    for (int bx = 0; bx < inner.cols; ++bx) {
      const float d = above.at<float>(by, bx), n = blocks.noise.at<float>(by, bx);
      if (!inner.at<uint8_t>(by, bx) || std::isnan(d)) continue;
      off.push_back(std::fabs(d));
      if (!std::isnan(n)) noise.push_back(n);
    }
  }
  if (off.size() * 2 < static_cast<size_t>(area)) return false;  // Mostly unmeasured.
  const double least = std::max(options.lies_on_mm, 3 * outline::Median(&noise));
  return outline::Median(&off) >= least && StandsOffAtRim(blocks, outer, inner, least);
}

// Whether `inner` (blocks) is a leaf in a window of `outer` (a frame, or a support beside it):
// set apart inside it (SetApartInside) and lying below `plane`, outer's plane along its outline,
// on what shows through the window, along its own outline (the median height of its blocks
// within three of its outline under the plane by at least options.lies_on_mm and three times the
// blocks' noise: a paper frame stands 0.3 mm high), or resting on what shows through along
// options.window_resting_share of that rim (under the plane so, and within a leaf's thickness of
// the lowest of `planes`, the table). Judged at its rim, not over all of it: a creased or curled
// leaf in a window rises above the frame's face away from its edges, and a waved one along them
// where its crests meet the window's edge.
bool InWindow(const outline::Blocks& blocks, const cv::Mat& outer, const cv::Mat& inner,
              const outline::Plane& plane, const std::vector<outline::Plane>& planes,
              int min_blocks, const OutlineOptions& options) {
  if (!SetApartInside(blocks, outer, inner, min_blocks, options)) return false;
  cv::Mat deep;
  cv::erode(outline::Filled(inner), deep, cv::Mat::ones(7, 7, CV_8U), cv::Point(-1, -1), 1,
            cv::BORDER_CONSTANT, cv::Scalar(0));
  std::vector<float> below, noise;
  std::vector<double> above_ground;  // Each rim block's height above the lowest known plane.
  int measured = 0;
  for (int by = 0; by < inner.rows; ++by) {
    for (int bx = 0; bx < inner.cols; ++bx) {
      const float z = blocks.z.at<float>(by, bx), n = blocks.noise.at<float>(by, bx);
      if (!inner.at<uint8_t>(by, bx) || std::isnan(z)) continue;
      ++measured;
      if (!std::isnan(n)) noise.push_back(n);
      if (deep.at<uint8_t>(by, bx)) continue;
      const double x = blocks.x.at<float>(by, bx), y = blocks.y.at<float>(by, bx);
      below.push_back(static_cast<float>(plane.At(x, y) - z));
      double ground = plane.At(x, y);
      for (const outline::Plane& p : planes) ground = std::min(ground, p.At(x, y));
      above_ground.push_back(z - ground);
    }
  }
  if (measured * 2 < cv::countNonZero(inner) || below.empty()) {
    return false;  // Mostly unmeasured.
  }
  const double bar = std::max(options.lies_on_mm, 3 * outline::Median(&noise));
  // Its rim on what lies below the frame (the table), a leaf's thickness above it, along a share
  // of it: a waved or creased leaf's rim rises above the frame's face away from where it rests.
  int resting = 0;
  for (size_t k = 0; k < below.size(); ++k) {
    if (below[k] >= bar && above_ground[k] <= options.cut.thickness_mm) ++resting;
  }
  return outline::Median(&below) >= bar ||
         resting >= options.window_resting_share * static_cast<double>(below.size());
}

}  // namespace

bool LeafHintFits(const cv::Rect& hint, cv::Size view, double max_share, std::string* why) {
  const std::string name = "the leaf hint " + std::to_string(hint.x) + "," +
                           std::to_string(hint.y) + "," + std::to_string(hint.width) + "," +
                           std::to_string(hint.height) + " (x,y,width,height, camera pixels)";
  // The far edges in 64 bits: the numbers may be anyone's.
  if (hint.x < 0 || hint.y < 0 || hint.width <= 0 || hint.height <= 0 ||
      int64_t{hint.x} + hint.width > view.width || int64_t{hint.y} + hint.height > view.height) {
    *why = name + " is not a box inside the " + SizeText(view) + " camera's view";
    return false;
  }
  return LeafHintShareFits(static_cast<double>(hint.area()) / std::max(1, view.area()), max_share,
                           name, why);
}

bool LeafHintShareFits(double share, double max_share, const std::string& name, std::string* why) {
  if (share <= max_share) return true;
  *why = name + " covers " + Fixed(100 * share, 0) + "% of the camera's view, more than " +
         Fixed(100 * max_share, 0) + "%: a hint is a box inside the leaf, not around it (draw " +
         "it over the leaf alone)";
  return false;
}

namespace {

// What the cut found on the blocks (CutOnBlocks): the leaf's blocks with the cut's looks, the
// surround's planes (a support's or a frame's among them), and how high above the table lies a
// plane with nothing standing on it that was taken for the leaf (0: none).
struct BlockCut {
  std::vector<outline::Plane> planes;
  cv::Mat leaf;  // CV_8U over the blocks.
  outline::Cut found;
  double raised_mm = 0;
};

// The leaf on the blocks: the surround's planes, the cut seeded at the hint or the view's centre
// (cut again where the planes moved when fitted again), the largest part off the centre when
// nothing lies there (`min_blocks`: a leaf's least size), and the cut again inside a support or
// a frame found with the leaf. What makes it doubtful goes to `out`.
BlockCut CutOnBlocks(const outline::Blocks& blocks, cv::Size size, int min_blocks,
                     const OutlineOptions& options, Outline* out) {
  using namespace outline;
  std::vector<Plane> planes = FitSurround(blocks, options.surround);
  cv::Mat above = AboveSurround(blocks, planes);
  const cv::Mat seed = SeedBlocks(blocks, size, options.hint);
  Cut found = CutLeaf(blocks, above, seed, OuterSurround(blocks, above), cv::Mat(), options.cut);
  // The planes again over all the surround the cut left, and the leaf cut again against them
  // where they moved by more than the surround strays from its plane.
  if (RefitSurround(blocks, found.leaf, options.surround, &planes) > options.cut.plane_mm) {
    above = AboveSurround(blocks, planes);
    found = CutLeaf(blocks, above, seed, OuterSurround(blocks, above), cv::Mat(), options.cut);
  }
  cv::Mat cut = AtSeed(found.leaf, seed);
  if (cv::countNonZero(cut) < min_blocks && options.hint.empty()) {
    // Nothing at the view's centre: the leaf lies off it. The largest part found that does not
    // run off the view, flagged when another almost as large was found too.
    cut = LargestWithin(found.leaf, out);
  }
  // What was found may be a support or a frame with the leaf on it, or a frame with the leaf in
  // its window, on the table below it: cut again inside it, against the plane along its outline
  // (twice: a leaf in a frame on a support).
  double raised_mm = 0;  // What was found lies this high above the table, nothing standing on it.
  for (int level = 0; level < 2 && cv::countNonZero(cut) > 0; ++level) {
    Plane plane;
    cv::Mat ring;
    int known = -1;
    if (!PlaneAlongOutline(blocks, cut, planes, options.surround, &plane, &ring, &known)) {
      break;
    }
    std::vector<Plane> more = planes;
    if (known >= 0) {
      more[known] = plane;  // A frame or support known, fitted better along its own outline.
    } else {
      more.push_back(plane);
    }
    const cv::Mat above_more = AboveSurround(blocks, more);
    const cv::Mat within = outline::Filled(cut);  // The inner leaf may reach into cut's holes.
    Cut inner_cut = CutLeaf(blocks, above_more, seed, ring, within, options.cut);
    cv::Mat inner = AtSeed(inner_cut.leaf, seed);
    if (cv::countNonZero(inner) == 0) inner = Largest(inner_cut.leaf);
    const bool lies_on = LiesOn(blocks, cut, inner, above_more, min_blocks, options);
    const bool in_window =
        !lies_on && InWindow(blocks, cut, inner, plane, planes, min_blocks, options);
    if (in_window) {
      // What shows through the window beside the leaf is the table: cut again knowing its look
      // as well as the frame's.
      Cut again = CutLeaf(blocks, above_more, seed, ring | OuterSurround(blocks, above), within,
                          options.cut);
      cv::Mat inner_again = AtSeed(again.leaf, seed);
      if (cv::countNonZero(inner_again) == 0) inner_again = Largest(again.leaf);
      if (InWindow(blocks, cut, inner_again, plane, planes, min_blocks, options)) {
        inner_cut = again;
        inner = inner_again;
      }
    }
    if (!lies_on && !in_window) {
      // What was found lies on a plane well above the table, and nothing on it stands off it: a
      // support or a box, maybe, with the leaf flush on it or elsewhere. Unless enough of what
      // lies just outside it is as high: then it is a leaf on a support wider than itself.
      double lowest = 1e9;
      for (const Plane& known : planes) lowest = std::min(lowest, known.c);
      if (plane.c - lowest > options.raised_plane_mm &&
          ShareOutsideAtPlane(blocks, cut, plane, options.raised_plane_mm) <
              options.wider_support_share) {
        raised_mm = plane.c - lowest;
      }
      break;
    }
    cut = inner;
    planes = more;
    above = above_more;
    if (in_window) {
      // Beside a leaf in a window lies what shows through it (the table): its look with the
      // frame's.
      inner_cut.look_surround.Add(found.look_surround);
      inner_cut.look_surround.Finish();
    }
    found = inner_cut;
  }
  return {planes, cut, found, raised_mm};
}

// The leaf at the pixel (ToThePixel): the cut's blocks brought to the rim by the refinement, over
// the pixels with a height, its holes filled or kept (`holes`: those kept), the rim's mixed pixels
// trimmed. Empty when less than `area_min` pixels of it were measured (`measured`: the pixels with
// a height). `full_cut` gets the cut at the pixel.
cv::Mat ToThePixel(const BlockCut& c, const outline::Cues& cues, const cv::Mat& points,
                   const cv::Mat& measured, int block, double area_min,
                   const OutlineOptions& options, cv::Mat* full_cut, int* holes) {
  using namespace outline;
  // Brought to the pixel, over the pixels with a height: what the cut holds without one, where
  // that reaches its outline (a shadow, a side seen edge-on), is not restored.
  *full_cut = BlocksToPixels(c.leaf, block, points.size());
  cv::Mat region = RefineRim(*full_cut, cues, points, c.planes, c.found.look_leaf,
                             c.found.look_surround, block, options);
  region = AtSeed(region, *full_cut);
  cv::Mat leaf = AtSeed(region & measured, *full_cut);
  if (cv::countNonZero(leaf) < area_min) return cv::Mat();
  const cv::Rect holes_box = (cv::boundingRect(leaf) + cv::Size(4, 4) - cv::Point(2, 2)) &
                             cv::Rect(0, 0, points.cols, points.rows);
  cv::Mat box_leaf = leaf(holes_box);
  const cv::Mat cautious = StepThreshold(cues.gray(holes_box), cues.bright, options.step_mm,
                                         options.scale_px, /*darkest=*/true);
  // The surround's looks learned outside the leaf's outline: not from the holes to be judged.
  const SurroundLook surround(points, cues.colour, outline::Filled(leaf), c.planes,
                              c.found.look_leaf, options.well_plane_mm, options.well_look);
  *holes = FillHoles(cues.z(holes_box), cues.gray(holes_box), cautious, cues.bright, &box_leaf,
                     &surround, holes_box.tl());
  // The rim's mixed pixels out, once the holes are settled (their rims are the leaf's too).
  TrimRim(cues.z, options.trim_off_mm, &leaf);
  return leaf;
}

// The outline's figures and doubts (JudgeLeaf): how much of the leaf was measured and how much of
// its rim is set apart, what the outline at the pixel lost of the cut, the leaf unmeasured or seen
// edge-on beside its outline, and whether it runs off the view or is more likely the table or a
// support than a leaf.
void JudgeLeaf(const cv::Mat& leaf, const cv::Mat& full_cut, const outline::Cues& cues,
               const cv::Mat& points, const cv::Mat& measured, const BlockCut& c, int block,
               const OutlineOptions& options, const Calibration* rig, Outline* out) {
  using namespace outline;
  // Of the cut's pixels outside the leaf, those without a height may be leaf unmeasured; those
  // with one the refinement left out are the surround (a burnt edge's bays, a hole).
  out->measured_share = static_cast<double>(cv::countNonZero(leaf & measured)) /
                        std::max(1, cv::countNonZero(leaf | (full_cut & ~measured)));
  // The checks below read the leaf and share nothing: two sets of them side by side, about
  // equal in time (the look at the view's sides is the longest of them).
  double lost = 0;
  int unseen = 0;
  const int longer = std::max(leaf.cols, leaf.rows);
  auto at_the_sides = [&] {
    out->touches_border =
        TouchesBorder(leaf, options.border_px) ||
        LookRunsOff(leaf, cues.colour, options.border_px,
                    static_cast<int>(options.off_view_reach_share * longer),
                    options.unseen_look) >= std::max(3.0, options.off_view_share * longer);
    out->confidence = RimConfidence(leaf, cues, options.rim_look_px, options.rim_look_contrast);
  };
  auto around_the_rim = [&] {
    // What the cut found well inside its outline (beyond the block and band the refinement may
    // move it by) and the outline at the pixel left out, its holes aside: part of the leaf lost.
    lost = LostInside(full_cut, leaf, block + options.band_px);
    std::optional<ProjectorSight> sight;
    if (rig && !c.planes.empty()) sight.emplace(*rig, points, c.planes, options.unseen_clear_mm);
    unseen = UnseenBeside(leaf, measured, cues.colour, c.found.look_leaf, c.found.look_surround,
                          options.unseen_reach_px, options.unseen_look, sight ? &*sight : nullptr);
    if (rig) {
      out->edge_on_share =
          EdgeOnShare(leaf, points, c.planes, rig->camera, options.edge_on_height_mm,
                      options.edge_on_deg, options.edge_on_band_px);
    }
  };
  cv::parallel_for_(
      cv::Range(0, 2),
      [&](const cv::Range& sets) {
        for (int set = sets.start; set < sets.end; ++set) {
          if (set == 0) {
            at_the_sides();
          } else {
            around_the_rim();
          }
        }
      },
      2);
  if (lost > options.max_lost_share) {
    out->doubts.push_back(
        {"outline_uncertain",
         "the outline brought to the pixel leaves out " + Fixed(100 * lost, 0) +
             "% of the leaf the cut found well inside its outline: part of the leaf is not "
             "restored; check the outline in the report, or draw a leaf hint in the viewer "
             "(--leaf-hint) and scan again"});
  }
  const int leaf_px = std::max(1, cv::countNonZero(leaf));
  out->unseen_share = static_cast<double>(unseen) / leaf_px;
  if (out->unseen_share > options.max_unseen_share) {
    out->doubts.push_back(
        {"edge_unmeasured",
         "beside the outline, " + Fixed(100 * out->unseen_share, 1) +
             "% more of the leaf (by its look) has no 3D point: an edge curled up edge-on to the "
             "projector, or a slope facing away from it; it is left out of the restored page: "
             "lay that edge flatter or turn the leaf towards the projector and scan again"});
  }
  if (out->edge_on_share > options.max_edge_on_share) {
    out->doubts.push_back(
        {"edge_on",
         "along " + Fixed(100 * out->edge_on_share, 0) +
             "% of the outline the leaf's edge stands " + Fixed(options.edge_on_height_mm, 0) +
             " mm or more off what it lies on and the camera sees it nearly edge-on (over " +
             Fixed(options.edge_on_deg, 0) +
             " degrees from face-on): if that edge curls over, the camera sees only a sliver "
             "of it and the leaf beneath is missing from the restored page; lay that edge "
             "flatter, or turn it towards the camera, and scan again"});
  }
  // Plausibility: a leaf lies inside the view; what fills most of it, or reaches two or more of
  // its sides, is more likely the table or a support.
  const int sides = SidesTouched(leaf, options.border_px);
  const double view_share =
      static_cast<double>(cv::countNonZero(leaf)) / std::max(1, cv::countNonZero(measured));
  if (sides >= 2 || view_share > options.max_view_share) {
    out->doubts.push_back(
        {"outline_uncertain",
         "the leaf found covers " + Fixed(100 * view_share, 0) + "% of what was measured and " +
             "reaches " + std::to_string(sides) +
             " of the view's sides: more likely the table or a support than a leaf; check the "
             "outline in the report, or draw a leaf hint in the viewer (--leaf-hint) and scan "
             "again"});
  }
}

// The leaf's pages (SplitPages): a spread's two at its gutter, or the one leaf, with the doubts on
// what lies there: a valley that may be a crease as well as a gutter, a book said with no gutter
// found, a plane `raised_mm` above the table with nothing standing on it taken for the leaf.
void SplitPages(const cv::Mat& points, const outline::Cues& cues, const cv::Mat& leaf,
                double raised_mm, const OutlineOptions& options, Outline* out) {
  using namespace outline;
  // An open book: its two pages at the gutter. Split when the operator says it is a book, or,
  // on auto, when the two sides are parted along the valley (two sheets) or level off beyond
  // its bend (pages on a book block); any other valley is one creased leaf as well as a book's
  // two pages, and is flagged.
  cv::Mat left, right;
  GutterSigns signs;
  const bool valley =
      options.find_spread && options.object != ObjectKind::kLeaf &&
      SplitAtGutter(points, cues.z, leaf, options, &out->gutter, &left, &right, &signs);
  if (valley && (options.object == ObjectKind::kBook || signs.parted || signs.bound)) {
    out->pages = {left, right};
  } else {
    out->pages = {leaf};
    if (valley) {
      out->doubts.push_back(
          {"object_ambiguous",
           "a sharp valley runs down the leaf, its two sides meeting in it: one creased leaf, or "
           "an open book's two pages; restored as one leaf: say object: book (vellum scan "
           "--object book, or in the viewer) to restore two pages, or object: leaf"});
    } else if (options.find_spread && options.object == ObjectKind::kBook) {
      out->doubts.push_back(
          {"object_ambiguous",
           "said to be an open book, but no gutter was found between two pages (a valley both "
           "pages rise from): restored as one leaf; check the outline in the report"});
    }
  }
  // On a raised plane with nothing standing on it: a support or a box, perhaps, unless two pages
  // were found rising from a gutter on it (an open book's block, which a support does not have).
  if (raised_mm > 0 && out->pages.size() < 2) {
    out->doubts.push_back(
        {"leaf_ambiguous",
         "what was found as the leaf lies on a plane " + Fixed(raised_mm, 1) +
             " mm above the table with nothing standing on it: a support or a box, perhaps, "
             "with the leaf flush on it or beside it: check the outline in the report, draw "
             "a leaf hint over the leaf in the viewer (or give --leaf-hint) and scan again"});
  }
}

}  // namespace

Outline FindLeaf(const cv::Mat& points, const cv::Mat& texture, const OutlineOptions& options,
                 const Calibration* rig) {
  using namespace outline;
  Outline out;
  std::string why;
  if (!options.Check(&why)) {
    out.status = Status::Error("outline options: " + why);
    return out;
  }
  if (!options.hint.empty() &&
      !LeafHintFits(options.hint, points.size(), options.max_view_share, &why)) {
    out.status = Status::Error(why);
    return out;
  }
  if (points.type() != CV_32FC3 || points.empty()) {
    out.status = Status::Error("outline input: the point map must be CV_32FC3");
    return out;
  }
  if (texture.size() != points.size()) {
    out.status = Status::Error("the texture is " + SizeText(texture.size()) + ", the point map " +
                               SizeText(points.size()));
    return out;
  }
  const cv::Size size = points.size();
  const Cues cues = MeasureCues(points, texture, options);
  const int block = BlockSize(size, options.blocks_across);
  const Blocks blocks = MakeBlocks(cues, points, block);
  if (blocks.grid.width < 4 || blocks.grid.height < 4) {
    out.status = Status::Error("outline input: the view of " + SizeText(size) + " is too small");
    return out;
  }
  const double area_min = options.min_area * size.area();
  const int min_blocks = static_cast<int>(area_min / (block * block));
  const BlockCut cut = CutOnBlocks(blocks, size, min_blocks, options, &out);
  if (cv::countNonZero(cut.leaf) * block * block < area_min) {
    out.status = Status::Error(
        "no leaf found: nothing around the centre of the view stands off the table or support "
        "by its height or its look");
    return out;
  }
  cv::Mat full_cut;
  const cv::Mat measured = cues.z > -1e3f;
  const cv::Mat leaf =
      ToThePixel(cut, cues, points, measured, block, area_min, options, &full_cut, &out.holes);
  if (leaf.empty()) {
    out.status = Status::Error("no leaf found: too little of it was measured in 3D");
    return out;
  }
  JudgeLeaf(leaf, full_cut, cues, points, measured, cut, block, options, rig, &out);
  out.method = "cut";
  out.mask = leaf;
  SplitPages(points, cues, leaf, cut.raised_mm, options, &out);
  out.status = Status::Ok();
  return out;
}

cv::Mat DrawOutline(const cv::Mat& texture, const Outline& outline) {
  cv::Mat out = EightBitBgr(texture).clone();  // Drawn on: never the texture itself.
  const cv::Scalar colours[] = {cv::Scalar(0, 200, 255), cv::Scalar(255, 120, 0)};
  const int thickness = std::max(1, out.cols / 600);
  for (size_t k = 0; k < outline.pages.size(); ++k) {
    std::vector<std::vector<cv::Point>> contours;
    cv::findContours(outline.pages[k].clone(), contours, cv::RETR_LIST, cv::CHAIN_APPROX_SIMPLE);
    cv::drawContours(out, contours, -1, colours[k % 2], thickness, cv::LINE_AA);
  }
  return out;
}

RaisedHole HighestRaisedHole(const cv::Mat& points, const cv::Mat& leaf_mask, double min_rise_mm) {
  RaisedHole best;
  std::vector<std::vector<cv::Point>> contours;
  std::vector<cv::Vec4i> hierarchy;
  cv::findContours(leaf_mask.clone(), contours, hierarchy, cv::RETR_CCOMP, cv::CHAIN_APPROX_SIMPLE);
  const cv::Rect view(cv::Point(0, 0), leaf_mask.size());
  // The median height of the measured points of `where` (a mask of `box`); NaN when none.
  std::vector<float> z;
  auto median_height = [&](const cv::Mat& where, cv::Rect box) {
    z.clear();
    for (int v = 0; v < box.height; ++v) {
      const uint8_t* in = where.ptr<uint8_t>(v);
      const cv::Vec3f* p = points.ptr<cv::Vec3f>(box.y + v) + box.x;
      for (int u = 0; u < box.width; ++u) {
        if (in[u] && !std::isnan(p[u][2])) z.push_back(p[u][2]);
      }
    }
    return z.empty() ? std::numeric_limits<double>::quiet_NaN() : Median(&z);
  };
  for (size_t k = 0; k < contours.size(); ++k) {
    if (hierarchy[k][3] < 0) continue;  // An outer contour, not a hole.
    const int area = static_cast<int>(cv::contourArea(contours[k]));
    if (area <= best.area_px || area < 16) continue;
    // The hole and a ring of the leaf around it, a few pixels wide.
    const int ring = 6;
    const cv::Rect box =
        (cv::boundingRect(contours[k]) + cv::Size(2 * ring, 2 * ring) - cv::Point(ring, ring)) &
        view;
    cv::Mat hole = cv::Mat::zeros(box.size(), CV_8U);
    cv::drawContours(hole, contours, static_cast<int>(k), cv::Scalar(255), cv::FILLED, cv::LINE_8,
                     cv::noArray(), 0, -box.tl());
    hole &= ~leaf_mask(box);  // Islands of leaf inside the hole are not the hole.
    cv::Mat around;
    cv::dilate(hole, around, cv::Mat::ones(2 * ring + 1, 2 * ring + 1, CV_8U));
    around &= leaf_mask(box);
    const double rise = median_height(hole, box) - median_height(around, box);
    if (rise >= min_rise_mm) best = {area, rise, box};
  }
  return best;
}

}  // namespace vellum
