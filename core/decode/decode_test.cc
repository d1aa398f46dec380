#include "core/decode/decode.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "core/decode/frame_check.h"

namespace vellum {
namespace {

// The projector's own images seen by a camera of the same size: frame k = pattern k exactly.
std::vector<cv::Mat> IdealFrames(const PatternSequence& seq) {
  std::vector<cv::Mat> frames;
  for (const PatternSpec& s : seq.patterns) frames.push_back(RenderPattern(s, seq.projector_size));
  return frames;
}

TEST(FastAtan2, MatchesStdAtan2) {
  double worst = 0;
  for (int i = 0; i < 3600; ++i) {
    const double a = i * 2 * M_PI / 3600;
    for (double r : {1e-3, 1.0, 250.0}) {
      const float y = static_cast<float>(r * std::sin(a)), x = static_cast<float>(r * std::cos(a));
      worst =
          std::max(worst, std::fabs(double(FastAtan2(y, x)) - std::atan2(double(y), double(x))));
    }
  }
  // float rounding of pi/2 - r and pi - r dominates: a few ulp of pi.
  EXPECT_LT(worst, 1e-6);
}

TEST(LocalLinearFit, ReproducesALinearFieldUnderAnyWeights) {
  cv::Mat values(60, 80, CV_32F), values2(60, 80, CV_32F), weights(60, 80, CV_32F);
  cv::RNG rng(3);
  for (int v = 0; v < 60; ++v) {
    for (int u = 0; u < 80; ++u) {
      values.at<float>(v, u) = 300.0f + 0.66f * u - 0.2f * v;
      values2.at<float>(v, u) = 100.0f - 0.05f * u + 0.9f * v;
      // Ink/paper-like weights with holes: the fit must stay unbiased (a weighted mean would not).
      const double r = rng.uniform(0.0, 1.0);
      weights.at<float>(v, u) = r < 0.2 ? 0.0f : (r < 0.6 ? 0.006f : 0.7f);
    }
  }
  std::vector<cv::Mat> fitted;
  LocalLinearFit({values, values2}, weights, 3, &fitted);
  for (int v = 0; v < 60; ++v) {
    for (int u = 0; u < 80; ++u) {
      if (weights.at<float>(v, u) == 0) {
        EXPECT_TRUE(std::isnan(fitted[0].at<float>(v, u)));
        continue;
      }
      ASSERT_NEAR(fitted[0].at<float>(v, u), values.at<float>(v, u), 2e-3) << u << "," << v;
      ASSERT_NEAR(fitted[1].at<float>(v, u), values2.at<float>(v, u), 2e-3) << u << "," << v;
    }
  }
}

// Non-power-of-two projectors decode to the exact column and row.
TEST(Decode, IdealFramesDecodeExactlyForOddProjectorSizes) {
  for (cv::Size size : {cv::Size(854, 480), cv::Size(1280, 800)}) {
    PatternOptions o;
    o.projector_size = size;
    const PatternSequence seq = MakePatternSequence(o);
    const std::vector<cv::Mat> frames = IdealFrames(seq);
    for (bool phase : {false, true}) {
      DecodeOptions d;
      d.use_phase = phase;
      d.smooth_radius_px = 0;
      d.saturation_dn = 256;  // The projector's own images reach 255 without clipping.
      const DecodeResult r = Decode(seq, frames, d);
      ASSERT_TRUE(r.status.ok()) << r.status.message();
      EXPECT_EQ(r.stats.valid, size.area());
      double worst = 0;
      for (int y = 0; y < size.height; ++y) {
        for (int x = 0; x < size.width; ++x) {
          worst = std::max(worst, std::fabs(double(r.projector_x.at<float>(y, x)) - x));
          worst = std::max(worst, std::fabs(double(r.projector_y.at<float>(y, x)) - y));
        }
      }
      // Gray code alone is exact at pixel centres. The phase carries the 8-bit rounding of the
      // sinusoid (+-0.5 DN on a 127.5 DN amplitude: ~1e-3 rad, 0.01 px at most at P = 16).
      EXPECT_LT(worst, phase ? 0.02 : 1e-6) << size << " phase=" << phase;
    }
  }
}

// A Gray bit read wrongly at its stripe boundary moves the Gray value by one column; the phase
// must absorb it (no one-period jump), and Gray code alone must stay within one pixel.
TEST(Decode, BoundaryBitErrorsLeaveNoPeriodJumps) {
  PatternOptions o;
  o.projector_size = {512, 16};
  const PatternSequence seq = MakePatternSequence(o);
  std::vector<cv::Mat> frames = IdealFrames(seq);
  int flipped = 0;
  for (int bit = 0; bit < seq.GrayBits(Axis::kColumn); ++bit) {
    cv::Mat& on = frames[seq.Find(PatternKind::kGray, Axis::kColumn, bit, false)];
    cv::Mat& off = frames[seq.Find(PatternKind::kGray, Axis::kColumn, bit, true)];
    for (int c = 0; c + 1 < on.cols; ++c) {
      if (on.at<uint8_t>(0, c) != on.at<uint8_t>(0, c + 1)) {  // Column c is at a boundary.
        on.col(c).setTo(on.at<uint8_t>(0, c + 1));
        off.col(c).setTo(off.at<uint8_t>(0, c + 1));
        ++flipped;
      }
    }
  }
  ASSERT_GT(flipped, 500);
  for (bool phase : {true, false}) {
    DecodeOptions d;
    d.use_phase = phase;
    d.smooth_radius_px = 0;
    d.saturation_dn = 256;
    const DecodeResult r = Decode(seq, frames, d);
    ASSERT_TRUE(r.status.ok());
    for (int x = 0; x < 512; ++x) {
      const float got = r.projector_x.at<float>(8, x);
      ASSERT_FALSE(std::isnan(got));
      EXPECT_LT(std::fabs(got - x), phase ? 0.02 : 1.0 + 1e-6) << "column " << x;
    }
  }
}

TEST(Decode, ShadowAndDarkPixelsAreInvalid) {
  const PatternSequence seq = MakePatternSequence(PatternOptions{{64, 32}});
  std::vector<cv::Mat> frames = IdealFrames(seq);
  // A projector shadow: only ambient light, every frame the same value.
  for (cv::Mat& f : frames) f(cv::Rect(10, 10, 5, 5)).setTo(20);
  DecodeOptions d;
  d.saturation_dn = 256;
  DecodeResult r = Decode(seq, frames, d);
  ASSERT_TRUE(r.status.ok());
  EXPECT_EQ(cv::countNonZero(r.valid(cv::Rect(10, 10, 5, 5))), 0);
  EXPECT_EQ(r.stats.valid, 64 * 32 - 25);
  // A clipped white frame (255 with the default saturation level) is rejected, not trusted.
  r = Decode(seq, frames);
  EXPECT_EQ(r.stats.valid, 0);
  EXPECT_EQ(r.stats.rejected_saturated, 64 * 32 - 25);
}

// Interreflections: where global light outweighs direct light and changes with the coarse
// patterns (a lit neighbour bouncing light in), comparing a pattern with its inverse reads the
// bit wrongly. The direct/global rule must reject those pixels rather than decode garbage.
TEST(Decode, StrongGlobalLightIsRejectedNotMisread) {
  const PatternSequence seq = MakePatternSequence(PatternOptions{{64, 32}});
  const cv::Rect region(10, 8, 20, 12);
  std::vector<cv::Mat> frames;
  for (const PatternSpec& spec : seq.patterns) {
    const cv::Mat pattern = RenderPattern(spec, seq.projector_size);
    cv::Mat frame(pattern.size(), CV_8U);
    for (int y = 0; y < frame.rows; ++y) {
      for (int x = 0; x < frame.cols; ++x) {
        const double f = pattern.at<uint8_t>(y, x) / 255.0;
        double v = 10 + 120 * f;  // Black level 10 DN, direct light 120 DN.
        if (region.contains({x, y})) {
          // Direct light 30 DN; global light 30 DN under fine patterns (half the scene lit),
          // 60 DN under white, and under coarse Gray bits more light when the pixel is dark.
          const bool coarse = spec.kind == PatternKind::kGray && spec.bit >= 3;
          if (spec.kind == PatternKind::kBlack) {
            v = 10;
          } else if (spec.kind == PatternKind::kWhite) {
            v = 10 + 30 + 60;
          } else if (coarse) {
            v = 10 + (f > 0.5 ? 40 : 50);
          } else {
            v = 10 + 30 * f + 30;
          }
        }
        frame.at<uint8_t>(y, x) = cv::saturate_cast<uint8_t>(v);
      }
    }
    frames.push_back(frame);
  }
  DecodeOptions d;
  d.smooth_radius_px = 0;
  const DecodeResult r = Decode(seq, frames, d);
  ASSERT_TRUE(r.status.ok());
  for (int y = 0; y < 32; ++y) {
    for (int x = 0; x < 64; ++x) {
      if (region.contains({x, y})) {
        EXPECT_EQ(r.valid.at<uint8_t>(y, x), 0) << "misread at " << x << "," << y;
      } else {
        ASSERT_EQ(r.valid.at<uint8_t>(y, x), 255) << x << "," << y;
        EXPECT_NEAR(r.projector_x.at<float>(y, x), x, 0.05);
      }
    }
  }
  EXPECT_EQ(r.stats.rejected_bits, region.area());
}

// The sequence's ideal frames as a camera gives them: gain and black level, and Gaussian noise
// of `noise_dn`, in 8 bits.
std::vector<cv::Mat> NoisyFrames(const PatternSequence& seq, double gain, double black_dn,
                                 double noise_dn, uint64_t seed) {
  cv::RNG rng(seed);
  std::vector<cv::Mat> frames;
  for (const cv::Mat& ideal : IdealFrames(seq)) {
    cv::Mat noise(ideal.size(), CV_32F), f;
    rng.fill(noise, cv::RNG::NORMAL, 0.0, noise_dn);
    ideal.convertTo(f, CV_32F, gain, black_dn);
    cv::Mat(f + noise).convertTo(f, CV_8U);
    frames.push_back(f);
  }
  return frames;
}

// Each Gray frame and its inverse add up to the white and black frames (FramePairCheck): in a sound
// scan at almost every lit pixel, whatever the bit; a frame of another pattern in one's place
// breaks that at about half the lit pixels (two Gray bit planes differ at half the pixels), in
// its own pair only.
TEST(Decode, AFrameOfAnotherPatternIsToldByItsPairNotAddingUp) {
  PatternOptions o;
  o.projector_size = cv::Size(640, 480);
  const PatternSequence seq = MakePatternSequence(o);
  // DecodeOptions::noise_dn; black at 20 DN, white at 198: none clipped.
  std::vector<cv::Mat> frames = NoisyFrames(seq, 0.7, 20.0, 1.5, 7);
  const int pattern = seq.Find(PatternKind::kGray, Axis::kRow, 6, false);
  const int inverse = seq.Find(PatternKind::kGray, Axis::kRow, 6, true);
  ASSERT_GE(pattern, 0);
  ASSERT_GE(inverse, 0);
  auto worst_other = [&](const DecodeStats& stats, double* share) {
    double worst = 0;
    for (const FramePairCheck& p : stats.pairs) {
      EXPECT_GT(p.lit, 640 * 480 / 2);
      if (p.pattern == pattern) {
        EXPECT_EQ(p.inverse, inverse);
        *share = p.Share();
      } else {
        worst = std::max(worst, p.Share());
      }
    }
    return worst;
  };
  const DecodeResult sound = Decode(seq, frames);
  ASSERT_TRUE(sound.status.ok()) << sound.status.message();
  // Every inverse-paired bit of both axes (10 column bits, 9 row bits).
  EXPECT_EQ(sound.stats.pairs.size(), 19u);
  double share = -1;
  // 6 sigmas of the sum's noise: a sound pair disagrees at a fraction of a percent.
  EXPECT_LT(worst_other(sound.stats, &share), 0.01);
  EXPECT_LT(share, 0.01);
  frames[pattern] = frames[seq.Find(PatternKind::kGray, Axis::kRow, 5, false)].clone();
  const DecodeResult swapped = Decode(seq, frames);
  ASSERT_TRUE(swapped.status.ok()) << swapped.status.message();
  EXPECT_LT(worst_other(swapped.stats, &share), 0.01);
  EXPECT_GT(share, 0.4);
  // A frame of another pattern lies on the scan's two levels as the right one would: the
  // redundancy does not tell which of the pair is wrong, and nothing is left out.
  for (const FramePairCheck& p : swapped.stats.pairs) EXPECT_EQ(p.left_out, -1);
}

// A camera noisier than the options say (3.5 DN where noise_dn is 1.5) on a dim scene (white
// 41 DN over black): the pair check takes its tolerance from the scan's own finest pairs, so a
// sound pair is not called wrong at a fifth of its pixels (the sum of four frames spreads by 7
// DN, over the 9 DN that 1.5 DN would allow), and a frame of another pattern is still told.
TEST(Decode, ThePairCheckFollowsTheCamerasOwnNoise) {
  PatternOptions o;
  o.projector_size = cv::Size(640, 480);
  const PatternSequence seq = MakePatternSequence(o);
  std::vector<cv::Mat> frames = NoisyFrames(seq, 0.16, 12.0, 3.5, 11);  // Black 12, white 53.
  const DecodeResult sound = Decode(seq, frames);
  ASSERT_TRUE(sound.status.ok()) << sound.status.message();
  ASSERT_FALSE(sound.stats.pairs.empty());
  for (const FramePairCheck& p : sound.stats.pairs) {
    EXPECT_LT(p.Share(), 0.005) << "bit " << p.bit << " of axis " << p.axis;
  }
  const int pattern = seq.Find(PatternKind::kGray, Axis::kColumn, 7, false);
  frames[pattern] = frames[seq.Find(PatternKind::kGray, Axis::kColumn, 6, false)].clone();
  const DecodeResult swapped = Decode(seq, frames);
  ASSERT_TRUE(swapped.status.ok()) << swapped.status.message();
  int told = 0;
  for (const FramePairCheck& p : swapped.stats.pairs) {
    if (p.pattern != pattern) continue;
    ++told;
    EXPECT_GT(p.Share(), 0.3);
  }
  EXPECT_EQ(told, 1);
}

// Where the redundancy tells which frame of a pair is wrong, the bit is decoded from the other
// alone and the decode is the sound scan's: a frame of another leaf (here the pattern seen
// shifted and at 60% of this leaf's light: values off both of this scan's levels wherever its
// stripes or its light differ), and an inverse taken before the projector changed (it shows its
// pair's pattern, and is the later shown).
TEST(Decode, AFrameTheRedundancyTellsIsLeftOutAndTheBitDecodedWithoutIt) {
  PatternOptions o;
  o.projector_size = cv::Size(640, 480);
  const PatternSequence seq = MakePatternSequence(o);
  cv::RNG rng(11);
  auto camera = [&](const cv::Mat& ideal, double gain) {
    cv::Mat noise(ideal.size(), CV_32F), f;
    rng.fill(noise, cv::RNG::NORMAL, 0.0, 1.5);
    ideal.convertTo(f, CV_32F, 0.7 * gain, 20.0);
    cv::Mat(f + noise).convertTo(f, CV_8U);
    return f;
  };
  const std::vector<cv::Mat> ideal = IdealFrames(seq);
  std::vector<cv::Mat> frames;
  for (const cv::Mat& m : ideal) frames.push_back(camera(m, 1.0));
  const DecodeResult sound = Decode(seq, frames);
  ASSERT_TRUE(sound.status.ok()) << sound.status.message();
  for (const FramePairCheck& p : sound.stats.pairs) EXPECT_EQ(p.left_out, -1);
  const int pattern = seq.Find(PatternKind::kGray, Axis::kRow, 6, false);
  const int inverse = seq.Find(PatternKind::kGray, Axis::kRow, 6, true);
  ASSERT_GT(inverse, pattern);
  // The share of lit pixels whose projector row moved by more than a hundredth of a pixel.
  auto moved = [&](const DecodeResult& r) {
    int lit = 0, off = 0;
    for (int y = 0; y < 480; ++y) {
      for (int x = 0; x < 640; ++x) {
        const float a = sound.projector_y.at<float>(y, x), b = r.projector_y.at<float>(y, x);
        if (!(a == a)) continue;
        ++lit;
        off += !(std::fabs(a - b) <= 0.01f);
      }
    }
    return static_cast<double>(off) / lit;
  };
  struct Case {
    const char* name;
    int frame;
    cv::Mat by;
    int left_out;
    bool shows_pair;
  };
  cv::Mat shifted;
  const cv::Mat shift = (cv::Mat_<double>(2, 3) << 1, 0, 0, 0, 1, 13);
  cv::warpAffine(ideal[pattern], shifted, shift, ideal[pattern].size(), cv::INTER_LINEAR,
                 cv::BORDER_REPLICATE);
  const Case cases[] = {{"another leaf", pattern, camera(shifted, 0.6), pattern, false},
                        {"before the change", inverse, camera(ideal[pattern], 1.0), inverse, true}};
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    std::vector<cv::Mat> broken = frames;
    broken[c.frame] = c.by;
    const DecodeResult r = Decode(seq, broken);
    ASSERT_TRUE(r.status.ok()) << r.status.message();
    for (const FramePairCheck& p : r.stats.pairs) {
      if (p.pattern != pattern) {
        EXPECT_EQ(p.left_out, -1) << p.pattern;
        continue;
      }
      EXPECT_GT(p.Share(), 0.05);
      EXPECT_EQ(p.left_out, c.left_out);
      EXPECT_EQ(p.shows_pair, c.shows_pair);
    }
    EXPECT_LT(moved(r), 1e-4);
    // The same decode with mending off (the bar above any share): many rows wrong or lost.
    DecodeOptions never;
    never.suspect_pair_share = 1.0;
    EXPECT_GT(moved(Decode(seq, broken, never)), 0.01);
  }
}

TEST(Decode, RejectsWrongFrameCountAndMixedSizes) {
  const PatternSequence seq = MakePatternSequence(PatternOptions{{64, 32}});
  std::vector<cv::Mat> frames = IdealFrames(seq);
  frames.pop_back();
  DecodeResult r = Decode(seq, frames);
  EXPECT_FALSE(r.status.ok());
  EXPECT_NE(r.status.message().find("frames"), std::string::npos) << r.status.message();
  frames = IdealFrames(seq);
  frames[3] = cv::Mat(10, 10, CV_8U, cv::Scalar(0));
  r = Decode(seq, frames);
  EXPECT_FALSE(r.status.ok());
  EXPECT_NE(r.status.message().find("frame 3"), std::string::npos) << r.status.message();
  EXPECT_FALSE(DecodeResult().status.ok()) << "a default result must say 'not run'";
}

// Frames as a camera sees them: a page at 70% of the projector's light over a 12 DN black
// level, slightly defocused, with 1.5 DN noise (the default DecodeOptions::noise_dn).
std::vector<cv::Mat> CameraFrames(const PatternSequence& seq, uint64_t seed) {
  cv::RNG rng(seed);
  std::vector<cv::Mat> frames;
  for (const PatternSpec& s : seq.patterns) {
    cv::Mat f;
    RenderPattern(s, seq.projector_size).convertTo(f, CV_32F, 0.7, 12.0);
    cv::GaussianBlur(f, f, cv::Size(3, 3), 0.6);
    cv::Mat noise(f.size(), CV_32F);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, 1.5);
    f += noise;
    f.convertTo(f, CV_8U);
    frames.push_back(f);
  }
  return frames;
}

