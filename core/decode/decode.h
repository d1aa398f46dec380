// Per-camera-pixel decoding of a structured-light scan into projector coordinates.
//
// Gray code gives each pixel an integer projector column/row; the phase-shifted sinusoids give
// the sub-pixel position within one period, and the Gray code picks the period (so a Gray-code
// bit error at a stripe boundary moves the Gray value by one pixel and changes nothing). A
// noise-aware local linear fit (weights = signal power, robust to depth steps) then estimates
// each pixel's coordinate from its neighbourhood, so dark ink borrows from nearby paper.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/patterns/patterns.h"

namespace vellum {

struct DecodeOptions {
  bool use_phase = true;           // Use the phase patterns when present (false: Gray code only).
  double min_contrast_dn = 5.0;    // Minimum white - black difference, camera DN.
  double min_modulation_dn = 2.5;  // Minimum sinusoid amplitude, camera DN.
  double uncertain_bit_dn = 3.0;   // A Gray bit with |pattern - inverse| below this is uncertain.
  double max_unwrap_error = 0.3;   // Max |Gray - phase| disagreement, fraction of the period.
  int saturation_dn = 255;         // A white frame value >= this is clipped (256: never).
  double noise_dn = 1.5;           // Camera noise standard deviation, DN (sets fit weights).
  int smooth_radius_px = 3;        // Local fit window radius, camera pixels, 0..8; 0 = no fit.
  int smooth_passes = 2;           // Robust (Tukey) reweighting passes of the local fit.
  double outlier_sigmas = 4.685;   // Tukey cut-off, in units of a pixel's expected noise.
  // The local fit's bias where the surface curves (a plane over the window rounds a crease)
  // removed by fitting its residual once more (twicing), where that correction exceeds this
  // many times its own expected noise. With the phase patterns only (a Gray code's staircase is
  // no curve).
  bool correct_curvature = true;
  double curvature_sigmas = 2.0;
  // A Gray frame pair disagreeing (FramePairCheck) at more of its lit pixels than this is looked
  // into: where one frame of the two is told as the one that does not fit, the bit is decoded
  // from the other alone (a sound pair disagrees at 0.02% of its lit pixels on the virtual
  // gantry; a frame of another leaf at 8%, of another pattern at half). 1: never.
  double suspect_pair_share = 0.05;

  bool Check(std::string* why) const;
};

// How far a Gray bit's frame and its inverse's agree: the two together light every pixel once,
// as the white frame does, so light being additive, pattern + inverse = white + black at every
// pixel, whatever the stripe's blur or the light scattered. A frame of another scan or leaf, a
// pattern shown in another's place, or one taken before the projector changed breaks that at many
// pixels.
//
// Which frame of a pair that disagrees is wrong, where the scan's redundancy tells: at the
// pixels where they disagree, a frame of another leaf lies off the two levels this scan's light
// allows (unlit, lit) where the right frame lies on them; a frame taken before the projector
// changed shows its pair's pattern (the two alike), and it is the later one shown. A frame of
// another pattern lies on the levels like the right one: that pair is named, not mended, as is
// one of the finest bits, whose frames gave the light every bit is judged by.
struct FramePairCheck {
  int axis = 0;      // 0 columns, 1 rows.
  int bit = 0;       // Gray bit (0 finest).
  int pattern = -1;  // Frame indices.
  int inverse = -1;
  int64_t lit = 0;       // Pixels lit enough to judge (direct light >= min_contrast_dn).
  int64_t disagree = 0;  // Of those, where pattern + inverse is off white + black.
  // Looked into when the pair disagreed at more than DecodeOptions::suspect_pair_share:
  int64_t off_pattern = 0;  // Of the disagreeing pixels, where the pattern's frame lies off
  int64_t off_inverse = 0;  // both levels of the scan's light; where the inverse's does;
  int64_t alike = 0;        // where the two frames show the same value.
  int left_out = -1;        // The frame the bit was decoded without (-1: decoded from both),
  bool shows_pair = false;  // as it shows its pair's pattern (else: it lies off the light).
  double Share() const { return lit > 0 ? static_cast<double>(disagree) / lit : 0.0; }
};

struct DecodeStats {
  int pixels = 0;               // Camera pixels decoded.
  int lit = 0;                  // Pixels with enough white/black contrast (projector reaches them).
  int valid = 0;                // Pixels with a projector coordinate.
  int rejected_saturated = 0;   // Pixels with a clipped white frame.
  int rejected_bits = 0;        // Lit pixels with two or more uncertain coarse Gray bits.
  int rejected_modulation = 0;  // Lit pixels whose sinusoid amplitude is too low.
  int rejected_unwrap = 0;      // Lit pixels whose Gray code and phase disagree.
  int fit_fallbacks = 0;        // Pixels where the local fit was inconsistent (depth step).
  // The Gray code's stripe, projector pixels: 1, or 2^k for a code without its k finest bits.
  // With the Gray code alone it is the decode's step; phase patterns interpolate within it.
  int gray_stripe_px = 1;
  // Where the Gray code alone sets the coordinates (no phase patterns), they step by the stripe:
  // this is that step, projector pixels (0 with phase patterns).
  int step_px = 0;
  std::vector<FramePairCheck> pairs;  // Each inverse-paired Gray bit's agreement.
};

struct DecodeResult {
  Status status = Status::Error("decode not run");
  cv::Mat projector_x;       // CV_32F projector column (pixel centres at integers), NaN if invalid.
  cv::Mat projector_y;       // CV_32F projector row, NaN if invalid or rows not encoded.
  cv::Mat valid;             // CV_8U, 255 where the pixel decoded.
  cv::Mat amplitude;         // CV_32F (white - black) / 2, camera DN.
  bool has_columns = false;  // The sequence encoded projector columns.
  bool has_rows = false;     // The sequence encoded projector rows.
  DecodeStats stats;
};

// Decodes scans and keeps its scratch buffers between calls (a daemon decodes many scans; fresh
// 8 MB buffers per call would cost more in page faults than the arithmetic).
//
// A scan is decoded whole (Decode) or frame by frame as a camera gives them or a reader reads
// them (Begin, Add each frame once in any order, Finish). Each frame is taken up as soon as
// what it depends on is in: a phase frame at once, a Gray bit once its inverse (or the white
// frame) and the light estimate's high-frequency frames are; then it is let go. Memory is the
// camera's pixels times a fixed count (the sums, the white and black frames, the light
// estimate's few frames), not times the frame count, when the sequence shows its finest Gray
// bits first (MakePatternSequence does); any order decodes, holding what it must.
class Decoder {
 public:
  explicit Decoder(const DecodeOptions& options = DecodeOptions());
  ~Decoder();
  Decoder(const Decoder&) = delete;
  Decoder& operator=(const Decoder&) = delete;

