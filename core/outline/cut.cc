// CutLeaf (steps.h): leaf against surround as one energy over every cue, minimised exactly by a
// graph cut (Boykov & Kolmogorov's max-flow, OpenCV's GCGraph, as GrabCut uses it; Rother et al.
// 2004 learn each side's look from the last cut in the same way).
#include <algorithm>
#include <array>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <opencv2/imgproc/detail/gcgraph.hpp>

#include "core/outline/steps.h"

namespace vellum {

bool CutOptions::Check(std::string* why) const {
  if (!(plane_mm > 0) || !(flush_share >= 0 && flush_share < 1) || !(thickness_mm > 0) ||
      !(max_off >= 0) || !(max_on >= 0) || !(look_weight >= 0) || !(max_look > 0) ||
      !(border_cost >= 0) || !(smooth >= 0) || !(smooth_floor >= 0 && smooth_floor <= 1) ||
      rounds < 0 || rounds > 10) {
    *why =
        "cut: plane_mm, thickness_mm and max_look must be > 0, flush_share in [0, 1), the costs "
        ">= 0, smooth_floor in [0, 1], rounds in [0, 10]";
    return false;
  }
  return true;
}

namespace outline {

cv::Mat OuterSurround(const Blocks& blocks, const cv::Mat& above) {
  const cv::Size g = blocks.grid;
  cv::Mat out(g, CV_8U, cv::Scalar(0));
  const int ring_x = std::max(1, g.width / 10), ring_y = std::max(1, g.height / 10);
  for (int by = 0; by < g.height; ++by) {
    for (int bx = 0; bx < g.width; ++bx) {
      const bool outer =
          bx < ring_x || by < ring_y || bx >= g.width - ring_x || by >= g.height - ring_y;
      const bool border = bx == 0 || by == 0 || bx == g.width - 1 || by == g.height - 1;
      const float d = above.at<float>(by, bx);
      float sigma = blocks.noise.at<float>(by, bx);
      if (std::isnan(sigma)) sigma = 0.05f;
      const bool on = std::fabs(d) <= std::max(2.0f * sigma, 0.01f);
      out.at<uint8_t>(by, bx) = (outer && on) || (border && std::isnan(d)) ? 255 : 0;
    }
  }
  return out;
}

namespace {

// The heights' costs, which do not change from round to round: (to call it leaf, to call it
// surround) per block, weighted by the share of it measured; `on`: a block that lies on the
// surround within twice its sigma; `bins`: each block's colour bin (Look::Bin).
struct HeightCosts {
  std::vector<float> leaf, surround;
  std::vector<uint8_t> on;
  std::vector<int> bins;
};
HeightCosts CostsOfHeight(const Blocks& blocks, const cv::Mat& above, const CutOptions& options) {
  const cv::Size g = blocks.grid;
  const int n = g.area();
  HeightCosts c;
  std::vector<float>& height_leaf = c.leaf;
  std::vector<float>& height_surround = c.surround;
  std::vector<uint8_t>& on = c.on;
  std::vector<int>& bins = c.bins;
  height_leaf.assign(n, 0);
  height_surround.assign(n, 0);
  on.assign(n, 0);
  bins.resize(n);
  const double spread = (1 - options.flush_share) * 0.5 / options.thickness_mm;  // Per mm.
  for (int by = 0; by < g.height; ++by) {
    for (int bx = 0; bx < g.width; ++bx) {
      const int i = by * g.width + bx;
      bins[i] = Look::Bin(blocks.colour.at<cv::Vec3b>(by, bx));
      const float d = above.at<float>(by, bx);
      if (std::isnan(d)) continue;
      float noise = blocks.noise.at<float>(by, bx);
      if (std::isnan(noise)) noise = 0.05f;
      const double sigma = std::hypot(noise, options.plane_mm), a = std::fabs(d);
      // log N(d; 0, sigma), and the leaf's density: flush, or spread over its thickness (half its
      // mass) and thinly over the next 100 mm (the other half).
      const double log_on =
          -0.5 * (a / sigma) * (a / sigma) - std::log(sigma * std::sqrt(2 * M_PI));
      const double leaf_spread =
          a <= options.thickness_mm ? spread : spread * options.thickness_mm / 100;
      const double log_leaf = std::log(options.flush_share * std::exp(log_on) + leaf_spread);
      const double ratio = std::clamp(log_leaf - log_on, -options.max_on, options.max_off) *
                           blocks.valid.at<float>(by, bx);
      (ratio > 0 ? height_surround : height_leaf)[i] = static_cast<float>(std::fabs(ratio));
      on[i] = a <= 2 * sigma;
    }
  }
  return c;
}

// The links between neighbouring blocks (to the right, and down): cheap across a rim or a
// texture edge.
void Links(const Blocks& blocks, const CutOptions& options, std::vector<float>* right_out,
           std::vector<float>* down_out) {
  const cv::Size g = blocks.grid;
  const int n = g.area();
  auto link = [&](int by, int bx, int cy, int cx) {
    const float e = std::max({blocks.rim.at<float>(by, bx), blocks.rim.at<float>(cy, cx),
                              blocks.edge.at<float>(by, bx), blocks.edge.at<float>(cy, cx)});
    return static_cast<float>(options.smooth *
                              (options.smooth_floor + (1 - options.smooth_floor) * std::exp(-e)));
  };
  std::vector<float>& right = *right_out;
  std::vector<float>& down = *down_out;
  right.assign(n, 0);
  down.assign(n, 0);
  for (int by = 0; by < g.height; ++by) {
    for (int bx = 0; bx < g.width; ++bx) {
      const int i = by * g.width + bx;
      if (bx + 1 < g.width) right[i] = link(by, bx, by, bx + 1);
      if (by + 1 < g.height) down[i] = link(by, bx, by + 1, bx);
    }
  }
}

// One graph cut of the blocks into leaf (255 in *leaf) and surround: each block's costs of
// height and, when both looks are known, of look, the view's border and the barred blocks
// kept off the leaf, and the links.
void CutOnce(const Blocks& blocks, const HeightCosts& costs, const Look& look_leaf,
             const Look& look_surround, const std::vector<uint8_t>& barred,
             const std::vector<float>& right, const std::vector<float>& down,
             const CutOptions& options, cv::Mat* leaf_out) {
  const cv::Size g = blocks.grid;
  const int n = g.area();
  const std::vector<float>& height_leaf = costs.leaf;
  const std::vector<float>& height_surround = costs.surround;
  const std::vector<int>& bins = costs.bins;
  cv::Mat& leaf = *leaf_out;
  const bool looks = !look_leaf.empty() && !look_surround.empty();
  cv::detail::GCGraph<float> graph(n, 2 * n);
  for (int by = 0; by < g.height; ++by) {
    for (int bx = 0; bx < g.width; ++bx) {
      const int i = by * g.width + bx;
      double to_leaf = height_leaf[i], to_surround = height_surround[i];
      if (looks) {
        const double ratio = std::clamp(look_leaf.Log(bins[i]) - look_surround.Log(bins[i]),
                                        -options.max_look, options.max_look);
        (ratio > 0 ? to_surround : to_leaf) += options.look_weight * std::fabs(ratio);
      }
      if (bx == 0 || by == 0 || bx == g.width - 1 || by == g.height - 1) {
        to_leaf += options.border_cost;
      }
      if (barred[i]) to_leaf = 1e6;
      graph.addVtx();
      // The source side is the leaf: a block left there pays its cost to call it leaf (the
      // link to the sink, cut), one moved to the sink its cost to call it surround.
      graph.addTermWeights(i, static_cast<float>(to_surround), static_cast<float>(to_leaf));
    }
  }
  for (int i = 0; i < n; ++i) {
    if (right[i] > 0) graph.addEdges(i, i + 1, right[i], right[i]);
    if (down[i] > 0) graph.addEdges(i, i + g.width, down[i], down[i]);
  }
  graph.maxFlow();
  for (int i = 0; i < n; ++i) {
    leaf.at<uint8_t>(i / g.width, i % g.width) = graph.inSourceSegment(i) ? 255 : 0;
  }
}

}  // namespace

Cut CutLeaf(const Blocks& blocks, const cv::Mat& above, const cv::Mat& seed,
            const cv::Mat& surround, const cv::Mat& allowed, const CutOptions& options) {
  const cv::Size g = blocks.grid;
  const int n = g.area();
  const HeightCosts costs = CostsOfHeight(blocks, above, options);
  const std::vector<int>& bins = costs.bins;
  const std::vector<uint8_t>& on = costs.on;
  std::vector<float> right, down;
  Links(blocks, options, &right, &down);
  // The first looks: the surround's from `surround`; the leaf's from the blocks well off the
  // surround and those of the seed that look unlike the surround (less likely under its look
  // than under an even one: the seed may hold some of the surround, and ink as dark as a dark
  // table teaches nothing).
  Cut cut;
  cv::Mat& leaf = cut.leaf;
  leaf = cv::Mat(g, CV_8U, cv::Scalar(0));
  Look& look_leaf = cut.look_leaf;
  Look& look_surround = cut.look_surround;
  std::vector<uint8_t> leafy(n, 0), surroundish(n, 0), barred(n, 0), strange(n, 0);
  for (int i = 0; i < n; ++i) {
    const int by = i / g.width, bx = i % g.width;
    barred[i] = !allowed.empty() && !allowed.at<uint8_t>(by, bx);
    surroundish[i] = !barred[i] && surround.at<uint8_t>(by, bx) != 0;
    if (surroundish[i]) look_surround.Add(bins[i], 1);
  }
  look_surround.Finish();
  // Unlike the surround: less likely under its look than all but a twentieth of its own samples
  // (a leaf reaching into the view's outer tenth puts some of its look there).
  auto unlike_surround = [&] {
    std::vector<double> typical;
    for (int i = 0; i < n; ++i) {
      if (surroundish[i]) typical.push_back(look_surround.Log(bins[i]));
    }
    double least = -1e300;
    if (!typical.empty()) {
      std::nth_element(typical.begin(), typical.begin() + typical.size() / 20, typical.end());
      least = typical[typical.size() / 20];
    }
    for (int i = 0; i < n; ++i) strange[i] = typical.empty() || look_surround.Log(bins[i]) < least;
  };
  unlike_surround();
  for (int i = 0; i < n; ++i) {
    const int by = i / g.width, bx = i % g.width;
    leafy[i] = !barred[i] && (costs.surround[i] >= 0.5 * options.max_off ||
                              (seed.at<uint8_t>(by, bx) && strange[i]));
    surroundish[i] = surroundish[i] && !leafy[i];
  }
  for (int round = 0; round <= options.rounds; ++round) {
    look_leaf = Look();
    look_surround = Look();
    for (int i = 0; i < n; ++i) {
      if (leafy[i]) look_leaf.Add(bins[i], 1);
      if (surroundish[i]) look_surround.Add(bins[i], 1);
    }
    look_leaf.Finish();
    look_surround.Finish();
    CutOnce(blocks, costs, look_leaf, look_surround, barred, right, down, options, &leaf);
    if (round == options.rounds) break;
    // The looks relearned from this cut: the surround's from what it left, the leaf's from what
    // it took but for what lies on the surround and looks like it (a support as bright as paper,
    // taken with the leaf, would teach the leaf's look the support's).
    unlike_surround();
    for (int i = 0; i < n; ++i) {
      const bool in = leaf.at<uint8_t>(i / g.width, i % g.width) != 0;
      leafy[i] = in && (!on[i] || strange[i]);
      surroundish[i] = !in && !barred[i];
    }
  }
  return cut;
}

}  // namespace outline
}  // namespace vellum