// Frame by frame in any order decodes exactly as the whole scan does (the phase sums are exact
// integers, so their order cannot matter).
TEST(StreamingDecode, AnyOrderGivesTheWholeScansDecode) {
  const PatternSequence seq = MakePatternSequence(PatternOptions{{160, 96}});
  const std::vector<cv::Mat> frames = CameraFrames(seq, 7);
  const DecodeResult whole = Decode(seq, frames);
  ASSERT_TRUE(whole.status.ok()) << whole.status.message();
  ASSERT_GT(whole.stats.valid, 160 * 96 * 9 / 10);
  std::vector<int> order(frames.size());
  for (size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
  cv::RNG rng(11);
  for (int trial = 0; trial < 3; ++trial) {
    if (trial == 1) std::reverse(order.begin(), order.end());
    if (trial == 2) cv::randShuffle(order, 1.0, &rng);
    Decoder decoder;
    ASSERT_TRUE(decoder.Begin(seq, frames[0].size()).ok());
    for (int k : order) ASSERT_TRUE(decoder.Add(k, frames[k]).ok()) << k;
    DecodeResult streamed;
    decoder.Finish(&streamed);
    ASSERT_TRUE(streamed.status.ok()) << streamed.status.message();
    EXPECT_EQ(cv::norm(streamed.valid, whole.valid, cv::NORM_INF), 0) << "trial " << trial;
    EXPECT_EQ(streamed.stats.valid, whole.stats.valid);
    EXPECT_EQ(streamed.stats.rejected_bits, whole.stats.rejected_bits);
    // NaN where invalid: compare on valid pixels only.
    for (const auto& [a, b] : {std::pair{&streamed.projector_x, &whole.projector_x},
                               std::pair{&streamed.projector_y, &whole.projector_y}}) {
      cv::Mat d = cv::abs(*a - *b);
      d.setTo(0, whole.valid == 0);
      double worst = 0;
      cv::minMaxLoc(d, nullptr, &worst);
      EXPECT_EQ(worst, 0) << "trial " << trial;
    }
    EXPECT_EQ(decoder.HeldFrameBytes(), 0u) << "a finished decode holds no frame";
  }
}

// In the station's own order (MakePatternSequence: white, black, finest Gray bits first) a frame
// is let go as soon as it is taken up: the frames held never exceed white and black, the light
// estimate's 8 high-frequency frames and the finest bits before them (4 frames), against the
// 58 frames of a scan held whole.
TEST(StreamingDecode, InTheStationsOrderFewFramesAreEverHeld) {
  const PatternSequence seq = MakePatternSequence(PatternOptions{{160, 96}});
  ASSERT_EQ(seq.patterns.size(), 2u + 2 * (8 + 7) + 16u);  // 160 x 96: 8 and 7 Gray bits.
  const std::vector<cv::Mat> frames = CameraFrames(seq, 3);
  const size_t frame_bytes = frames[0].total();
  Decoder decoder;
  ASSERT_TRUE(decoder.Begin(seq, frames[0].size()).ok());
  size_t peak = 0;
  for (size_t k = 0; k < frames.size(); ++k) {
    ASSERT_TRUE(decoder.Add(static_cast<int>(k), frames[k]).ok());
    peak = std::max(peak, decoder.HeldFrameBytes());
    EXPECT_EQ(decoder.Received(), static_cast<int>(k + 1));
  }
  EXPECT_LE(peak, 14 * frame_bytes);
  // After the light estimate only white and black stay.
  EXPECT_EQ(decoder.HeldFrameBytes(), 2 * frame_bytes);
  DecodeResult r;
  decoder.Finish(&r);
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  EXPECT_EQ(r.stats.valid, Decode(seq, frames).stats.valid);
}

TEST(StreamingDecode, AFrameMissingTwiceOrOfTheWrongSizeIsNamed) {
  const PatternSequence seq = MakePatternSequence(PatternOptions{{64, 32}});
  const std::vector<cv::Mat> frames = IdealFrames(seq);
  Decoder decoder;
  DecodeResult r;
  ASSERT_TRUE(decoder.Begin(seq, frames[0].size()).ok());
  for (size_t k = 0; k < frames.size(); ++k) {
    if (k != 9) {
      ASSERT_TRUE(decoder.Add(static_cast<int>(k), frames[k]).ok());
    }
  }
  decoder.Finish(&r);
  ASSERT_FALSE(r.status.ok());
  EXPECT_NE(r.status.message().find("frame 9 (pattern '" + Describe(seq.patterns[9]) +
                                    "') never came: 39 of 40 frames"),
            std::string::npos)
      << r.status.message();

  ASSERT_TRUE(decoder.Begin(seq, frames[0].size()).ok());
  ASSERT_TRUE(decoder.Add(4, frames[4]).ok());
  Status s = decoder.Add(4, frames[4]);
  EXPECT_NE(s.message().find("frame 4: given twice"), std::string::npos) << s.message();
  decoder.Finish(&r);
  EXPECT_EQ(r.status.message(), s.message()) << "the scan ends with its first error";

  ASSERT_TRUE(decoder.Begin(seq, frames[0].size()).ok());
  s = decoder.Add(5, cv::Mat(10, 20, CV_8U, cv::Scalar(0)));
  EXPECT_NE(s.message().find("frame 5: is 20x10, not the camera's 64x32"), std::string::npos)
      << s.message();
  s = decoder.Add(58, frames[0]);
  EXPECT_FALSE(s.ok());
  ASSERT_TRUE(decoder.Begin(seq, frames[0].size()).ok());
  EXPECT_NE(decoder.Add(58, frames[0]).message().find("frame 58: no such frame"),
            std::string::npos);
}

// A capture that shows its own pattern, one that shows the one before, and one that mixes the
// two, on a linear camera (offset 20, gain 200) with stripes 6 pixels wide blurred over two:
// the pair adds up to white plus black only when clean; the steady check sees a change of a
// third of the contrast over half the picture, and not the noise.
TEST(FrameCheck, APairAddsUpOnlyWhenEachFrameShowsItsOwnPattern) {
  const cv::Size size(120, 80);
  cv::Mat light(size, CV_32F);
  for (int x = 0; x < size.width; ++x) light.col(x).setTo((x / 6) % 2 ? 1.0 : 0.0);
  cv::GaussianBlur(light, light, cv::Size(0, 0), 1.0);
  auto frame = [&](const cv::Mat& l, double seed) {
    cv::Mat noise(size, CV_32F), out;
    cv::RNG(static_cast<uint64_t>(seed)).fill(noise, cv::RNG::NORMAL, 0, 1.5);
    cv::Mat(20 + 200 * l + noise).convertTo(out, CV_8U);
    return out;
  };
  const cv::Mat ones(size, CV_32F, cv::Scalar(1)), zeros(size, CV_32F, cv::Scalar(0));
  const cv::Mat white = frame(ones, 1), black = frame(zeros, 2);
  const cv::Mat pattern = frame(light, 3), inverse = frame(ones - light, 4);
  EXPECT_LT(PairMismatch(pattern, inverse, white, black), 0.01);
  // The inverse shows its pattern whole (a display lag of more than an exposure).
  EXPECT_GT(PairMismatch(pattern, frame(light, 5), white, black), 0.9);
  // The inverse holds a third of its pattern (an exposure straddling the change).
  const cv::Mat mixed = frame((ones - light) * (2.0 / 3) + light * (1.0 / 3), 6);
  const double mismatch = PairMismatch(pattern, mixed, white, black);
  EXPECT_GT(mismatch, FrameCheckOptions().mixed_share) << mismatch;
  // Steady: the same pattern in two frames (their own noise) against the mixed one.
  EXPECT_LE(FrameChange(inverse, frame(ones - light, 7)), FrameCheckOptions().changed_share);
  EXPECT_GT(FrameChange(inverse, mixed), 0.2);
  // Unlit: no pixel to judge, nothing found.
  EXPECT_EQ(PairMismatch(black, black, black, black), 0.0);
  FrameCheckOptions o;
  std::string why;
  EXPECT_TRUE(o.Check(&why)) << why;
  o.pair_tolerance = 1.5;
  EXPECT_FALSE(o.Check(&why));
  EXPECT_NE(why.find("frame check"), std::string::npos);
}

}  // namespace
}  // namespace vellum
