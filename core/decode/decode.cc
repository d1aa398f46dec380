#include "core/decode/decode.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>

#include <opencv2/core/utility.hpp>

#include "core/common/check.h"

namespace vellum {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
// Weights are signal power relative to this amplitude, so they stay near 1 in float sums.
constexpr float kReferenceAmplitudeDn = 100.0f;
// Rows per parallel strip of the local fit (each strip recomputes 2r rows of moments).
constexpr int kFitStripRows = 64;

struct AxisPlan {
  bool present = false;
  int bits = 0;
  std::vector<int> pattern, inverse;  // Frame indices per bit, index 0 = finest bit.
  int steps = 0;                      // Phase steps, 0 if no phase patterns are used.
  int period = 0;
  std::vector<int> phase;             // Frame indices per step.
  std::vector<float> cos_k, sin_k;
};

AxisPlan PlanAxis(const PatternSequence& seq, Axis axis, bool use_phase) {
  AxisPlan plan;
  plan.bits = seq.GrayBits(axis);
  plan.present = plan.bits > 0;
  for (int b = 0; b < plan.bits; ++b) {
    plan.pattern.push_back(seq.Find(PatternKind::kGray, axis, b, false));
    plan.inverse.push_back(seq.Find(PatternKind::kGray, axis, b, true));
  }
  if (use_phase && seq.PhaseSteps(axis) > 0) {
    plan.steps = seq.PhaseSteps(axis);
    plan.period = seq.PhasePeriod(axis);
    for (int k = 0; k < plan.steps; ++k) {
      plan.phase.push_back(seq.Find(PatternKind::kPhase, axis, 0, false, k));
      const double delta = 2.0 * M_PI * k / plan.steps;
      plan.cos_k.push_back(static_cast<float>(std::cos(delta)));
      plan.sin_k.push_back(static_cast<float>(std::sin(delta)));
    }
  }
  return plan;
}

// Per-row scratch buffers of the decode pass.
struct RowScratch {
  std::vector<uint32_t> code;
  std::vector<uint8_t> uncertain;
  std::vector<float> s, c;
};

// Decodes one axis of one camera row into raw coordinates (NaN where rejected) and, for phase,
// the sinusoid amplitude. Returns per-row rejection counts through the counters.
void DecodeAxisRow(const AxisPlan& plan, const std::vector<cv::Mat>& frames, int y,
                   const DecodeOptions& options, const uint8_t* lit, RowScratch* scratch,
                   float* coordinate, float* modulation, int* rejected_bits,
                   int* rejected_modulation, int* rejected_unwrap) {
  const int width = frames[0].cols;
  auto& code = scratch->code;
  auto& uncertain = scratch->uncertain;
  code.assign(width, 0);
  uncertain.assign(width, 0);
  const int margin = static_cast<int>(std::ceil(options.uncertain_bit_dn));
  for (int b = plan.bits - 1; b >= 0; --b) {
    const uint8_t* p = frames[plan.pattern[b]].ptr<uint8_t>(y);
    const uint8_t* q = frames[plan.inverse[b]].ptr<uint8_t>(y);
    // Bits with stripes of 8 or more projector pixels survive defocus; only they vote on
    // whether the pixel sees the projector at all (two uncertain ones: shadow or no signal).
    const uint8_t counts = b >= 2 ? 1 : 0;
    for (int x = 0; x < width; ++x) {
      const int d = static_cast<int>(p[x]) - static_cast<int>(q[x]);
      code[x] = (code[x] << 1) | static_cast<uint32_t>(d > 0);
      uncertain[x] = static_cast<uint8_t>(uncertain[x] + ((d < margin && d > -margin) ? counts : 0));
    }
  }
  for (int x = 0; x < width; ++x) {  // Reflected Gray code to binary.
    uint32_t v = code[x];
    v ^= v >> 1;
    v ^= v >> 2;
    v ^= v >> 4;
    v ^= v >> 8;
    v ^= v >> 16;
    code[x] = v;
  }
  if (plan.steps == 0) {
    for (int x = 0; x < width; ++x) {
      if (!lit[x]) {
        coordinate[x] = kNaN;
      } else if (uncertain[x] >= 2) {
        coordinate[x] = kNaN;
        ++*rejected_bits;
      } else {
        coordinate[x] = static_cast<float>(code[x]);
      }
    }
    return;
  }
  auto& s = scratch->s;
  auto& c = scratch->c;
  s.assign(width, 0.0f);
  c.assign(width, 0.0f);
  for (int k = 0; k < plan.steps; ++k) {
    const uint8_t* f = frames[plan.phase[k]].ptr<uint8_t>(y);
    const float ck = plan.cos_k[k], sk = plan.sin_k[k];
    for (int x = 0; x < width; ++x) {
      const float v = f[x];
      c[x] += v * ck;
      s[x] += v * sk;
    }
  }
  const float period = static_cast<float>(plan.period);
  const float to_px = period / static_cast<float>(2.0 * M_PI);
  const float amp_scale = 2.0f / plan.steps;
  const float min_mod = static_cast<float>(options.min_modulation_dn);
  const float max_err = static_cast<float>(options.max_unwrap_error) * period;
  for (int x = 0; x < width; ++x) {
    const float amp = amp_scale * std::sqrt(s[x] * s[x] + c[x] * c[x]);
    modulation[x] = amp;
    float phase = FastAtan2(s[x], c[x]);
    if (phase < 0) phase += static_cast<float>(2.0 * M_PI);
    const float wrapped = phase * to_px;  // In [0, period).
    const float gray = static_cast<float>(code[x]);
    const float n = std::nearbyint((gray - wrapped) / period);
    const float unwrapped = wrapped + n * period;
    if (!lit[x]) {
      coordinate[x] = kNaN;
    } else if (uncertain[x] >= 2) {
      coordinate[x] = kNaN;
      ++*rejected_bits;
    } else if (amp < min_mod) {
      coordinate[x] = kNaN;
      ++*rejected_modulation;
    } else if (std::fabs(unwrapped - gray) > max_err) {
      coordinate[x] = kNaN;
      ++*rejected_unwrap;
    } else {
      coordinate[x] = unwrapped;
    }
  }
}

}  // namespace

