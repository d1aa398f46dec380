#include "core/decode/decode.h"

#include <gtest/gtest.h>

#include <cmath>

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

}  // namespace
}  // namespace vellum
