// The leaf as the live preview shows it (LeafInPreview): by its look alone, while it is placed.
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "core/common/depth.h"
#include "core/mesh/mesh.h"
#include "core/outline/outline.h"

namespace vellum {
namespace {

// Tone of a preview: 8-bit gray, median-smoothed so that ink (under half of any 5 x 5
// neighbourhood on a page of text) takes the paper's tone, and a region is its material's.
cv::Mat PaperTone(const cv::Mat& image) {
  cv::Mat tone;
  cv::medianBlur(EightBitGray(image), tone, 5);
  return tone;
}

// The bright regions of *bright (SegmentPage's: over 0.6 of the 98th percentile), each with its
// holes filled, covering at least `min_px`, largest first.
std::vector<cv::Mat> BrightRegions(const cv::Mat& tone, int min_px, cv::Mat* bright) {
  *bright = SegmentPage(tone, 0.6, /*largest_only=*/false);
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(bright->clone(), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  std::vector<cv::Mat> regions;
  for (size_t k = 0; k < contours.size(); ++k) {
    if (cv::contourArea(contours[k]) < min_px) continue;
    cv::Mat filled = cv::Mat::zeros(tone.size(), CV_8U);
    cv::drawContours(filled, contours, static_cast<int>(k), cv::Scalar(255), cv::FILLED);
    regions.push_back(filled);
  }
  std::sort(regions.begin(), regions.end(), [](const cv::Mat& a, const cv::Mat& b) {
    return cv::countNonZero(a) > cv::countNonZero(b);
  });
  return regions;
}

// Otsu's threshold of `tone` over the pixels of `mask`, and the two classes' mean tones.
int MaskedOtsu(const cv::Mat& tone, const cv::Mat& mask, double* dark, double* bright) {
  double hist[256] = {0};
  double n = 0, sum = 0;
  for (int v = 0; v < tone.rows; ++v) {
    const uint8_t* t = tone.ptr<uint8_t>(v);
    const uint8_t* m = mask.ptr<uint8_t>(v);
    for (int u = 0; u < tone.cols; ++u) {
      if (!m[u]) continue;
      ++hist[t[u]];
      ++n;
      sum += t[u];
    }
  }
  int best = 0;
  double best_between = -1, n0 = 0, sum0 = 0;
  *dark = *bright = n > 0 ? sum / n : 0;
  for (int t = 0; t < 255; ++t) {
    n0 += hist[t];
    sum0 += t * hist[t];
    const double n1 = n - n0;
    if (n0 == 0 || n1 == 0) continue;
    const double m0 = sum0 / n0, m1 = (sum - sum0) / n1;
    const double between = n0 * n1 * (m0 - m1) * (m0 - m1);
    if (between > best_between) {
      best_between = between;
      best = t;
      *dark = m0;
      *bright = m1;
    }
  }
  return best;
}

// How sharply the tone steps across a contour: the median over its points of the tone's change
// between the two pixels 2 px either side of it, across its normal.
double EdgeStep(const cv::Mat& tone, const std::vector<cv::Point>& contour) {
  const int n = static_cast<int>(contour.size());
  if (n < 8) return 0;
  const cv::Rect view(0, 0, tone.cols, tone.rows);
  std::vector<double> steps;
  steps.reserve(n);
  constexpr int kAlong = 3, kAcross = 2;
  for (int k = 0; k < n; ++k) {
    const cv::Point d = contour[(k + kAlong) % n] - contour[(k - kAlong + n) % n];
    const double len = std::hypot(d.x, d.y);
    if (len == 0) continue;
    const cv::Point2d normal(-d.y / len, d.x / len);
    const cv::Point a(cvRound(contour[k].x + kAcross * normal.x),
                      cvRound(contour[k].y + kAcross * normal.y));
    const cv::Point b(cvRound(contour[k].x - kAcross * normal.x),
                      cvRound(contour[k].y - kAcross * normal.y));
    if (!view.contains(a) || !view.contains(b)) continue;
    steps.push_back(std::abs(tone.at<uint8_t>(a) - tone.at<uint8_t>(b)));
  }
  if (steps.empty()) return 0;
  std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
  return steps[steps.size() / 2];
}

// Of a part's filled outline, what its own tone must cover. Ink and pictures are holes in a leaf's
// paper (not bright, they are never candidates): a checkerboard page's paper covers about half of
// its outline, a page of text and pictures 0.68 (the family's seed 17). A part mostly holes is
// not a sheet.
constexpr double kSolid = 0.4;
// A leaf's edge is a step of the two tones within a pixel or two (EdgeStep at least this share of
// the step between them); shading across a curl or a bulge changes as much over tens of pixels.
constexpr double kSharp = 0.25;
// Of an enclosed part's outline, how much may run along the region's rim: a leaf laid near the
// edge of its support runs along it for a stretch; what is not enclosed (the region's own band
// of another tone, a shaded half) shares half its outline or more.
constexpr double kAtRim = 0.2;

// The largest part of `tone` above (or at most) `t` among `candidates` that is solid, enclosed
// (at most kAtRim of its outline within `band` of `rim`), at least `min_px`, and edged by a step of
// at least kSharp of `step`.
cv::Mat SolidEnclosedPart(const cv::Mat& tone, const cv::Mat& candidates, int t, bool above,
                          double step, const cv::Mat& rim, int band, int min_px) {
  cv::Mat near_rim;  // Within `band` of the region's rim.
  cv::dilate(rim, near_rim,
             cv::getStructuringElement(cv::MORPH_RECT, {2 * band + 1, 2 * band + 1}));
  cv::Mat part = (above ? tone > t : tone <= t) & candidates;
  cv::morphologyEx(part, part, cv::MORPH_OPEN, cv::getStructuringElement(cv::MORPH_RECT, {3, 3}));
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(part.clone(), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  cv::Mat best;
  double best_px = 0;
  for (size_t k = 0; k < contours.size(); ++k) {
    const double area = cv::contourArea(contours[k]);
    if (area < min_px || area <= best_px) continue;
    cv::Mat filled = cv::Mat::zeros(tone.size(), CV_8U);
    cv::drawContours(filled, contours, static_cast<int>(k), cv::Scalar(255), cv::FILLED);
    if (cv::countNonZero(part & filled) < kSolid * cv::countNonZero(filled)) continue;
    if (EdgeStep(tone, contours[k]) < kSharp * step) continue;  // Shading, not an edge.
    int at_rim = 0;
    for (const cv::Point& p : contours[k]) at_rim += near_rim.at<uint8_t>(p) != 0;
    if (at_rim > kAtRim * contours[k].size()) continue;  // It shares the region's rim.
    best = filled;
    best_px = area;
  }
  return best;
}

// Within `region` (a bright region of `bright`, holes filled): a solid part of another bright tone
// that it encloses, at least `min_px`, set apart by at least `min_step` grey levels: the leaf,
// where the region is a support or a mount about as bright as the leaf around it, whichever is the
// brighter. Ink and pictures (not bright) are holes in the leaf, never the leaf; a part that is
// not solid (a checkerboard's squares joined at their corners) is on the leaf. The tones are split
// twice (Otsu's threshold, then again within the lighter class): a page's coloured pictures, a
// mount and the paper are three. Empty when there is no such part: the region is the leaf.
cv::Mat EnclosedLeaf(const cv::Mat& tone, const cv::Mat& bright, const cv::Mat& region, int min_px,
                     double min_step) {
  const int band = std::max(2, region.cols / 100);
  cv::Mat inner;
  cv::erode(region, inner,
            cv::getStructuringElement(cv::MORPH_ELLIPSE, {2 * band + 1, 2 * band + 1}));
  // The region's own rim inside the view (not along the view's edge, which a region may run off).
  cv::Mat rim = region & ~inner;
  rim(cv::Rect(0, 0, band, rim.rows)).setTo(0);
  rim(cv::Rect(rim.cols - band, 0, band, rim.rows)).setTo(0);
  rim(cv::Rect(0, 0, rim.cols, band)).setTo(0);
  rim(cv::Rect(0, rim.rows - band, rim.cols, band)).setTo(0);
  cv::Mat candidates = inner & bright;
  for (int level = 0; level < 2; ++level) {
    double dark = 0, light = 0;
    const int t = MaskedOtsu(tone, candidates, &dark, &light);
    if (light - dark < min_step) return cv::Mat();
    cv::Mat best;
    for (const bool above : {true, false}) {
      cv::Mat part = SolidEnclosedPart(tone, candidates, t, above, light - dark, rim, band, min_px);
      if (!part.empty() && (best.empty() || cv::countNonZero(part) > cv::countNonZero(best))) {
        best = part;
      }
    }
    if (!best.empty()) return best;
    candidates &= tone > t;
  }
  return cv::Mat();
}

}  // namespace

cv::Mat PreviewOf(const cv::Mat& image) {
  if (image.cols <= kPreviewWidth) return image;
  cv::Mat small;
  const double s = static_cast<double>(kPreviewWidth) / image.cols;
  cv::resize(image, small, cv::Size(), s, s, cv::INTER_AREA);
  return small;
}

Outline LeafInPreview(const cv::Mat& image, const OutlineOptions& options) {
  Outline out;
  out.method = "look";
  constexpr int kLeast = 32;  // Pixels each way: a preview smaller shows no leaf to place.
  if (image.cols < kLeast || image.rows < kLeast) {
    out.status = Status::Error("no leaf in view");
    return out;
  }
  const cv::Mat tone = PaperTone(image);
  const int view_px = static_cast<int>(tone.total());
  const int min_px = static_cast<int>(options.min_area * view_px);
  // What reaches three sides of the view, or two opposite ones, or covers most of it, is the table
  // or a support larger than the view: the leaf, if any, is another bright region (in its holes).
  // (A leaf across the whole view runs off it both ways: its scan fails on "leaf in view" alone.)
  // Within such a surround no part is taken for the leaf: along the view's edge it has no rim to
  // enclose one, and a table's own shades would pass for a leaf.
  cv::Mat leaf, bright;
  bool surround_alike = false;
  for (const cv::Mat& region : BrightRegions(tone, min_px, &bright)) {
    const int sides = ViewSidesReached(region, options.border_px);
    const int reached = ViewSideCount(sides);
    const bool across = (sides & (kViewLeft | kViewRight)) == (kViewLeft | kViewRight) ||
                        (sides & (kViewTop | kViewBottom)) == (kViewTop | kViewBottom);
    if (reached >= 3 || across || cv::countNonZero(region) > 0.9 * view_px) {
      surround_alike = true;
      continue;
    }
    leaf = region;
    break;
  }
  if (leaf.empty()) {
    out.status = Status::Error(surround_alike ? "leaf as bright as its surround"  // The scan tells.
                                              : "no leaf in view");
    return out;
  }
  // A region of two tones, a solid bright one enclosed by the other: a leaf on a support or a
  // mount of about its brightness, smaller than the view. The enclosed part is the leaf.
  const double min_step = 0.025 * 255;
  const cv::Mat enclosed = EnclosedLeaf(tone, bright, leaf, min_px, min_step);
  if (!enclosed.empty()) leaf = enclosed;
  out.mask = leaf;
  out.pages = {leaf};
  out.touches_border = ViewSidesReached(leaf, options.border_px) != 0;
  out.status = Status::Ok();
  return out;
}

}  // namespace vellum