bool DecodeOptions::Check(std::string* why) const {
  if (min_contrast_dn < 0 || min_modulation_dn < 0 || uncertain_bit_dn < 0) {
    *why = "decode thresholds must not be negative";
    return false;
  }
  if (!(max_unwrap_error > 0 && max_unwrap_error < 0.5)) {
    *why = "max_unwrap_error must lie in (0, 0.5) of a period";
    return false;
  }
  if (smooth_radius_px < 0 || smooth_radius_px > 32) {
    *why = "smooth_radius_px must lie in [0, 32]";
    return false;
  }
  if (smooth_passes < 1 || noise_dn <= 0 || outlier_sigmas <= 0) {
    *why = "smooth_passes must be >= 1, noise_dn and outlier_sigmas > 0";
    return false;
  }
  return true;
}

float FastAtan2(float y, float x) {
  // atan on [0, 1] by the odd polynomial of Abramowitz & Stegun 4.4.49 (|error| <= 2e-8).
  const float ax = std::fabs(x), ay = std::fabs(y);
  const float hi = std::max(ax, ay), lo = std::min(ax, ay);
  const float a = hi > 0 ? lo / hi : 0.0f;
  const float s = a * a;
  float p = 0.0028662257f;
  p = p * s - 0.0161657367f;
  p = p * s + 0.0429096138f;
  p = p * s - 0.0752896400f;
  p = p * s + 0.1065626393f;
  p = p * s - 0.1420889944f;
  p = p * s + 0.1999355085f;
  p = p * s - 0.3333314528f;
  float r = a + a * s * p;
  if (ay > ax) r = static_cast<float>(M_PI_2) - r;
  if (x < 0) r = static_cast<float>(M_PI) - r;
  return y < 0 ? -r : r;
}

