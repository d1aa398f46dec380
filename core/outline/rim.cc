// Flood, RefineRim and the outline's figures (steps.h).
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

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
      level[row + u] = !(x >= 0)          ? -1
                       : x >= kLevels - 1 ? kLevels - 1
                                          : static_cast<int16_t>(x);
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

namespace {
constexpr float kUnmeasuredLevel = 4;  // Rim-threshold units: a strong rim.
}  // namespace

cv::Mat RefineRim(const cv::Mat& cut, const Cues& cues, int block, int band) {
  const cv::Size size = cues.gray.size();
  // The cut at full size (the view's last partial row and column of blocks as their neighbours).
  cv::Mat full;
  cv::resize(cut, full, cut.size() * block, 0, 0, cv::INTER_NEAREST);
  cv::copyMakeBorder(full, full, 0, size.height - full.rows, 0, size.width - full.cols,
                     cv::BORDER_REPLICATE);
  // Seeds: what lies farther than a block and the band from the cut's outline, on either side,
  // and the middle of any part of the surround narrower than that (a hole, the gap between a
  // book's pages keeps a seed: the ridge of its distance from the outline, three pixels in at
  // least). A narrow part of the leaf gets none: the cut's errors are such parts (blocks of the
  // surround beside a raised edge, whose heights the edge's blur biases).
  const int reach = block + band;
  cv::Mat labels(size, CV_8U, cv::Scalar(0));
  cv::Mat distance, widest;
  cv::distanceTransform(full, distance, cv::DIST_L2, 3);
  labels.setTo(1, distance >= reach);
  cv::distanceTransform(~full, distance, cv::DIST_L2, 3);
  cv::dilate(distance, widest, cv::Mat());
  labels.setTo(2, (distance >= reach) | ((distance >= widest) & (distance >= 3)));
  // Flooded on the stronger of the rim and the texture's edge; a pixel without a height is a
  // crest of its own (the floods meet across a band without heights: a shadow beside a raised
  // edge, or the edge seen edge-on, does not carry the leaf onto what lies beyond it).
  cv::Mat level = cv::max(cues.rim, cues.edge);
  level.setTo(cv::Scalar(kUnmeasuredLevel), (cues.z < -1e3f) & (level < kUnmeasuredLevel));
  Flood(level, &labels);
  return labels == 1;
}

double RimConfidence(const cv::Mat& leaf, const Cues& cues) {
  cv::Mat eroded;
  cv::erode(leaf, eroded, cv::Mat());
  const cv::Mat rim = leaf & ~eroded;
  cv::Mat apart = (cues.rim > 0.5f) | (cues.edge > 1.0f);
  cv::dilate(apart, apart, cv::Mat(), cv::Point(-1, -1), 3);
  cv::Mat no_data = cues.z < -1e3f;
  cv::dilate(no_data, no_data, cv::Mat(), cv::Point(-1, -1), 2);
  const int total = cv::countNonZero(rim);
  if (total == 0) return 0;
  return static_cast<double>(cv::countNonZero(rim & (apart | no_data))) / total;
}

bool TouchesBorder(const cv::Mat& leaf, int border) { return SidesTouched(leaf, border) > 0; }

int SidesTouched(const cv::Mat& mask, int border) {
  const int b = std::max(1, border);
  if (mask.cols <= 2 * b || mask.rows <= 2 * b) return 4;
  const cv::Rect sides[4] = {cv::Rect(0, 0, b, mask.rows), cv::Rect(mask.cols - b, 0, b, mask.rows),
                             cv::Rect(0, 0, mask.cols, b), cv::Rect(0, mask.rows - b, mask.cols, b)};
  int touched = 0;
  for (const cv::Rect& side : sides) touched += cv::countNonZero(mask(side)) > 0;
  return touched;
}

}  // namespace vellum::outline
