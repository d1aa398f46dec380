// Flood, RefineRim and the outline's figures (steps.h).
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>
#include <type_traits>
#include <vector>

#include "core/outline/steps.h"

namespace vellum::outline {

void Flood(const cv::Mat& strength, cv::Mat* labels) {
  constexpr int kLevels = 256;
  const int w = strength.cols, h = strength.rows;
  // Each pixel's level (its strength in 1/32 of a unit, capped), or -1 where it is not flooded
  // (negative or NaN), and its label: flat, row-major and framed by a pixel not flooded, so a
  // neighbour is an offset and never out of bounds.
  const int stride = w + 2;
  std::vector<int16_t> level(static_cast<size_t>(stride) * (h + 2), -1);
  std::vector<uint8_t> label(level.size(), 0);
  for (int v = 0; v < h; ++v) {
    const float* s = strength.ptr<float>(v);
    const uint8_t* in = labels->ptr<uint8_t>(v);
    const size_t row = static_cast<size_t>(v + 1) * stride + 1;
    for (int u = 0; u < w; ++u) {
      const float x = s[u] * 32;
      level[row + u] = !(x >= 0) ? -1 : x >= kLevels - 1 ? kLevels - 1 : static_cast<int16_t>(x);
      label[row + u] = in[u];
    }
  }
  const int around[4] = {1, -1, stride, -stride};
  // A pixel is queued once: it is taken at the level of its first queueing (later ones come
  // from higher levels), so a pixel queued is marked as if it had no height.
  constexpr int16_t kQueued = -2;
  std::vector<std::vector<int>> buckets(kLevels);
  // The floods start from the seeds' edges: unlabelled pixels with a height beside a seed.
  for (int at = stride; at < stride * (h + 1); ++at) {
    if (label[at] != 0 || level[at] < 0) continue;
    if (label[at + 1] | label[at - 1] | label[at + stride] | label[at - stride]) {
      buckets[level[at]].push_back(at);
      level[at] = kQueued;
    }
  }
  for (int l = 0; l < kLevels; ++l) {
    for (size_t k = 0; k < buckets[l].size(); ++k) {
      const int at = buckets[l][k];
      if (label[at] != 0) continue;
      // The label of the flood that reached it: a labelled 4-neighbour.
      uint8_t from = 0;
      for (int d = 0; d < 4 && !from; ++d) from = label[at + around[d]];
      if (!from) continue;
      label[at] = from;
      for (int d = 0; d < 4; ++d) {
        const int next = at + around[d];
        if (label[next] != 0 || level[next] < 0) continue;
        buckets[std::max<int>(l, level[next])].push_back(next);
        level[next] = kQueued;
      }
    }
    std::vector<int>().swap(buckets[l]);
  }
  for (int v = 0; v < h; ++v) {
    std::copy_n(label.data() + static_cast<size_t>(v + 1) * stride + 1, w, labels->ptr<uint8_t>(v));
  }
}

cv::Mat BlocksToPixels(const cv::Mat& blocks, int block, cv::Size size) {
  cv::Mat full;
  cv::resize(blocks, full, blocks.size() * block, 0, 0, cv::INTER_NEAREST);
  cv::copyMakeBorder(full, full, 0, size.height - full.rows, 0, size.width - full.cols,
                     cv::BORDER_REPLICATE);
  return full;
}

namespace {

// The pixels of `open` that a path through `open` (4-connected) joins to `from`.
cv::Mat ReachedFrom(const cv::Mat& open, const cv::Mat& from) {
  cv::Mat parts;
  const int count = cv::connectedComponents(open | from, parts, 4, CV_32S);
  std::vector<uint8_t> reached(count, 0);
  for (int v = 0; v < parts.rows; ++v) {
    const uint8_t* f = from.ptr<uint8_t>(v);
    const int* p = parts.ptr<int>(v);
    for (int u = 0; u < parts.cols; ++u) reached[p[u]] |= f[u] != 0;
  }
  cv::Mat out(open.size(), CV_8U);
  for (int v = 0; v < parts.rows; ++v) {
    const uint8_t* o = open.ptr<uint8_t>(v);
    const int* p = parts.ptr<int>(v);
    uint8_t* r = out.ptr<uint8_t>(v);
    for (int u = 0; u < parts.cols; ++u) r[u] = o[u] && reached[p[u]] ? 255 : 0;
  }
  return out;
}

}  // namespace

cv::Mat RefineRim(const cv::Mat& full, const Cues& cues, const cv::Mat& points,
                  const std::vector<Plane>& planes, const Look& leaf, const Look& surround,
                  int block, const OutlineOptions& options) {
  const cv::Size size = cues.gray.size();
  // Seeds: what lies farther than a block and the band from the cut's outline, on either side,
  // and the middle of any part of the surround narrower than that (a hole, the gap between a
  // book's pages keeps a seed: the ridge of its distance from the outline, three pixels in at
  // least). A narrow part of the leaf gets none: the cut's errors are such parts (blocks of the
  // surround beside a raised edge, whose heights the edge's blur biases).
  const int reach = block + options.band_px;
  // Worked within the cut's box (and a margin, for exactly the same result as over the view):
  // beyond it, everything is surround farther than `reach` from the leaf.
  const cv::Rect view(0, 0, size.width, size.height);
  const cv::Rect box = cv::boundingRect(full);
  auto grown = [&](int by) { return (box - cv::Point(by, by) + cv::Size(2 * by, 2 * by)) & view; };
  const cv::Rect in_leaf = grown(1), near_leaf = grown(reach + 2);
  cv::Mat labels(size, CV_8U, cv::Scalar(2));
  labels(near_leaf).setTo(0);
  cv::Mat distance, widest;
  cv::distanceTransform(full(in_leaf), distance, cv::DIST_L2, 3);
  labels(in_leaf).setTo(1, distance >= reach);
  cv::distanceTransform(~full(near_leaf), distance, cv::DIST_L2, 3);
  cv::dilate(distance, widest, cv::Mat());
  labels(near_leaf).setTo(2, (distance >= reach) | ((distance >= widest) & (distance >= 3)));
  // And the surround seen in a well of the cut's leaf: a pixel on a surround plane that looks
  // like the surround, with the leaf well above it within four pixels (the table between an open
  // book's pages, narrower than the cut's blocks resolve; options.well_*).
  if (!planes.empty() && !leaf.empty() && !surround.empty()) {
    cv::Mat highest;  // Over the cut's box (a view of the heights: the dilation sees past it).
    cv::dilate(cues.z(box), highest, cv::Mat::ones(9, 9, CV_8U));
    const float depth = static_cast<float>(options.well_depth_mm);
    cv::parallel_for_(cv::Range(box.y, box.y + box.height), [&](const cv::Range& range) {
      for (int v = range.start; v < range.end; ++v) {
        const uint8_t* in = full.ptr<uint8_t>(v);
        const float* z = cues.z.ptr<float>(v);
        const float* high = highest.ptr<float>(v - box.y) - box.x;
        const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
        const cv::Vec3b* colour = cues.colour.ptr<cv::Vec3b>(v);
        uint8_t* label = labels.ptr<uint8_t>(v);
        for (int u = box.x; u < box.x + box.width; ++u) {
          if (!in[u] || !Valid(z[u]) || high[u] < z[u] + depth || !std::isfinite(p[u][0])) {
            continue;
          }
          double nearest = 1e9;
          for (const Plane& plane : planes) {
            nearest = std::min(nearest, std::fabs(z[u] - plane.At(p[u][0], p[u][1])));
          }
          const int bin = Look::Bin(colour[u]);
          if (nearest <= options.well_plane_mm &&
              surround.Log(bin) - leaf.Log(bin) > options.well_look) {
            label[u] = 2;
          }
        }
      }
    });
  }
  // Flooded on the rim and the texture's edge together (the edge, sharp, places the outline
  // within the rim's band, which the decoder's fit spreads over 7 pixels), over the pixels with a
  // height: a band without heights (a shadow beside a raised edge, the edge seen edge-on) stops
  // both floods, and never carries the leaf onto what lies beyond it.
  // Within near_leaf: its own border lies farther than `reach` from the cut, seeded as the
  // surround, as is all beyond it.
  cv::Mat level = cues.rim(near_leaf) + cues.edge(near_leaf);
  level.setTo(cv::Scalar(-1), cues.z(near_leaf) < -1e3f);
  cv::Mat near_labels = labels(near_leaf);
  // No leaf seed on a rim or an edge (a full step of either): the floods meet there. Where the
  // cut's outline strays past the leaf's rim by more than a block and the band (a stretch of
  // table beside a low rim, whose heights the rim's blur lifts), the seeds reach the rim itself,
  // and from it the leaf would flood the table before the surround arrives. Inside the leaf, its
  // texture's edges join it again from the seeds around them.
  near_labels.setTo(0, (near_labels == 1) & (level >= 1));
  // And the surround seeded over what has no height outside the cut, as far as it reaches from the
  // surround's seeds: a dark table gives heights only here and there, and an island of them beside
  // the leaf, which no flood but the leaf's would reach, would be taken across the leaf's edge.
  near_labels.setTo(2, ReachedFrom((level < 0) & ~full(near_leaf), near_labels == 2));
  Flood(level, &near_labels);
  return labels == 1;
}

void TrimRim(const cv::Mat& z, double off_mm, cv::Mat* leaf) {
  constexpr int kReach = 5;  // The window: 11 x 11 pixels (at a corner, 16 pixels inside).
  // Within the leaf's box: outside it, no rim and no inner pixel (the erosions of a view of the
  // mask see past it, so they are the view's own).
  const cv::Rect box = cv::boundingRect(*leaf);
  if (box.empty()) return;
  for (int pass = 0; pass < 2; ++pass) {
    cv::Mat eroded, inner;
    const cv::Mat in_box = (*leaf)(box);
    cv::erode(in_box, eroded, cv::Mat());
    cv::erode(in_box, inner, cv::Mat::ones(5, 5, CV_8U));
    const cv::Mat rim = in_box & ~eroded;
    std::vector<cv::Point> rim_pixels;
    cv::findNonZero(rim, rim_pixels);
    for (cv::Point& p : rim_pixels) p += box.tl();
    std::vector<uint8_t> drop(rim_pixels.size(), 0);
    cv::parallel_for_(cv::Range(0, static_cast<int>(rim_pixels.size())), [&](const cv::Range& r) {
      for (int k = r.start; k < r.end; ++k) {
        const cv::Point p = rim_pixels[k];
        const float zp = z.at<float>(p);
        if (!Valid(zp)) continue;
        // A plane z = a + b du + c dv through the leaf's pixels two or more inside the rim.
        cv::Matx33d ata = cv::Matx33d::zeros();
        cv::Vec3d atb(0, 0, 0);
        int n = 0;
        for (int dv = -kReach; dv <= kReach; ++dv) {
          const int v = p.y + dv;
          if (v < box.y || v >= box.y + box.height) continue;
          for (int du = -kReach; du <= kReach; ++du) {
            const int u = p.x + du;
            if (!box.contains(cv::Point(u, v)) || !inner.at<uint8_t>(v - box.y, u - box.x)) {
              continue;
            }
            const float zz = z.at<float>(v, u);
            if (!Valid(zz)) continue;
            const cv::Vec3d row(1, du, dv);
            ata += row * row.t();
            atb += row * static_cast<double>(zz);
            ++n;
          }
        }
        cv::Vec3d plane;
        if (n < 12 || !cv::solve(ata, atb, plane, cv::DECOMP_CHOLESKY)) continue;
        // Off it by more than `off_mm` and what its slope gives over two pixels.
        const double slope = std::hypot(plane[1], plane[2]);
        drop[k] = std::fabs(zp - plane[0]) > off_mm + 2 * slope;
      }
    });
    int dropped = 0;
    for (size_t k = 0; k < rim_pixels.size(); ++k) {
      if (drop[k]) leaf->at<uint8_t>(rim_pixels[k]) = 0, ++dropped;
    }
    if (dropped == 0) break;
  }
}

cv::Mat LookApart(const cv::Mat& leaf, const cv::Mat& gray, double bright, int band_px,
                  double contrast, const cv::Mat& judge) {
  cv::Mat apart = cv::Mat::zeros(leaf.size(), CV_8U);
  if (band_px < 1) return apart;
  const cv::Rect view(0, 0, leaf.cols, leaf.rows);
  const cv::Rect leaf_box = (cv::boundingRect(leaf) + cv::Size(2, 2) - cv::Point(1, 1)) & view;
  if (leaf_box.empty()) return apart;
  // The rim: the leaf's pixels beside one outside it, 8-connected (those to judge).
  cv::Mat eroded;
  cv::erode(leaf(leaf_box), eroded, cv::Mat());
  cv::Mat rim_px = leaf(leaf_box) & ~eroded;
  if (!judge.empty()) rim_px &= judge(leaf_box);
  std::vector<cv::Point> rim;
  cv::findNonZero(rim_px, rim);
  if (rim.empty()) return apart;
  // Worked within the judged pixels' box and a margin: a pixel within band_px of one lies within
  // band_px of the outline (city-block) only through pixels in it, so its distance is exact.
  const int reach = 2 * band_px + 2;
  const cv::Rect box = (cv::boundingRect(rim) + leaf_box.tl() + cv::Size(2 * reach, 2 * reach) -
                        cv::Point(reach, reach)) &
                       view;
  for (cv::Point& p : rim) p += leaf_box.tl() - box.tl();
  const cv::Mat in_leaf = leaf(box), in_gray = gray(box);
  // Distances from the outline, inside and out (city-block: one linear pass each).
  cv::Mat in_depth, out_depth;
  cv::distanceTransform(in_leaf, in_depth, cv::DIST_L1, 3, CV_8U);
  cv::distanceTransform(~in_leaf, out_depth, cv::DIST_L1, 3, CV_8U);
  // The bands: 2 to band_px pixels from the outline, clear of the pixels that mix both sides.
  auto band = [&](const cv::Mat& depth, int u, int v) {
    const int d = depth.at<uint8_t>(v, u);
    return d >= 2 && d <= band_px;
  };
  const float least = static_cast<float>(contrast * bright);
  cv::parallel_for_(cv::Range(0, static_cast<int>(rim.size())), [&](const cv::Range& range) {
    std::vector<uint8_t> inside, outside;
    for (int k = range.start; k < range.end; ++k) {
      const cv::Point p = rim[k];
      inside.clear();
      outside.clear();
      for (int v = std::max(0, p.y - band_px); v <= std::min(box.height - 1, p.y + band_px); ++v) {
        const uint8_t* g = in_gray.ptr<uint8_t>(v);
        for (int u = std::max(0, p.x - band_px); u <= std::min(box.width - 1, p.x + band_px); ++u) {
          if (band(in_depth, u, v)) inside.push_back(g[u]);
          if (band(out_depth, u, v)) outside.push_back(g[u]);
        }
      }
      if (inside.size() < 4 || outside.size() < 4) continue;
      // The brighter side of each: paper between lines of ink, or the table between its specks;
      // ink, text and a checkerboard's squares on both sides of an outline drawn through the
      // page leave it the same.
      auto upper = [](std::vector<uint8_t>& values) {
        auto at = values.begin() + (values.size() * 4) / 5;
        std::nth_element(values.begin(), at, values.end());
        return static_cast<float>(*at);
      };
      if (std::fabs(upper(inside) - upper(outside)) >= least) {
        apart.at<uint8_t>(p + box.tl()) = 255;
      }
    }
  });
  return apart;
}

double RimConfidence(const cv::Mat& leaf, const Cues& cues, int band_px, double contrast) {
  // Within the leaf's box and a margin (the dilations' reach): beyond it there is no rim.
  constexpr int kMargin = 4;
  const cv::Rect view(0, 0, leaf.cols, leaf.rows);
  const cv::Rect box =
      (cv::boundingRect(leaf) + cv::Size(2 * kMargin, 2 * kMargin) - cv::Point(kMargin, kMargin)) &
      view;
  if (box.empty()) return 0;
  cv::Mat eroded;
  cv::erode(leaf(box), eroded, cv::Mat());
  const cv::Mat rim = leaf(box) & ~eroded;
  const int total = cv::countNonZero(rim);
  if (total == 0) return 0;
  cv::Mat apart = cues.rim(box) > 0.5f;
  cv::dilate(apart, apart, cv::Mat(), cv::Point(-1, -1), 3);
  cv::Mat no_data = cues.z(box) < -1e3f;
  cv::dilate(no_data, no_data, cv::Mat(), cv::Point(-1, -1), 2);
  const cv::Mat found = rim & (apart | no_data);
  // The look judged only where neither the height nor missing data set the rim apart.
  cv::Mat judge = cv::Mat::zeros(leaf.size(), CV_8U);
  judge(box).setTo(255, rim & ~found);
  const cv::Mat looks = LookApart(leaf, cues.gray, cues.bright, band_px, contrast, judge);
  return static_cast<double>(cv::countNonZero(found) + cv::countNonZero(rim & looks(box))) / total;
}

bool TouchesBorder(const cv::Mat& leaf, int border) { return SidesTouched(leaf, border) > 0; }

int SidesTouched(const cv::Mat& mask, int border) {
  return ViewSideCount(ViewSidesReached(mask, border));
}

}  // namespace vellum::outline