void LocalLinearFit(const std::vector<cv::Mat>& values, const cv::Mat& weights, int radius,
                    std::vector<cv::Mat>* fitted) {
  VELLUM_DEMAND(weights.type() == CV_32F);
  VELLUM_DEMAND(!values.empty() && values.size() <= 2);
  for (const cv::Mat& v : values) {
    VELLUM_DEMAND(v.type() == CV_32F && v.size() == weights.size());
  }
  const int width = weights.cols, height = weights.rows, r = radius;
  const int n = static_cast<int>(values.size());
  fitted->resize(n);
  for (int p = 0; p < n; ++p) (*fitted)[p].create(weights.size(), CV_32F);
  const int strips = (height + kFitStripRows - 1) / kFitStripRows;

  cv::parallel_for_(cv::Range(0, strips), [&](const cv::Range& strip_range) {
    // Horizontal moments per row: w, w du, w du^2, then per plane w v, w v du.
    const int planes = 3 + 2 * n;
    std::vector<float> wpad(width + 2 * r), vpad(static_cast<size_t>(n) * (width + 2 * r));
    std::vector<float> acc(static_cast<size_t>(6 + 3 * n) * width);
    std::vector<float> moments;
    for (int strip = strip_range.start; strip < strip_range.end; ++strip) {
      const int y0 = strip * kFitStripRows, y1 = std::min(height, y0 + kFitStripRows);
      const int h0 = std::max(0, y0 - r), h1 = std::min(height, y1 + r);
      moments.assign(static_cast<size_t>(h1 - h0) * planes * width, 0.0f);
      for (int y = h0; y < h1; ++y) {
        const float* w = weights.ptr<float>(y);
        for (int x = 0; x < width; ++x) wpad[x + r] = w[x] > 0 ? w[x] : 0.0f;
        for (int p = 0; p < n; ++p) {
          const float* v = values[p].ptr<float>(y);
          float* vp = &vpad[static_cast<size_t>(p) * (width + 2 * r)];
          for (int x = 0; x < width; ++x) vp[x + r] = w[x] > 0 ? w[x] * v[x] : 0.0f;
        }
        float* m = &moments[static_cast<size_t>(y - h0) * planes * width];
        float* m0 = m;
        float* m1 = m + width;
        float* m2 = m + 2 * width;
        for (int dx = -r; dx <= r; ++dx) {
          const float fdx = static_cast<float>(dx), fdx2 = fdx * fdx;
          const float* src = &wpad[r + dx];
          for (int x = 0; x < width; ++x) {
            m0[x] += src[x];
            m1[x] += src[x] * fdx;
            m2[x] += src[x] * fdx2;
          }
          for (int p = 0; p < n; ++p) {
            const float* vs = &vpad[static_cast<size_t>(p) * (width + 2 * r) + r + dx];
            float* mv0 = m + (3 + 2 * p) * width;
            float* mv1 = mv0 + width;
            for (int x = 0; x < width; ++x) {
              mv0[x] += vs[x];
              mv1[x] += vs[x] * fdx;
            }
          }
        }
      }
      for (int y = y0; y < y1; ++y) {
        std::fill(acc.begin(), acc.end(), 0.0f);
        float* S = &acc[0];
        float* Su = S + width;
        float* Sv = Su + width;
        float* Suu = Sv + width;
        float* Suv = Suu + width;
        float* Svv = Suv + width;
        for (int dy = -r; dy <= r; ++dy) {
          const int yy = y + dy;
          if (yy < 0 || yy >= height) continue;
          const float fdy = static_cast<float>(dy), fdy2 = fdy * fdy;
          const float* m = &moments[static_cast<size_t>(yy - h0) * planes * width];
          const float* m0 = m;
          const float* m1 = m + width;
          const float* m2 = m + 2 * width;
          for (int x = 0; x < width; ++x) {
            S[x] += m0[x];
            Sv[x] += m0[x] * fdy;
            Svv[x] += m0[x] * fdy2;
            Su[x] += m1[x];
            Suv[x] += m1[x] * fdy;
            Suu[x] += m2[x];
          }
          for (int p = 0; p < n; ++p) {
            const float* mv0 = m + (3 + 2 * p) * width;
            const float* mv1 = mv0 + width;
            float* X = &acc[static_cast<size_t>(6 + 3 * p) * width];
            float* Xu = X + width;
            float* Xv = Xu + width;
            for (int x = 0; x < width; ++x) {
              X[x] += mv0[x];
              Xv[x] += mv0[x] * fdy;
              Xu[x] += mv1[x];
            }
          }
        }
        const float* w = weights.ptr<float>(y);
        for (int x = 0; x < width; ++x) {
          // Intercept of the 3x3 weighted normal equations: first row of the adjugate.
          const double s = S[x], su = Su[x], sv = Sv[x];
          const double suu = Suu[x], suv = Suv[x], svv = Svv[x];
          const double c0 = suu * svv - suv * suv;
          const double c1 = sv * suv - su * svv;
          const double c2 = su * suv - suu * sv;
          const double det = s * c0 + su * c1 + sv * c2;
          const bool solvable = det > 1e-6 * s * suu * svv && s > 0;
          for (int p = 0; p < n; ++p) {
            const float* X = &acc[static_cast<size_t>(6 + 3 * p) * width];
            float value;
            if (!(w[x] > 0)) {
              value = kNaN;
            } else if (solvable) {
              value = static_cast<float>((c0 * X[x] + c1 * X[x + width] + c2 * X[x + 2 * width]) /
                                         det);
            } else {
              value = static_cast<float>(X[x] / s);
            }
            (*fitted)[p].ptr<float>(y)[x] = value;
          }
        }
      }
    }
  }, strips);
}