  const DecodeOptions& options() const { return options_; }
  // frames[k] is the camera image (CV_8U, one channel) taken while sequence.patterns[k] was
  // shown. Writes *result, reusing its images when they already have the right size and type.
  void Decode(const PatternSequence& sequence, const std::vector<cv::Mat>& frames,
              DecodeResult* result);

  // Starts a scan, forgetting any unfinished one.
  Status Begin(const PatternSequence& sequence, cv::Size camera_size);
  // Frame `index` of the sequence (CV_8U, one channel, the camera's size). A frame is kept by
  // reference until it is taken up (do not write into it meanwhile); one that does not own its
  // pixels is copied. An error (no such index, a frame twice, a wrong size) names the frame and
  // ends the scan: Finish reports it.
  Status Add(int index, const cv::Mat& frame);
  // Decodes what the frames gave; an error names the first frame that never came.
  void Finish(DecodeResult* result);
  int Received() const;           // Frames added since Begin.
  size_t HeldFrameBytes() const;  // Bytes of frames held now, waiting to be taken up.

 private:
  struct Stream;
  Status Store(int index, const cv::Mat& frame);  // Checks and keeps a frame.
  void Digest();  // Takes up every frame whose inputs are in, in one pass over the rows.
  // Finds which frame of a disagreeing pair does not fit the scan's light and, where one is
  // told, classifies the bit again without it (check->left_out). Before the frames are let go.
  void Mend(FramePairCheck* check, int16_t margin, int16_t min_direct, int16_t floor_dn);
  // The pair check's tolerance at the dimmest pixels for this scan (Stream::pair_floor_dn), from
  // the finest pairs held with the white and black frames.
  int16_t PairFloor(int16_t min_direct) const;
  // Finish's steps: the final pass over the rows (coordinates, weights, counts into *stats),
  // the local fit of the coordinates (returns the pixels that kept their raw decode), and the
  // curvature the fit leaves put back.
  void Coordinates(DecodeResult* result, DecodeStats* stats);
  int Smooth(std::vector<cv::Mat>* raw);
  void CorrectCurvature(const std::vector<cv::Mat>& raw);

  DecodeOptions options_;
  std::unique_ptr<Stream> stream_;
  cv::Mat weight_, sigma_,
      robust_weight_;         // Per-pixel fit weight, expected noise (px), IRLS weight.
  std::vector<cv::Mat> fit_;  // Fitted coordinates per encoded axis.
  std::vector<cv::Mat> residual_, correction_;  // What the fit left, and its fit (twicing).
};

// One-shot convenience: a fresh Decoder and result.
DecodeResult Decode(const PatternSequence& sequence, const std::vector<cv::Mat>& frames,
                    const DecodeOptions& options = DecodeOptions());

// Weighted local linear fit (value ~ a + b du + c dv over a (2r+1)^2 window) of one or two
// value planes with shared weights; writes the fitted value at each pixel with weight > 0.
// Pixels whose window is degenerate get the weighted mean. Exposed for tests and benchmarks.
void LocalLinearFit(const std::vector<cv::Mat>& values, const cv::Mat& weights, int radius,
                    std::vector<cv::Mat>* fitted);

// atan2 to about 1e-7 rad, vectorisable; exposed for its test.
float FastAtan2(float y, float x);

}  // namespace vellum