namespace vellum {

int ViewSidesReached(const cv::Mat& mask, int border) {
  const int b = std::max(1, border);
  const int all = kViewLeft | kViewRight | kViewTop | kViewBottom;
  if (mask.cols <= 2 * b || mask.rows <= 2 * b) return all;
  // In ViewSide order: left, right, top, bottom.
  const cv::Rect sides[kViewSideCount] = {
      cv::Rect(0, 0, b, mask.rows), cv::Rect(mask.cols - b, 0, b, mask.rows),
      cv::Rect(0, 0, mask.cols, b), cv::Rect(0, mask.rows - b, mask.cols, b)};
  int reached = 0;
  for (int k = 0; k < kViewSideCount; ++k) {
    if (cv::countNonZero(mask(sides[k])) > 0) reached |= 1 << k;
  }
  return reached;
}

}  // namespace vellum

namespace vellum::outline {

cv::Mat MeanColour3x3(const cv::Mat& colour, cv::Rect box) {
  box &= cv::Rect(0, 0, colour.cols, colour.rows);
  cv::Mat mean(box.size(), CV_8UC3);
  if (box.empty()) return mean;
  // Columns box.x - 1 .. box.br().x, as far as the image has them; each its 3 rows' sums.
  const int x0 = std::max(0, box.x - 1), x1 = std::min(colour.cols, box.br().x + 1);
  const int span = 3 * (x1 - x0);
  std::vector<int> column(span);
  for (int v = 0; v < box.height; ++v) {
    const int y = box.y + v;
    const int y0 = std::max(0, y - 1), y1 = std::min(colour.rows - 1, y + 1);
    std::fill(column.begin(), column.end(), 0);
    for (int r = y0; r <= y1; ++r) {
      const uint8_t* in = colour.ptr<uint8_t>(r) + 3 * x0;
      for (int k = 0; k < span; ++k) column[k] += in[k];
    }
    const int rows = y1 - y0 + 1;
    uint8_t* out = mean.ptr<uint8_t>(v);
    // The image's first and last columns have fewer neighbours; all others three.
    auto edge = [&](int u) {
      const int x = box.x + u;
      const int left = std::max(0, x - 1), right = std::min(colour.cols - 1, x + 1);
      const int n = rows * (right - left + 1);
      const int* c = column.data() + 3 * (left - x0);
      for (int ch = 0; ch < 3; ++ch) {
        int sum = 0;
        for (int k = 0; k <= right - left; ++k) sum += c[3 * k + ch];
        out[3 * u + ch] = static_cast<uint8_t>(sum / n);
      }
    };
    const int first = box.x == 0 ? 1 : 0;
    const int last = box.br().x == colour.cols ? box.width - 1 : box.width;
    if (first > 0) edge(0);
    // Inner pixels: channel k of pixel u sums column entries 3 (u - 1) + k .. 3 (u + 1) + k.
    const int* c = column.data() + 3 * (box.x + first - 1 - x0);
    uint8_t* o = out + 3 * first;
    const int n = 3 * (last - first);
    // Divided by a constant, each case its own loop: 3 rows inside the image, 2 at its top or
    // bottom, 1 when it is a single row.
    auto inner = [&](auto divisor) {
      for (int k = 0; k < n; ++k) {
        o[k] = static_cast<uint8_t>((c[k] + c[k + 3] + c[k + 6]) / decltype(divisor)::value);
      }
    };
    if (rows == 3) {
      inner(std::integral_constant<int, 9>());
    } else if (rows == 2) {
      inner(std::integral_constant<int, 6>());
    } else {
      inner(std::integral_constant<int, 3>());
    }
    if (last < box.width) edge(box.width - 1);
  }
  return mean;
}

int LookRunsOff(const cv::Mat& leaf, const cv::Mat& colour, int border, int reach,
                double min_look) {
  const int b = std::max(1, border);
  reach = std::min({std::max(reach, b + 1), leaf.cols / 2, leaf.rows / 2});
  if (reach <= b) return 0;
  // Each side's strip, `reach` deep: left, right, top, bottom.
  const cv::Rect strips[4] = {
      cv::Rect(0, 0, reach, leaf.rows), cv::Rect(leaf.cols - reach, 0, reach, leaf.rows),
      cv::Rect(0, 0, leaf.cols, reach), cv::Rect(0, leaf.rows - reach, leaf.cols, reach)};
  bool near[4], any = false;
  for (int side = 0; side < 4; ++side) any |= near[side] = cv::countNonZero(leaf(strips[side])) > 0;
  if (!any) return 0;
  // The looks, from every other pixel: the leaf's from its own, what lies beside it from the
  // pixels 4 to `reach` from its outline (nearer, the camera's blur mixes the two), one per side
  // with that side's strip left out: what lies beside the leaf elsewhere (a table, a support, a
  // frame), not what it runs into at the side judged.
  // Over the leaf's box and `reach` around it (all that lies within reach of the leaf).
  const cv::Rect box =
      (cv::boundingRect(leaf) - cv::Point(reach, reach) + cv::Size(2 * reach, 2 * reach)) &
      cv::Rect(0, 0, leaf.cols, leaf.rows);
  cv::Mat apart;
  cv::distanceTransform(~leaf(box), apart, cv::DIST_L1, 3, CV_8U);
  // Every pixel's 3 x 3 mean colour, once, over all that is looked at: the box and the strips
  // of the sides the leaf comes near.
  cv::Rect looked = box;
  for (int side = 0; side < 4; ++side) {
    if (near[side]) looked |= strips[side];
  }
  const cv::Mat mean = MeanColour3x3(colour, looked);
  auto mean_at = [&](int u, int v) { return mean.at<cv::Vec3b>(v - looked.y, u - looked.x); };
  Look leaf_look;
  std::array<Look, 4> beside;
  for (int v = box.y + box.y % 2; v < box.y + box.height; v += 2) {  // Even rows and columns.
    const uint8_t* l = leaf.ptr<uint8_t>(v);
    const uint8_t* d = apart.ptr<uint8_t>(v - box.y) - box.x;
    for (int u = box.x + box.x % 2; u < box.x + box.width; u += 2) {
      if (l[u]) {
        leaf_look.Add(Look::Bin(mean_at(u, v)), 1);
        continue;
      }
      if (d[u] <= 3 || d[u] > reach) continue;
      const int bin = Look::Bin(mean_at(u, v));
      for (int side = 0; side < 4; ++side) {
        if (near[side] && !strips[side].contains(cv::Point(u, v))) beside[side].Add(bin, 1);
      }
    }
  }
  leaf_look.Finish();
  int longest = 0;
  for (int side = 0; side < 4; ++side) {
    if (!near[side]) continue;
    beside[side].Finish();
    if (leaf_look.empty() || beside[side].empty()) continue;
    // The leaf's look at the edge, and what may join it there: a pixel more like the leaf than
    // what lies beside it (paper between the lines of text; not a frame's grain, nor the mixed
    // pixels of a gap between the leaf and the edge).
    std::array<uint8_t, Look::kBins> leafish, besideish;
    for (int bin = 0; bin < Look::kBins; ++bin) {
      const double ratio = leaf_look.Log(bin) - beside[side].Log(bin);
      leafish[bin] = ratio >= min_look;
      besideish[bin] = ratio <= 0;
    }
    // Passable: the leaf, and what looks more like it; 2 in the edge band where the pixel looks
    // like the leaf.
    const cv::Rect strip = strips[side];
    const cv::Mat in_leaf = leaf(strip);
    cv::Mat pass(strip.size(), CV_8U, cv::Scalar(0));
    for (int v = 0; v < strip.height; ++v) {
      const uint8_t* l = in_leaf.ptr<uint8_t>(v);
      uint8_t* out = pass.ptr<uint8_t>(v);
      for (int u = 0; u < strip.width; ++u) {
        if (l[u]) {
          out[u] = 1;
          continue;
        }
        const int x = strip.x + u, y = strip.y + v;
        const int bin = Look::Bin(mean_at(x, y));
        if (besideish[bin]) continue;
        const bool at_edge = side == 0   ? x < b
                             : side == 1 ? x >= leaf.cols - b
                             : side == 2 ? y < b
                                         : y >= leaf.rows - b;
        out[u] = at_edge && leafish[bin] ? 2 : 1;
      }
    }
    cv::Mat labels;
    const int n = cv::connectedComponents(pass != 0, labels, 8, CV_32S);
    std::vector<uint8_t> joined(n, 0);
    for (int v = 0; v < strip.height; ++v) {
      const uint8_t* l = in_leaf.ptr<uint8_t>(v);
      const int* label = labels.ptr<int>(v);
      for (int u = 0; u < strip.width; ++u) {
        if (l[u]) joined[label[u]] = 1;
      }
    }
    // The positions along the edge with a joined pixel that looks like the leaf.
    const bool down = side < 2;  // The left and right sides run down the rows.
    std::vector<uint8_t> seen(down ? strip.height : strip.width, 0);
    for (int v = 0; v < strip.height; ++v) {
      const uint8_t* p = pass.ptr<uint8_t>(v);
      const int* label = labels.ptr<int>(v);
      for (int u = 0; u < strip.width; ++u) {
        if (p[u] == 2 && joined[label[u]]) seen[down ? v : u] = 1;
      }
    }
    // The longest stretch of them (a gap of a pixel bridged): a leaf runs off the view along
    // a stretch of the edge, where a frame's grain or the noise passes for paper here and there.
    int run = 0, gap = 0;
    for (const uint8_t at : seen) {
      if (at) {
        run += 1 + gap;
        gap = 0;
        longest = std::max(longest, run);
      } else if (++gap > 1) {
        run = gap = 0;
      }
    }
  }
  return longest;
}

ProjectorSight::ProjectorSight(const Calibration& rig, const cv::Mat& points,
                               const std::vector<Plane>& planes, double clear_mm)
    : rig_(rig), points_(points), planes_(planes), clear_mm_(clear_mm) {
  // The highest point measured, in one pass over the map (no copy of its heights).
  float top = -std::numeric_limits<float>::infinity();
  for (int v = 0; v < points.rows; ++v) {
    const cv::Vec3f* p = points.ptr<cv::Vec3f>(v);
    for (int u = 0; u < points.cols; ++u) {
      if (p[u][2] > top) top = p[u][2];  // NaN compares false: skipped.
    }
  }
  top_mm_ = std::isfinite(top) ? top : 0.0;
}

bool ProjectorSight::Lit(cv::Point pixel, const cv::Mat& apart, cv::Point offset) const {
  const cv::Vec3d eye = rig_.camera.Center();
  const cv::Vec3d ray = rig_.camera.RayDirection(pixel);
  // The first plane the ray meets: z = a x + b y + c along eye + t ray.
  double t = std::numeric_limits<double>::infinity();
  for (const Plane& plane : planes_) {
    const double den = ray[2] - plane.a * ray[0] - plane.b * ray[1];
    if (std::fabs(den) < 1e-9) continue;
    const double at = (plane.At(eye[0], eye[1]) - eye[2]) / den;
    if (at > 0) t = std::min(t, at);
  }
  if (!std::isfinite(t)) return false;
  const cv::Vec3d from = eye + t * ray;
  const cv::Vec3d to = rig_.projector.Center() - from;
  if (to[2] <= 0) return false;
  // Where the line stands above everything measured; from there on nothing shades it.
  const double s_top = std::min(1.0, (top_mm_ + clear_mm_ - from[2]) / to[2]);
  if (s_top <= 0) return true;
  const cv::Vec3d top = from + s_top * to;
  const cv::Point2d q0 = rig_.camera.Project(from), q1 = rig_.camera.Project(top);
  if (!std::isfinite(q0.x) || !std::isfinite(q1.x)) return false;
  // Walked in the image a pixel at a time; the line's point over each pixel found from the
  // pixel's share w of the way (perspective: s = w d0 / (w d0 + (1 - w) d1), d the depths).
  const cv::Vec3d axis(rig_.camera.rotation(2, 0), rig_.camera.rotation(2, 1),
                       rig_.camera.rotation(2, 2));
  const double d0 = (from - eye).dot(axis), d1 = (top - eye).dot(axis);
  const int steps = std::max(1, static_cast<int>(std::ceil(cv::norm(q1 - q0))));
  for (int k = 1; k <= steps; ++k) {
    const double w = static_cast<double>(k) / steps;
    const cv::Point q(cvRound(q0.x + w * (q1.x - q0.x)), cvRound(q0.y + w * (q1.y - q0.y)));
    if (q == pixel) continue;
    if (q.x < 0 || q.y < 0 || q.x >= points_.cols || q.y >= points_.rows) return false;
    const cv::Vec3f x = points_.at<cv::Vec3f>(q);
    if (!std::isfinite(x[2])) {
      // Over a pixel without a height farther from the leaf than the pixel judged (the rest of
      // the band, outward): the line leaves the leaf behind, and goes on. Nearer the leaf, what
      // stands there may shade it.
      const cv::Point b = q - offset;
      const bool in_box = b.x >= 0 && b.y >= 0 && b.x < apart.cols && b.y < apart.rows;
      if (in_box && apart.at<uint8_t>(b) <= apart.at<uint8_t>(pixel - offset)) return false;
      continue;
    }
    const double s = s_top * w * d0 / (w * d0 + (1 - w) * d1);
    if (from[2] + s * to[2] < x[2] + clear_mm_) return false;
  }
  return true;
}

int UnseenBeside(const cv::Mat& leaf, const cv::Mat& measured, const cv::Mat& colour,
                 const Look& leaf_look, const Look& surround_look, int reach_px, double min_look,
                 const ProjectorSight* sight) {
  if (leaf_look.empty() || surround_look.empty() || reach_px < 1) return 0;
  const cv::Rect view(0, 0, leaf.cols, leaf.rows);
  const cv::Rect box = (cv::boundingRect(leaf) + cv::Size(2 * reach_px, 2 * reach_px) -
                        cv::Point(reach_px, reach_px)) &
                       view;
  if (box.empty()) return 0;
  const cv::Mat in_leaf = leaf(box);
  // Each pixel's distance from the leaf (city-block, in 8 bits: one linear pass).
  cv::Mat apart;
  cv::distanceTransform(~in_leaf, apart, cv::DIST_L1, 3, CV_8U);
  const cv::Mat in_view = colour(box), heights = measured(box);
  // The candidates joined to the leaf: from those within two pixels of it (its rim was trimmed of
  // mixed pixels), through the pixels without a height within reach, 8-connected. Counted four
  // pixels or more from it: nearer, a pixel mixes the leaf's rim with what lies beside it (the
  // camera's blur), and looks like neither.
  auto candidate = [&](int u, int v) {
    return apart.at<uint8_t>(v, u) > 0 && apart.at<uint8_t>(v, u) <= reach_px &&
           !heights.at<uint8_t>(v, u);
  };
  cv::Mat seen(box.size(), CV_8U, cv::Scalar(0));
  std::vector<cv::Point> queue;
  for (int v = 0; v < box.height; ++v) {
    const uint8_t* d = apart.ptr<uint8_t>(v);
    for (int u = 0; u < box.width; ++u) {
      if (d[u] > 0 && d[u] <= 2 && candidate(u, v)) {
        seen.at<uint8_t>(v, u) = 1;
        queue.emplace_back(u, v);
      }
    }
  }
  // The look's evidence by colour bin, once.
  std::array<uint8_t, Look::kBins> leafish, tableish;
  for (int b = 0; b < Look::kBins; ++b) {
    leafish[b] = leaf_look.Log(b) - surround_look.Log(b) >= min_look;
    tableish[b] = surround_look.Log(b) - leaf_look.Log(b) >= min_look;
  }
  int unseen = 0;
  while (!queue.empty()) {
    const cv::Point p = queue.back();
    queue.pop_back();
    if (apart.at<uint8_t>(p) > 3) {
      const int bin = Look::Bin(Mean3x3(in_view, p.x, p.y));
      unseen +=
          leafish[bin] || (sight && !tableish[bin] && sight->Lit(p + box.tl(), apart, box.tl()));
    }
    for (int dv = -1; dv <= 1; ++dv) {
      for (int du = -1; du <= 1; ++du) {
        const int u = p.x + du, v = p.y + dv;
        if (u < 0 || v < 0 || u >= box.width || v >= box.height || seen.at<uint8_t>(v, u) ||
            !candidate(u, v)) {
          continue;
        }
        seen.at<uint8_t>(v, u) = 1;
        queue.emplace_back(u, v);
      }
    }
  }
  return unseen;
}

double EdgeOnShare(const cv::Mat& leaf, const cv::Mat& points, const std::vector<Plane>& planes,
                   const CameraModel& camera, double height_mm, double deg, int band_px) {
  constexpr int kReach = 2;  // The slopes across 2 x kReach pixels.
  const cv::Rect box = (cv::boundingRect(leaf) + cv::Size(2, 2) - cv::Point(1, 1)) &
                       cv::Rect(0, 0, leaf.cols, leaf.rows);
  if (box.empty()) return 0;
  const cv::Mat in_leaf = leaf(box) > 0;
  cv::Mat inner, deep;
  cv::erode(in_leaf, inner, cv::Mat::ones(2 * kReach + 1, 2 * kReach + 1, CV_8U));
  cv::erode(in_leaf, deep, cv::Mat::ones(2 * band_px + 1, 2 * band_px + 1, CV_8U));
  const cv::Mat band = inner & ~deep;
  const cv::Vec3d centre = camera.Center();
  const double face_on = camera.matrix(0, 0) * camera.matrix(1, 1);
  const double steepest = 1 / std::cos(deg * CV_PI / 180);
  auto point = [&](int u, int v, cv::Vec3d* p) {
    if (u < 0 || v < 0 || u >= box.width || v >= box.height || !in_leaf.at<uint8_t>(v, u)) {
      return false;
    }
    const cv::Vec3f x = points.at<cv::Vec3f>(v + box.y, u + box.x);
    if (!std::isfinite(x[0]) || !std::isfinite(x[1]) || !std::isfinite(x[2])) return false;
    *p = cv::Vec3d(x[0], x[1], x[2]);
    return true;
  };
  // The band's pixels seen edge-on.
  cv::Mat edge_on(box.size(), CV_8U, cv::Scalar(0));
  for (int v = 0; v < box.height; ++v) {
    for (int u = 0; u < box.width; ++u) {
      if (!band.at<uint8_t>(v, u)) continue;
      cv::Vec3d p, l, r, t, b;
      if (!point(u, v, &p) || !point(u - kReach, v, &l) || !point(u + kReach, v, &r) ||
          !point(u, v - kReach, &t) || !point(u, v + kReach, &b)) {
        continue;
      }
      const double patch = cv::norm(((r - l) / (2 * kReach)).cross((b - t) / (2 * kReach)));
      const double d = cv::norm(p - centre);
      edge_on.at<uint8_t>(v, u) = patch * face_on > steepest * d * d ? 255 : 0;
    }
  }
  cv::dilate(edge_on, edge_on, cv::Mat::ones(2 * band_px + 1, 2 * band_px + 1, CV_8U));
  // The outline's pixels: of those, the edges standing off the surround beside such a surface.
  int outline = 0, counted = 0;
  for (int v = 0; v < box.height; ++v) {
    for (int u = 0; u < box.width; ++u) {
      if (!in_leaf.at<uint8_t>(v, u) || inner.at<uint8_t>(v, u)) continue;
      ++outline;
      cv::Vec3d p;
      if (!edge_on.at<uint8_t>(v, u) || !point(u, v, &p)) continue;
      // The plane beneath: the highest at or below the edge, else the lowest.
      double beneath = -std::numeric_limits<double>::infinity(), lowest = 0;
      for (size_t k = 0; k < planes.size(); ++k) {
        const double z = planes[k].At(p[0], p[1]);
        if (z <= p[2] && z > beneath) beneath = z;
        if (k == 0 || z < lowest) lowest = z;
      }
      if (!std::isfinite(beneath)) beneath = planes.empty() ? 0.0 : lowest;
      counted += p[2] - beneath >= height_mm;
    }
  }
  return outline ? static_cast<double>(counted) / outline : 0.0;
}

}  // namespace vellum::outline