DecodeResult Decode(const PatternSequence& sequence, const std::vector<cv::Mat>& frames,
                    const DecodeOptions& options) {
  DecodeResult result;
  std::string why;
  if (!options.Check(&why)) {
    result.status = Status::Error("decode options: " + why);
    return result;
  }
  if (!sequence.Check(&why)) {
    result.status = Status::Error("pattern sequence: " + why);
    return result;
  }
  if (frames.size() != sequence.patterns.size()) {
    result.status = Status::Error("the scan has " + std::to_string(frames.size()) +
                                  " frames but its pattern sequence has " +
                                  std::to_string(sequence.patterns.size()));
    return result;
  }
  for (size_t k = 0; k < frames.size(); ++k) {
    if (frames[k].empty() || frames[k].type() != CV_8UC1 || frames[k].size() != frames[0].size()) {
      result.status = Status::Error("frame " + std::to_string(k) +
                                    " is empty, not 8-bit single channel, or differs in size "
                                    "from frame 0");
      return result;
    }
  }
  const cv::Size size = frames[0].size();
  const int width = size.width, height = size.height;
  const AxisPlan col = PlanAxis(sequence, Axis::kColumn, options.use_phase);
  const AxisPlan row = PlanAxis(sequence, Axis::kRow, options.use_phase);
  const cv::Mat& white = frames[sequence.Find(PatternKind::kWhite)];
  const cv::Mat& black = frames[sequence.Find(PatternKind::kBlack)];

  cv::Mat raw_x(size, CV_32F, cv::Scalar(kNaN)), raw_y(size, CV_32F, cv::Scalar(kNaN));
  cv::Mat weight(size, CV_32F), sigma(size, CV_32F);
  result.amplitude.create(size, CV_32F);
  std::atomic<int> lit_count{0}, saturated{0}, bad_bits{0}, bad_mod{0}, bad_unwrap{0};

  // Expected coordinate noise (projector px) of a phase decode with amplitude b:
  // P / (2 pi) * noise / (b sqrt(N / 2)). Gray code alone: its quantisation, half a pixel.
  auto phase_sigma_scale = [&](const AxisPlan& plan) {
    return plan.steps > 0 ? plan.period / (2.0 * M_PI) * options.noise_dn /
                                std::sqrt(plan.steps / 2.0)
                          : 0.0;
  };
  const double col_sigma = phase_sigma_scale(col), row_sigma = phase_sigma_scale(row);

  cv::parallel_for_(cv::Range(0, height), [&](const cv::Range& range) {
    RowScratch scratch;
    std::vector<uint8_t> lit(width);
    std::vector<float> mod_x(width, 0.0f), mod_y(width, 0.0f);
    int n_lit = 0, n_sat = 0, n_bits = 0, n_mod = 0, n_unwrap = 0;
    for (int y = range.start; y < range.end; ++y) {
      const uint8_t* wr = white.ptr<uint8_t>(y);
      const uint8_t* br = black.ptr<uint8_t>(y);
      float* amp = result.amplitude.ptr<float>(y);
      for (int x = 0; x < width; ++x) {
        const int contrast = static_cast<int>(wr[x]) - static_cast<int>(br[x]);
        amp[x] = 0.5f * static_cast<float>(contrast);
        lit[x] = contrast >= options.min_contrast_dn && wr[x] < options.saturation_dn;
        n_lit += contrast >= options.min_contrast_dn;
        n_sat += contrast >= options.min_contrast_dn && wr[x] >= options.saturation_dn;
      }
      float* px = raw_x.ptr<float>(y);
      float* py = raw_y.ptr<float>(y);
      if (col.present) {
        DecodeAxisRow(col, frames, y, options, lit.data(), &scratch, px, mod_x.data(), &n_bits,
                      &n_mod, &n_unwrap);
      }
      if (row.present) {
        // A pixel rejected by the column code is not counted again by the row code.
        for (int x = 0; x < width; ++x) {
          if (col.present && std::isnan(px[x])) lit[x] = 0;
        }
        DecodeAxisRow(row, frames, y, options, lit.data(), &scratch, py, mod_y.data(), &n_bits,
                      &n_mod, &n_unwrap);
        if (col.present) {
          for (int x = 0; x < width; ++x) {
            if (std::isnan(py[x])) px[x] = kNaN;
          }
        }
      }
      float* w = weight.ptr<float>(y);
      float* sg = sigma.ptr<float>(y);
      for (int x = 0; x < width; ++x) {
        const float v = col.present ? px[x] : py[x];
        if (std::isnan(v)) {
          w[x] = 0.0f;
          sg[x] = 1.0f;
          continue;
        }
        // Signal power: the weaker of the two sinusoids, or the white/black amplitude.
        float b = amp[x];
        double s = 0.5;
        if (col.steps > 0 || row.steps > 0) {
          b = std::numeric_limits<float>::max();
          s = 0.0;
          if (col.steps > 0) {
            b = std::min(b, mod_x[x]);
            s = std::max(s, col_sigma / mod_x[x]);
          }
          if (row.present && row.steps > 0) {
            b = std::min(b, mod_y[x]);
            s = std::max(s, row_sigma / mod_y[x]);
          }
        }
        const float rel = b / kReferenceAmplitudeDn;
        w[x] = rel * rel;
        sg[x] = static_cast<float>(std::max(s, 0.01));
      }
    }
    lit_count += n_lit;
    saturated += n_sat;
    bad_bits += n_bits;
    bad_mod += n_mod;
    bad_unwrap += n_unwrap;
  });

  std::vector<cv::Mat> raw;
  if (col.present) raw.push_back(raw_x);
  if (row.present) raw.push_back(raw_y);
  int fallbacks = 0;
  if (options.smooth_radius_px > 0) {
    std::vector<cv::Mat> fit;
    LocalLinearFit(raw, weight, options.smooth_radius_px, &fit);
    const float cut = static_cast<float>(options.outlier_sigmas);
    // Robust reweighting: a pixel far from its own local fit (a depth step, a bad decode) loses
    // its weight in its neighbours' fits (Tukey biweight).
    auto normalized_residual = [&](int y, int x) {
      float worst = 0.0f;
      for (size_t p = 0; p < raw.size(); ++p) {
        worst = std::max(worst, std::fabs(raw[p].ptr<float>(y)[x] - fit[p].ptr<float>(y)[x]));
      }
      return worst / sigma.ptr<float>(y)[x];
    };
    cv::Mat robust_weight(size, CV_32F);
    for (int pass = 1; pass < options.smooth_passes; ++pass) {
      cv::parallel_for_(cv::Range(0, height), [&](const cv::Range& range) {
        for (int y = range.start; y < range.end; ++y) {
          const float* w = weight.ptr<float>(y);
          float* rw = robust_weight.ptr<float>(y);
          for (int x = 0; x < width; ++x) {
            if (!(w[x] > 0)) {
              rw[x] = 0.0f;
              continue;
            }
            const float u = normalized_residual(y, x) / cut;
            const float t = u < 1.0f ? 1.0f - u * u : 0.0f;
            rw[x] = w[x] * t * t;
          }
        }
      });
      LocalLinearFit(raw, robust_weight, options.smooth_radius_px, &fit);
      // A pixel whose robust weight fell to zero keeps its raw value unless it is refitted.
      for (int y = 0; y < height; ++y) {
        const float* rw = robust_weight.ptr<float>(y);
        const float* w = weight.ptr<float>(y);
        for (int x = 0; x < width; ++x) {
          if (w[x] > 0 && !(rw[x] > 0)) {
            for (size_t p = 0; p < raw.size(); ++p) {
              fit[p].ptr<float>(y)[x] = raw[p].ptr<float>(y)[x];
            }
          }
        }
      }
    }
    // Where the fit still disagrees with the pixel (a step inside the window), keep the raw
    // decode: it is unbiased, only noisier.
    for (int y = 0; y < height; ++y) {
      const float* w = weight.ptr<float>(y);
      for (int x = 0; x < width; ++x) {
        if (!(w[x] > 0)) continue;
        if (normalized_residual(y, x) > cut) {
          ++fallbacks;
          for (size_t p = 0; p < raw.size(); ++p) {
            fit[p].ptr<float>(y)[x] = raw[p].ptr<float>(y)[x];
          }
        }
      }
    }
    size_t p = 0;
    if (col.present) raw_x = fit[p++];
    if (row.present) raw_y = fit[p++];
  }
  result.projector_x = raw_x;
  result.projector_y = raw_y;
  result.valid = weight > 0;
  result.has_columns = col.present;
  result.has_rows = row.present;
  DecodeStats& st = result.stats;
  st.pixels = width * height;
  st.lit = lit_count;
  st.valid = cv::countNonZero(result.valid);
  st.rejected_saturated = saturated;
  st.rejected_bits = bad_bits;
  st.rejected_modulation = bad_mod;
  st.rejected_unwrap = bad_unwrap;
  st.fit_fallbacks = fallbacks;
  result.status = Status::Ok();
  return result;
}

}  // namespace vellum
