#include "core/decode/decode.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <mutex>
#include <opencv2/core/utility.hpp>
#include <tuple>

#include "core/common/check.h"
#include "core/common/text.h"

namespace vellum {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kPi = static_cast<float>(M_PI);
// Weights are signal power relative to this amplitude, so they stay near 1 in float sums.
constexpr float kReferenceAmplitudeDn = 100.0f;
// Rows per parallel strip of the local fit (each strip recomputes 2r rows of moments).
constexpr int kFitStripRows = 48;
// Gray bits with stripes of 8 or more projector pixels survive defocus; only they vote on
// whether a pixel sees the projector at all.
constexpr int kFirstVotingBit = 2;
// Largest local fit radius (the fit is compiled per radius).
constexpr int kMaxFitRadius = 8;

// atan2 on [0, 1] by the odd polynomial of Abramowitz & Stegun 4.4.49 (|error| <= 2e-8), with
// branch-free octant folding so loops over it vectorise.
inline float Atan2Inline(float y, float x) {
  const float ax = std::fabs(x), ay = std::fabs(y);
  const float hi = std::max(ax, ay), lo = std::min(ax, ay);
  const float a = lo / std::max(hi, 1e-30f);
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
  r = ay > ax ? 0.5f * kPi - r : r;
  r = x < 0 ? kPi - r : r;
  return y < 0 ? -r : r;
}

struct AxisPlan {
  bool present = false;
  int bits = 0;
  int first_bit = 0;  // The finest bit coded: stripes of 2^first_bit projector pixels.
  // Frame indices per bit, index 0 = finest bit (-1 below first_bit; inverse -1 throughout for
  // a code without inverses, whose bits are judged against the white and black frames).
  std::vector<int> pattern, inverse;
  int steps = 0;  // Phase steps, 0 if no phase patterns are used.
  int period = 0;
  std::vector<int> phase;  // Frame indices per step.
  // cos and sin of each step in fixed point (times `fixed`): the phase sums are exact integers,
  // the same whatever order the frames come in.
  std::vector<int32_t> cos_k, sin_k;
  float fixed = 1.0f;
  double sigma_scale = 0.5;  // Expected coordinate noise (px) x amplitude (DN).
};

AxisPlan PlanAxis(const PatternSequence& seq, Axis axis, const DecodeOptions& options) {
  AxisPlan plan;
  plan.bits = seq.GrayBits(axis);
  plan.present = plan.bits > 0;
  plan.first_bit = seq.FirstGrayBit(axis);
  for (int b = 0; b < plan.bits; ++b) {
    plan.pattern.push_back(seq.Find(PatternKind::kGray, axis, b, false));
    plan.inverse.push_back(seq.Find(PatternKind::kGray, axis, b, true));
  }
  if (options.use_phase && seq.PhaseSteps(axis) > 0) {
    plan.steps = seq.PhaseSteps(axis);
    plan.period = seq.PhasePeriod(axis);
    // The largest power of two for which 255 x steps x fixed cannot overflow 32 bits: 2^20 for
    // 8 steps, a coefficient to 5e-7, as fine as float sums were.
    int64_t fixed = 1;
    while (255LL * plan.steps * fixed * 2 <= INT32_MAX) fixed *= 2;
    plan.fixed = static_cast<float>(fixed);
    for (int k = 0; k < plan.steps; ++k) {
      plan.phase.push_back(seq.Find(PatternKind::kPhase, axis, 0, false, k));
      const double delta = 2.0 * M_PI * k / plan.steps;
      plan.cos_k.push_back(static_cast<int32_t>(std::lround(plan.fixed * std::cos(delta))));
      plan.sin_k.push_back(static_cast<int32_t>(std::lround(plan.fixed * std::sin(delta))));
    }
    // Phase noise sigma / (b sqrt(N / 2)) rad, times P / (2 pi) px per rad.
    plan.sigma_scale = plan.period / (2.0 * M_PI) * options.noise_dn / std::sqrt(plan.steps / 2.0);
  }
  return plan;
}

struct Counters {
  int lit = 0, saturated = 0, bits = 0, modulation = 0, unwrap = 0;
};

// Per-row scratch of the final pass.
struct RowScratch {
  explicit RowScratch(int width) : code(width), amp(width), coord(width), error(width) {}
  std::vector<uint16_t> code;
  std::vector<float> amp, coord, error;
};

// Restrict-qualified parameters of functions that stay out of line are what lets GCC
// vectorise these loops (restrict on locals, or after inlining, is ignored).

// Direct and global light of one camera row (Nayar et al. 2006, as Xu & Aliaga and Moreno &
// Taubin's scan3d-capture use it): over high-frequency patterns, each lighting half the scene,
// a pixel sees Lmax = Ld + Lg / 2 and Lmin = Lg / 2. The black frame is subtracted first, so
// ambient light and the projector's black level do not count as global light.
__attribute__((noinline)) void LightFromExtremes(const uint8_t* __restrict lmax,
                                                 const uint8_t* __restrict lmin,
                                                 const uint8_t* __restrict b,
                                                 int16_t* __restrict direct,
                                                 int16_t* __restrict global, int width) {
  for (int x = 0; x < width; ++x) {
    const int16_t lo = static_cast<int16_t>(std::max(0, lmin[x] - b[x]));
    direct[x] = static_cast<int16_t>(lmax[x] - lmin[x]);
    global[x] = static_cast<int16_t>(2 * lo);
  }
}

// Classifies one Gray bit of a row into code (at bit `shift`) and counts uncertain votes. Bit
// classification of Xu & Aliaga: where direct light dominates, pattern vs inverse (with a
// noise margin); where global light dominates, only a pattern clearly below the direct level
// with its inverse above the global level (or the reverse) decides. kUndo takes back what the
// same call without it gave (the bit cleared, its votes subtracted), so a bit can be classified
// again from other frames.
template <bool kUndo>
__attribute__((noinline)) void ClassifyBit(const uint8_t* __restrict p, const uint8_t* __restrict q,
                                           const uint8_t* __restrict black,
                                           const int16_t* __restrict direct,
                                           const int16_t* __restrict global, int16_t margin,
                                           int16_t min_direct, uint16_t votes, int shift,
                                           uint16_t* __restrict code,
                                           uint16_t* __restrict uncertain, int width) {
  const int16_t neg_margin = static_cast<int16_t>(-margin);
  const uint16_t keep = static_cast<uint16_t>(~(1u << shift));
  for (int x = 0; x < width; ++x) {
    const int16_t pv = static_cast<int16_t>(p[x] - black[x]);
    const int16_t qv = static_cast<int16_t>(q[x] - black[x]);
    const int16_t d = static_cast<int16_t>(pv - qv);
    // 0/1 integers rather than bools: the vectoriser handles their selects.
    const uint16_t direct_wins = direct[x] > global[x];
    const uint16_t one = (pv >= global[x]) & (qv <= direct[x]);
    const uint16_t zero = (pv <= direct[x]) & (qv >= global[x]);
    const uint16_t bit = static_cast<uint16_t>((direct_wins & (d > 0)) | ((1 - direct_wins) & one));
    const uint16_t near = (d < margin) & (d > neg_margin);
    const uint16_t unsure = static_cast<uint16_t>((direct[x] < min_direct) | (direct_wins & near) |
                                                  ((1 - direct_wins) & (1 - (one | zero))));
    if constexpr (kUndo) {
      code[x] = static_cast<uint16_t>(code[x] & keep);
      uncertain[x] = static_cast<uint16_t>(uncertain[x] - unsure * votes);
    } else {
      code[x] = static_cast<uint16_t>(code[x] | (bit << shift));
      uncertain[x] = static_cast<uint16_t>(uncertain[x] + unsure * votes);
    }
  }
}

// Counts, in one row, the pixels lit enough to judge and those where a Gray pattern and its
// inverse do not add up to the white and black frames: |p + q - white - black| above 35% of the
// direct light and 6 noise sigmas (pixels clipped in any of the three skipped). Of those, when
// `off_pattern` is given, counts where each frame lies off both levels the scan's light allows
// a lit pixel (above black: global / 2 unlit, direct + global / 2 lit; off: farther than 20% of
// the direct light and 6 noise sigmas from both), and where the two frames show the same value.
template <bool kBlame>
__attribute__((noinline)) void PairDisagreement(
    const uint8_t* __restrict p, const uint8_t* __restrict q, const uint8_t* __restrict black,
    const uint8_t* __restrict white, const int16_t* __restrict direct,
    const int16_t* __restrict global, int16_t min_direct, int16_t floor_dn, int width, int64_t* lit,
    int64_t* disagree, int64_t* off_pattern = nullptr, int64_t* off_inverse = nullptr,
    int64_t* alike = nullptr) {
  int n = 0, off = 0, np = 0, nq = 0, same = 0;
  for (int x = 0; x < width; ++x) {
    const int d = direct[x];
    const int judged = (d >= min_direct) & (p[x] < 255) & (q[x] < 255) & (white[x] < 255);
    const int r = p[x] + q[x] - white[x] - black[x];
    const int tol = std::max<int>(floor_dn, (d * 35) / 100);
    const int wrong = judged & ((r > tol) | (r < -tol));
    n += judged;
    off += wrong;
    if constexpr (kBlame) {
      const int pv = p[x] - black[x], qv = q[x] - black[x];
      const int lo = global[x] / 2, hi = d + global[x] / 2;
      const int near = std::max<int>(floor_dn, d / 5);
      const int p_off = (std::abs(pv - lo) > near) & (std::abs(pv - hi) > near);
      const int q_off = (std::abs(qv - lo) > near) & (std::abs(qv - hi) > near);
      np += wrong & p_off;
      nq += wrong & q_off;
      same += wrong & (std::abs(pv - qv) <= near);
    }
  }
  *lit += n;
  *disagree += off;
  if constexpr (kBlame) {
    *off_pattern += np;
    *off_inverse += nq;
    *alike += same;
  }
}

// Adds one phase-shifted frame's row to the sums c += v cos(delta_k), s += v sin(delta_k).
__attribute__((noinline)) void AccumulatePhase(const uint8_t* __restrict f, int32_t ck, int32_t sk,
                                               int32_t* __restrict c, int32_t* __restrict s,
                                               int width) {
  for (int x = 0; x < width; ++x) {
    const int32_t v = f[x];
    c[x] += v * ck;
    s[x] += v * sk;
  }
}

// One axis of one camera row, from its classified Gray code (reflected, as accumulated) and
// phase sums: `coordinate` gets the projector coordinate, NaN where the pixel is rejected, and
// `modulation` the sinusoid amplitude (or (white - black) / 2 for Gray code alone). Pixels with
// lit[x] == 0 are skipped and not counted.
void CoordinatesRow(const AxisPlan& plan, const uint16_t* gray_code, const uint16_t* uncertain,
                    const int32_t* c, const int32_t* s, const DecodeOptions& options,
                    const uint8_t* lit, const float* half_contrast, int width, RowScratch* sc,
                    float* coordinate, float* modulation, Counters* count) {
  uint16_t* __restrict code = sc->code.data();
  for (int x = 0; x < width; ++x) {  // Reflected Gray code to binary.
    uint16_t v = gray_code[x];
    v ^= v >> 1;
    v ^= v >> 2;
    v ^= v >> 4;
    v ^= v >> 8;
    code[x] = v;
  }
  float* amp = sc->amp.data();
  float* coord = sc->coord.data();
  float* err = sc->error.data();
  float max_err = 0.0f, min_mod = 0.0f;
  // The code numbers stripes of 2^first_bit projector pixels: the stripe's centre.
  const float stripe = static_cast<float>(1 << plan.first_bit);
  const float centre = 0.5f * (stripe - 1.0f);
  if (plan.steps == 0) {
    for (int x = 0; x < width; ++x) {
      coord[x] = static_cast<float>(code[x]) * stripe + centre;
      amp[x] = half_contrast[x];
      err[x] = 0.0f;
    }
  } else {
    const float period = static_cast<float>(plan.period);
    const float inv_period = 1.0f / period;
    const float to_px = period / (2.0f * kPi);
    const float amp_scale = 2.0f / (plan.steps * plan.fixed);
    for (int x = 0; x < width; ++x) {
      const float sx = static_cast<float>(s[x]), cx = static_cast<float>(c[x]);
      amp[x] = amp_scale * std::sqrt(sx * sx + cx * cx);
      float phase = Atan2Inline(sx, cx);
      phase = phase < 0 ? phase + 2.0f * kPi : phase;
      const float wrapped = phase * to_px;  // In [0, period).
      const float gray = static_cast<float>(code[x]) * stripe + centre;
      // The Gray code picks the period: a boundary bit error (+-1 stripe) changes nothing.
      const float n = std::floor((gray - wrapped) * inv_period + 0.5f);
      coord[x] = wrapped + n * period;
      err[x] = std::fabs(coord[x] - gray);
    }
    // Within a stripe the phase may lie anywhere: half a stripe more is allowed.
    max_err = static_cast<float>(options.max_unwrap_error) * period + 0.5f * (stripe - 1.0f);
    min_mod = static_cast<float>(options.min_modulation_dn);
  }
  int n_bits = 0, n_mod = 0, n_unwrap = 0;
  for (int x = 0; x < width; ++x) {
    const bool on = lit[x] != 0;
    const bool bad_bits = uncertain[x] >= 2;
    const bool bad_mod = amp[x] < min_mod;
    const bool bad_unwrap = err[x] > max_err;
    n_bits += on & bad_bits;
    n_mod += on & !bad_bits & bad_mod;
    n_unwrap += on & !bad_bits & !bad_mod & bad_unwrap;
    const bool ok = on & !bad_bits & !bad_mod & !bad_unwrap;
    coordinate[x] = ok ? coord[x] : kNaN;
    modulation[x] = amp[x];
  }
  count->bits += n_bits;
  count->modulation += n_mod;
  count->unwrap += n_unwrap;
}

}  // namespace

// The decode in progress: what has come, what is held, and the sums so far.
struct Decoder::Stream {
  PatternSequence sequence;
  cv::Size size;
  AxisPlan axes[2];  // Column, row.
  int white = -1, black = -1;
  // Frames the direct/global light estimate needs: the two finest inverse-paired Gray bits of
  // each axis (high frequency); white and black when the code has no inverses.
  std::vector<int> high_frequency;
  std::vector<cv::Mat> held;      // By frame index: frames come and not yet taken up.
  std::vector<uint8_t> received;  // By frame index.
  std::vector<uint8_t> phase_done[2], bit_done[2];  // By step, by bit.
  int count = 0;                                    // Frames received.
  cv::Mat code[2], uncertain[2];      // CV_16U: reflected Gray code so far; uncertain-bit votes.
  cv::Mat cos_sum[2], sin_sum[2];     // CV_32S: phase sums so far, fixed point.
  cv::Mat direct, global;             // CV_16S: the light estimate, once light_ready.
  std::vector<FramePairCheck> pairs;  // Each inverse-paired bit's, as it is taken up.
  // How far a pair may stray from white + black before it disagrees, at the dimmest pixels, DN:
  // six times the noise the options expect (three standard deviations of a sum of four frames),
  // or three of the spread this scan's own pairs show where the camera is noisier (PairFloor).
  int16_t pair_floor_dn = 0;
  bool light_ready = false;
  Status status = Status::Error("decode not begun");

  bool Has(int index) const { return index >= 0 && received[index]; }
  bool LightInputsIn() const {
    if (!Has(black)) return false;
    for (int k : high_frequency) {
      if (!Has(k)) return false;
    }
    return true;
  }
  // Gray bit b of an axis can be classified (its light estimate aside).
  bool BitInputsIn(const AxisPlan& plan, int b) const {
    // White too: a pair is checked against it (FramePairCheck), a lone pattern judged by it.
    return Has(plan.pattern[b]) && Has(white) && (plan.inverse[b] < 0 || Has(plan.inverse[b]));
  }
};

Decoder::Decoder(const DecodeOptions& options)
    : options_(options), stream_(std::make_unique<Stream>()) {}
Decoder::~Decoder() = default;

Status Decoder::Begin(const PatternSequence& sequence, cv::Size camera_size) {
  Stream& st = *stream_;
  st.held.clear();
  st.pairs.clear();
  st.count = 0;
  st.light_ready = false;
  st.pair_floor_dn = 0;
  std::string why;
  if (!options_.Check(&why)) return st.status = Status::Error("decode options: " + why);
  if (!sequence.Check(&why)) return st.status = Status::Error("pattern sequence: " + why);
  if (camera_size.width <= 0 || camera_size.height <= 0) {
    return st.status = Status::Error("decode: the camera size is empty");
  }
  st.sequence = sequence;
  st.size = camera_size;
  const int n = static_cast<int>(sequence.patterns.size());
  st.held.assign(n, cv::Mat());
  st.received.assign(n, 0);
  st.white = sequence.Find(PatternKind::kWhite);
  st.black = sequence.Find(PatternKind::kBlack);
  st.axes[0] = PlanAxis(sequence, Axis::kColumn, options_);
  st.axes[1] = PlanAxis(sequence, Axis::kRow, options_);
  // High-frequency patterns for the direct/global estimate: Gray bits 1 and 2 (stripes of 4
  // and 8 projector pixels: fine, yet above the defocus) of each axis, with their inverses.
  // A code without its finest bits uses its two finest; without inverses, no pattern pair lights
  // every pixel once, and the white and black frames give the light (direct = white - black,
  // no global light seen).
  st.high_frequency.clear();
  for (const AxisPlan& plan : st.axes) {
    const int low = std::max(1, plan.first_bit);
    for (int b = low; b <= low + 1 && b < plan.bits; ++b) {
      if (plan.inverse[b] < 0) continue;
      st.high_frequency.push_back(plan.pattern[b]);
      st.high_frequency.push_back(plan.inverse[b]);
    }
  }
  const AxisPlan& first = st.axes[0].present ? st.axes[0] : st.axes[1];
  if (st.high_frequency.empty() && first.inverse[first.first_bit] >= 0) {
    // A projector of 2 or 3 pixels: its only bit.
    st.high_frequency = {first.pattern[first.first_bit], first.inverse[first.first_bit]};
  }
  if (st.high_frequency.empty()) st.high_frequency = {st.white, st.black};
  for (int a = 0; a < 2; ++a) {
    const AxisPlan& plan = st.axes[a];
    st.bit_done[a].assign(plan.bits, 0);
    st.phase_done[a].assign(plan.steps, 0);
    if (!plan.present) continue;
    st.code[a].create(camera_size, CV_16U);
    st.code[a].setTo(0);
    st.uncertain[a].create(camera_size, CV_16U);
    st.uncertain[a].setTo(0);
    if (plan.steps > 0) {
      st.cos_sum[a].create(camera_size, CV_32S);
      st.cos_sum[a].setTo(0);
      st.sin_sum[a].create(camera_size, CV_32S);
      st.sin_sum[a].setTo(0);
    }
  }
  st.direct.create(camera_size, CV_16S);
  st.global.create(camera_size, CV_16S);
  return st.status = Status::Ok();
}

Status Decoder::Store(int index, const cv::Mat& frame) {
  Stream& st = *stream_;
  if (!st.status.ok()) return st.status;
  const int n = static_cast<int>(st.received.size());
  auto fail = [&](const std::string& why) {
    return st.status = Status::Error("frame " + std::to_string(index) + ": " + why);
  };
  if (index < 0 || index >= n) {
    return fail("no such frame: the pattern sequence has " + std::to_string(n));
  }
  if (st.received[index]) return fail("given twice");
  if (frame.empty() || frame.type() != CV_8UC1 || frame.size() != st.size) {
    return fail(frame.empty() ? "is empty"
                : frame.type() != CV_8UC1
                    ? "is not 8-bit single channel"
                    : "is " + SizeText(frame.size()) + ", not the camera's " + SizeText(st.size));
  }
  st.received[index] = 1;
  ++st.count;
  const PatternSpec& spec = st.sequence.patterns[index];
  // Phase frames of an axis decoded by Gray code alone are not needed.
  const bool unused =
      spec.kind == PatternKind::kPhase && st.axes[spec.axis == Axis::kColumn ? 0 : 1].steps == 0;
  // A frame that does not own its pixels (wrapping a message's buffer) is copied.
  if (!unused) st.held[index] = frame.u != nullptr ? frame : frame.clone();
  return Status::Ok();
}

Status Decoder::Add(int index, const cv::Mat& frame) {
  const Status s = Store(index, frame);
  if (s.ok()) Digest();
  return s;
}

int Decoder::Received() const { return stream_->count; }

size_t Decoder::HeldFrameBytes() const {
  size_t bytes = 0;
  for (const cv::Mat& m : stream_->held) bytes += m.total() * m.elemSize();
  return bytes;
}

void Decoder::Mend(FramePairCheck* check, int16_t margin, int16_t min_direct, int16_t floor_dn) {
  Stream& st = *stream_;
  const int width = st.size.width;
  const cv::Mat& pattern = st.held[check->pattern];
  const cv::Mat& inverse = st.held[check->inverse];
  FramePairCheck looked = *check;
  looked.lit = looked.disagree = 0;
  std::mutex mutex;
  cv::parallel_for_(cv::Range(0, st.size.height), [&](const cv::Range& range) {
    FramePairCheck part;
    for (int y = range.start; y < range.end; ++y) {
      PairDisagreement<true>(pattern.ptr<uint8_t>(y), inverse.ptr<uint8_t>(y),
                             st.held[st.black].ptr<uint8_t>(y), st.held[st.white].ptr<uint8_t>(y),
                             st.direct.ptr<int16_t>(y), st.global.ptr<int16_t>(y), min_direct,
                             floor_dn, width, &part.lit, &part.disagree, &part.off_pattern,
                             &part.off_inverse, &part.alike);
    }
    const std::lock_guard<std::mutex> lock(mutex);
    looked.lit += part.lit;
    looked.disagree += part.disagree;
    looked.off_pattern += part.off_pattern;
    looked.off_inverse += part.off_inverse;
    looked.alike += part.alike;
  });
  *check = looked;
  // A frame of the light estimate's (the finest bits) has shaped the direct and global light
  // every bit is judged by: leaving it out of one bit would not mend the others. Named only.
  for (int k : st.high_frequency) {
    if (k == check->pattern || k == check->inverse) return;
  }
  // The frame to leave out: the one off the light's levels at a good part of the disagreeing
  // pixels and at several times the other's; else, the two alike at nearly all of them, the
  // later shown (the sequence is shown in its order). Otherwise the redundancy does not tell.
  const int64_t n = check->disagree;
  if (check->off_pattern > n / 4 && check->off_pattern > 3 * check->off_inverse) {
    check->left_out = check->pattern;
  } else if (check->off_inverse > n / 4 && check->off_inverse > 3 * check->off_pattern) {
    check->left_out = check->inverse;
  } else if (check->Share() > 0.75 && check->alike > n * 9 / 10) {
    // The two alike wherever lit (another pattern differs from the right one at half the
    // pixels at most): one frame shows its pair's pattern.
    check->left_out = std::max(check->pattern, check->inverse);
    check->shows_pair = true;
  }
  if (check->left_out < 0) return;
  // The bit again, from the frame kept alone, as a code without inverses is decoded: against
  // white + black - kept, the frame its pair would have been. (Everywhere, not only where the
  // two disagree: where a wrong frame passes for its pair's complement at a dim pixel, the pair
  // is less sure than the frame alone, and the decode rejected 15 times the pixels.)
  const AxisPlan& plan = st.axes[check->axis];
  const int b = check->bit;
  const bool keep_pattern = check->left_out == check->inverse;
  const uint16_t votes = b >= kFirstVotingBit ? 1 : 0;
  cv::parallel_for_(cv::Range(0, st.size.height), [&](const cv::Range& range) {
    std::vector<uint8_t> made(width);
    for (int y = range.start; y < range.end; ++y) {
      const uint8_t* p = pattern.ptr<uint8_t>(y);
      const uint8_t* q = inverse.ptr<uint8_t>(y);
      const uint8_t* black = st.held[st.black].ptr<uint8_t>(y);
      const int16_t* direct = st.direct.ptr<int16_t>(y);
      const int16_t* global = st.global.ptr<int16_t>(y);
      uint16_t* code = st.code[check->axis].ptr<uint16_t>(y);
      uint16_t* uncertain = st.uncertain[check->axis].ptr<uint16_t>(y);
      ClassifyBit<true>(p, q, black, direct, global, margin, min_direct, votes, b - plan.first_bit,
                        code, uncertain, width);
      const uint8_t* kept = keep_pattern ? p : q;
      const uint8_t* white = st.held[st.white].ptr<uint8_t>(y);
      for (int x = 0; x < width; ++x) {
        made[x] = static_cast<uint8_t>(std::clamp(white[x] + black[x] - kept[x], 0, 255));
      }
      ClassifyBit<false>(keep_pattern ? p : made.data(), keep_pattern ? made.data() : q, black,
                         direct, global, margin, min_direct, votes, b - plan.first_bit, code,
                         uncertain, width);
    }
  });
}

int16_t Decoder::PairFloor(int16_t min_direct) const {
  const Stream& st = *stream_;
  const int16_t expected = static_cast<int16_t>(std::ceil(6.0 * options_.noise_dn));
  if (st.high_frequency.size() < 2 || st.high_frequency[0] == st.white) return expected;
  // Each finest pair's median |pattern + inverse - white - black| over the lit pixels of every
  // eighth row (a sound pair's is the noise of four frames: 0.67 of its standard deviation); the
  // least of them, so one wrong frame among them does not raise it.
  double least = std::numeric_limits<double>::infinity();
  std::array<int, 512> counts;  // |p + q - w - b| lies in [0, 510].
  for (size_t k = 0; k + 1 < st.high_frequency.size(); k += 2) {
    const cv::Mat& pattern = st.held[st.high_frequency[k]];
    const cv::Mat& inverse = st.held[st.high_frequency[k + 1]];
    if (pattern.empty() || inverse.empty()) continue;
    counts.fill(0);
    int n = 0;
    for (int y = 0; y < st.size.height; y += 8) {
      const uint8_t* p = pattern.ptr<uint8_t>(y);
      const uint8_t* q = inverse.ptr<uint8_t>(y);
      const uint8_t* w = st.held[st.white].ptr<uint8_t>(y);
      const uint8_t* b = st.held[st.black].ptr<uint8_t>(y);
      for (int x = 0; x < st.size.width; ++x) {
        if (w[x] - b[x] < min_direct || p[x] == 255 || q[x] == 255 || w[x] == 255) continue;
        ++counts[std::abs(p[x] + q[x] - w[x] - b[x])];
        ++n;
      }
    }
    if (n < 1000) continue;
    // The median, read within its bin (value m stands for [m - 0.5, m + 0.5)).
    int m = 0, below = 0;
    while (2 * (below + counts[m]) < n) below += counts[m++];
    const double median = std::max(0.0, m - 0.5 + (0.5 * n - below) / std::max(1, counts[m]));
    least = std::min(least, median);
  }
  if (!std::isfinite(least)) return expected;
  // Three standard deviations of the sum, as six times noise_dn is for the noise expected.
  const double sigma = 1.4826 * least;
  return static_cast<int16_t>(std::max<double>(expected, std::ceil(3 * sigma)));
}

void Decoder::Digest() {
  Stream& st = *stream_;
  if (!st.status.ok()) return;
  const bool do_light = !st.light_ready && st.LightInputsIn();
  const bool light = st.light_ready || do_light;
  struct BitJob {
    int axis, bit;
  };
  struct PhaseJob {
    int axis, step;
  };
  std::vector<BitJob> bits;
  std::vector<PhaseJob> phases;
  for (int a = 0; a < 2; ++a) {
    const AxisPlan& plan = st.axes[a];
    for (int b = plan.first_bit; light && b < plan.bits; ++b) {
      if (!st.bit_done[a][b] && st.BitInputsIn(plan, b)) bits.push_back({a, b});
    }
    for (int k = 0; k < plan.steps; ++k) {
      if (!st.phase_done[a][k] && st.Has(plan.phase[k])) phases.push_back({a, k});
    }
  }
  if (!do_light && bits.empty() && phases.empty()) return;
  const int width = st.size.width;
  const int16_t margin = static_cast<int16_t>(std::ceil(options_.uncertain_bit_dn));
  const int16_t min_direct = static_cast<int16_t>(std::ceil(options_.min_contrast_dn));
  if (st.pair_floor_dn == 0 && light && st.Has(st.white)) {
    st.pair_floor_dn = PairFloor(min_direct);
  }
  const int16_t floor_dn = st.pair_floor_dn;
  std::mutex pair_mutex;
  std::vector<std::pair<int64_t, int64_t>> pair_counts(bits.size());
  // One pass over the rows takes up every frame that can be: with a whole scan at hand, that
  // is all of them, row by row in cache.
  cv::parallel_for_(cv::Range(0, st.size.height), [&](const cv::Range& range) {
    std::vector<uint8_t> lmax(width), lmin(width), made(width);
    std::vector<std::pair<int64_t, int64_t>> counts(bits.size(), {0, 0});
    for (int y = range.start; y < range.end; ++y) {
      const uint8_t* black = st.held[st.black].ptr<uint8_t>(y);
      int16_t* direct = st.direct.ptr<int16_t>(y);
      int16_t* global = st.global.ptr<int16_t>(y);
      if (do_light) {
        std::fill(lmax.begin(), lmax.end(), 0);
        std::fill(lmin.begin(), lmin.end(), 255);
        for (int index : st.high_frequency) {
          const uint8_t* f = st.held[index].ptr<uint8_t>(y);
          for (int x = 0; x < width; ++x) {
            lmax[x] = std::max(lmax[x], f[x]);
            lmin[x] = std::min(lmin[x], f[x]);
          }
        }
        LightFromExtremes(lmax.data(), lmin.data(), black, direct, global, width);
      }
      for (size_t j = 0; j < bits.size(); ++j) {
        const BitJob& job = bits[j];
        const AxisPlan& plan = st.axes[job.axis];
        const uint8_t* p = st.held[plan.pattern[job.bit]].ptr<uint8_t>(y);
        const uint8_t* q = nullptr;
        const uint8_t* white = st.held[st.white].ptr<uint8_t>(y);
        if (plan.inverse[job.bit] >= 0) {
          q = st.held[plan.inverse[job.bit]].ptr<uint8_t>(y);
          PairDisagreement<false>(p, q, black, white, direct, global, min_direct, floor_dn, width,
                                  &counts[j].first, &counts[j].second);
        } else {
          // No inverse pattern: the one it would have given, white + black - pattern, so the
          // bit is judged against the middle of the white and black frames.
          for (int x = 0; x < width; ++x) {
            made[x] = static_cast<uint8_t>(std::clamp(white[x] + black[x] - p[x], 0, 255));
          }
          q = made.data();
        }
        ClassifyBit<false>(p, q, black, direct, global, margin, min_direct,
                           job.bit >= kFirstVotingBit ? 1 : 0, job.bit - plan.first_bit,
                           st.code[job.axis].ptr<uint16_t>(y),
                           st.uncertain[job.axis].ptr<uint16_t>(y), width);
      }
      for (const PhaseJob& job : phases) {
        const AxisPlan& plan = st.axes[job.axis];
        AccumulatePhase(st.held[plan.phase[job.step]].ptr<uint8_t>(y), plan.cos_k[job.step],
                        plan.sin_k[job.step], st.cos_sum[job.axis].ptr<int32_t>(y),
                        st.sin_sum[job.axis].ptr<int32_t>(y), width);
      }
    }
    const std::lock_guard<std::mutex> lock(pair_mutex);
    for (size_t j = 0; j < bits.size(); ++j) {
      pair_counts[j].first += counts[j].first;
      pair_counts[j].second += counts[j].second;
    }
  });
  for (size_t j = 0; j < bits.size(); ++j) {
    const AxisPlan& plan = st.axes[bits[j].axis];
    if (plan.inverse[bits[j].bit] < 0) continue;
    FramePairCheck check;
    check.axis = bits[j].axis;
    check.bit = bits[j].bit;
    check.pattern = plan.pattern[bits[j].bit];
    check.inverse = plan.inverse[bits[j].bit];
    check.lit = pair_counts[j].first;
    check.disagree = pair_counts[j].second;
    if (check.Share() > options_.suspect_pair_share) {
      Mend(&check, margin, min_direct, floor_dn);
    }
    st.pairs.push_back(check);
  }
  // Frames taken up are let go (white and black are kept to the end).
  st.light_ready = light;
  auto let_go = [&](int index) {
    if (index >= 0 && index != st.white && index != st.black) st.held[index].release();
  };
  for (const BitJob& job : bits) {
    st.bit_done[job.axis][job.bit] = 1;
    let_go(st.axes[job.axis].pattern[job.bit]);
    let_go(st.axes[job.axis].inverse[job.bit]);
  }
  for (const PhaseJob& job : phases) {
    st.phase_done[job.axis][job.step] = 1;
    let_go(st.axes[job.axis].phase[job.step]);
  }
}

bool DecodeOptions::Check(std::string* why) const {
  if (min_contrast_dn < 0 || min_modulation_dn < 0 || uncertain_bit_dn < 0) {
    *why = "decode thresholds must not be negative";
    return false;
  }
  if (!(max_unwrap_error > 0 && max_unwrap_error < 0.5)) {
    *why = "max_unwrap_error must lie in (0, 0.5) of a period";
    return false;
  }
  if (smooth_radius_px < 0 || smooth_radius_px > kMaxFitRadius) {
    *why = "smooth_radius_px must lie in [0, " + std::to_string(kMaxFitRadius) + "]";
    return false;
  }
  if (smooth_passes < 1 || noise_dn <= 0 || outlier_sigmas <= 0 || !(curvature_sigmas >= 0)) {
    *why = "smooth_passes must be >= 1, noise_dn and outlier_sigmas > 0, curvature_sigmas >= 0";
    return false;
  }
  if (!(suspect_pair_share > 0 && suspect_pair_share <= 1)) {
    *why = "suspect_pair_share must lie in (0, 1]";
    return false;
  }
  return true;
}

float FastAtan2(float y, float x) { return Atan2Inline(y, x); }

namespace {

// The local fit for a compile-time radius R and plane count N, so the tap loops unroll and the
// loops over x vectorise with every moment held in registers. Rows are processed in strips; a
// ring of 2R + 1 rows of horizontal moments (w, w du, w du^2, w v, w v du per plane) feeds the
// vertical sums, which are solved in place.
// The horizontal moments of row y for LocalLinearFitImpl (w, w du, w du^2, then w v, w v du per
// plane) into `m` (kPlanes rows of `width`), through the padded rows `wpad` and `vpad`. Inlined:
// each of its loops vectorises in place.
template <int R, int N>
[[gnu::always_inline]] inline void HorizontalMoments(const cv::Mat* values, const cv::Mat& weights,
                                                     int y, int width, float* wpad_data,
                                                     float* vpad_data, float* m) {
  const int padded = width + 2 * R;
  const float* w = weights.ptr<float>(y);
  float* wp = wpad_data + R;
  for (int x = 0; x < width; ++x) {
    const float wx = w[x];
    wp[x] = wx > 0 ? wx : 0.0f;
  }
  for (int p = 0; p < N; ++p) {
    const float* v = values[p].ptr<float>(y);
    float* vp = vpad_data + static_cast<size_t>(p) * padded + R;
    for (int x = 0; x < width; ++x) {
      const float wx = w[x], vx = v[x];
      vp[x] = wx > 0 ? wx * vx : 0.0f;
    }
  }
  // One output per loop: each reads a single padded source row, so every loop vectorises.
  auto taps = [&](const float* src, float* dst, int power) {
    for (int x = 0; x < width; ++x) {
      float acc = 0;
#pragma GCC unroll 17
      for (int d = -R; d <= R; ++d) {
        const float c = power == 0 ? 1.0f : (power == 1 ? float(d) : float(d * d));
        acc += src[x + d] * c;
      }
      dst[x] = acc;
    }
  };
  taps(wp, m, 0);
  taps(wp, m + width, 1);
  taps(wp, m + 2 * width, 2);
  for (int p = 0; p < N; ++p) {
    const float* vp = vpad_data + static_cast<size_t>(p) * padded + R;
    taps(vp, m + (3 + 2 * p) * width, 0);
    taps(vp, m + (4 + 2 * p) * width, 1);
  }
}

// One row of LocalLinearFitImpl's output from the 2R + 1 rows of horizontal moments around it
// (`rows`): the vertical sums in chunks, and each pixel's weighted plane's intercept (NaN where
// its weight `w` is 0). Inlined, for the same reason.
template <int R, int N>
[[gnu::always_inline]] inline void FitRow(const float* const* rows, const float* w, int width,
                                          float* out0, float* out1) {
  // Vertical sums in chunks of kChunk pixels, accumulated in L1-resident arrays:
  // S, Su, Sv, Suu, Suv, Svv, then X, Xu, Xv per plane.
  constexpr int kChunk = 64;
  constexpr int kSums = 6 + 3 * N;
  alignas(32) float acc[kSums][kChunk];
  for (int x0 = 0; x0 < width; x0 += kChunk) {
    const int len = std::min(kChunk, width - x0);
    for (int k = 0; k < kSums; ++k) {
      for (int i = 0; i < kChunk; ++i) acc[k][i] = 0.0f;
    }
    for (int d = -R; d <= R; ++d) {
      const float* m = rows[d + R] + x0;
      const float fd = static_cast<float>(d), fd2 = fd * fd;
      const float* m0 = m;
      const float* m1 = m + width;
      const float* m2 = m + 2 * width;
      for (int i = 0; i < len; ++i) {
        acc[0][i] += m0[i];
        acc[1][i] += m1[i];
        acc[2][i] += m0[i] * fd;
        acc[3][i] += m2[i];
        acc[4][i] += m1[i] * fd;
        acc[5][i] += m0[i] * fd2;
      }
      const float* a0 = m + 3 * width;
      const float* a1 = m + 4 * width;
      for (int i = 0; i < len; ++i) {
        acc[6][i] += a0[i];
        acc[7][i] += a1[i];
        acc[8][i] += a0[i] * fd;
      }
      if constexpr (N > 1) {
        const float* b0 = m + 5 * width;
        const float* b1 = m + 6 * width;
        for (int i = 0; i < len; ++i) {
          acc[9][i] += b0[i];
          acc[10][i] += b1[i];
          acc[11][i] += b0[i] * fd;
        }
      }
    }
    for (int i = 0; i < len; ++i) {
      const float S = acc[0][i], Su = acc[1][i], Sv = acc[2][i];
      const float Suu = acc[3][i], Suv = acc[4][i], Svv = acc[5][i];
      // Intercept of the 3x3 weighted normal equations: first row of the adjugate. Float
      // suffices: weights are O(1) and the window coordinates small integers.
      const float c0 = Suu * Svv - Suv * Suv;
      const float c1 = Sv * Suv - Su * Svv;
      const float c2 = Su * Suv - Suu * Sv;
      const float det = S * c0 + Su * c1 + Sv * c2;
      const bool solvable = det > 1e-4f * S * Suu * Svv && S > 0;
      const float inv_det = solvable ? 1.0f / det : 0.0f;
      const float inv_s = 1.0f / std::max(S, 1e-30f);
      const bool keep = w[x0 + i] > 0;
      const float fit0 = solvable ? (c0 * acc[6][i] + c1 * acc[7][i] + c2 * acc[8][i]) * inv_det
                                  : acc[6][i] * inv_s;
      out0[x0 + i] = keep ? fit0 : kNaN;
      if constexpr (N > 1) {
        const float fit1 = solvable ? (c0 * acc[9][i] + c1 * acc[10][i] + c2 * acc[11][i]) * inv_det
                                    : acc[9][i] * inv_s;
        out1[x0 + i] = keep ? fit1 : kNaN;
      }
    }
  }
}

template <int R, int N>
void LocalLinearFitImpl(const cv::Mat* values, const cv::Mat& weights, cv::Mat* fitted) {
  const int width = weights.cols, height = weights.rows;
  constexpr int kPlanes = 3 + 2 * N;
  constexpr int kRing = 2 * R + 1;
  const int strips = (height + kFitStripRows - 1) / kFitStripRows;
  cv::parallel_for_(
      cv::Range(0, strips),
      [&](const cv::Range& strip_range) {
        const int padded = width + 2 * R;
        std::vector<float> wpad(padded, 0.0f), vpad(static_cast<size_t>(N) * padded, 0.0f);
        std::vector<float> ring(static_cast<size_t>(kRing) * kPlanes * width);
        const std::vector<float> zeros(static_cast<size_t>(kPlanes) * width, 0.0f);
        auto ring_row = [&](int y) {
          return &ring[static_cast<size_t>(y % kRing) * kPlanes * width];
        };
        auto horizontal = [&](int y) {
          HorizontalMoments<R, N>(values, weights, y, width, wpad.data(), vpad.data(), ring_row(y));
        };
        for (int strip = strip_range.start; strip < strip_range.end; ++strip) {
          const int y0 = strip * kFitStripRows, y1 = std::min(height, y0 + kFitStripRows);
          for (int y = std::max(0, y0 - R); y < std::min(height, y0 + R); ++y) horizontal(y);
          for (int y = y0; y < y1; ++y) {
            if (y + R < height) horizontal(y + R);
            const float* rows[kRing];  // Local so the unrolled loop below keeps them in registers.
            for (int d = -R; d <= R; ++d) {
              const int yy = y + d;
              rows[d + R] = (yy < 0 || yy >= height) ? zeros.data() : ring_row(yy);
            }
            const float* w = weights.ptr<float>(y);
            float* out0 = fitted[0].ptr<float>(y);
            float* out1 = fitted[N > 1 ? 1 : 0].ptr<float>(y);
            FitRow<R, N>(rows, w, width, out0, out1);
          }
        }
      },
      strips);
}

template <int N>
void LocalLinearFitN(int radius, const cv::Mat* values, const cv::Mat& weights, cv::Mat* fitted) {
  switch (radius) {
    case 1:
      return LocalLinearFitImpl<1, N>(values, weights, fitted);
    case 2:
      return LocalLinearFitImpl<2, N>(values, weights, fitted);
    case 3:
      return LocalLinearFitImpl<3, N>(values, weights, fitted);
    case 4:
      return LocalLinearFitImpl<4, N>(values, weights, fitted);
    case 5:
      return LocalLinearFitImpl<5, N>(values, weights, fitted);
    case 6:
      return LocalLinearFitImpl<6, N>(values, weights, fitted);
    case 7:
      return LocalLinearFitImpl<7, N>(values, weights, fitted);
    case 8:
      return LocalLinearFitImpl<8, N>(values, weights, fitted);
  }
  VELLUM_DEMAND(radius >= 1 && radius <= kMaxFitRadius);
}

}  // namespace

void LocalLinearFit(const std::vector<cv::Mat>& values, const cv::Mat& weights, int radius,
                    std::vector<cv::Mat>* fitted) {
  VELLUM_DEMAND(weights.type() == CV_32F);
  VELLUM_DEMAND(!values.empty() && values.size() <= 2);
  for (const cv::Mat& v : values) {
    VELLUM_DEMAND(v.type() == CV_32F && v.size() == weights.size());
  }
  fitted->resize(values.size());
  for (cv::Mat& f : *fitted) f.create(weights.size(), CV_32F);
  if (values.size() == 1) {
    LocalLinearFitN<1>(radius, values.data(), weights, fitted->data());
  } else {
    LocalLinearFitN<2>(radius, values.data(), weights, fitted->data());
  }
}

void Decoder::Decode(const PatternSequence& sequence, const std::vector<cv::Mat>& frames,
                     DecodeResult* result) {
  result->status = Begin(sequence, frames.empty() ? cv::Size() : frames[0].size());
  if (!result->status.ok()) return;
  if (frames.size() != sequence.patterns.size()) {
    result->status = Status::Error("the scan has " + std::to_string(frames.size()) +
                                   " frames but its pattern sequence has " +
                                   std::to_string(sequence.patterns.size()));
    return;
  }
  // Every frame first; Finish then takes them all up in one pass over the rows.
  for (size_t k = 0; k < frames.size(); ++k) {
    result->status = Store(static_cast<int>(k), frames[k]);
    if (!result->status.ok()) return;
  }
  Finish(result);
}

// The final pass over the rows: each pixel's light (the amplitude, lit and clipped pixels),
// its projector coordinates from the codes and phases, and its fit weight and expected noise
// (weight_, sigma_). Counts the lit and rejected pixels into *stats.
void Decoder::Coordinates(DecodeResult* result, DecodeStats* stats) {
  Stream& st = *stream_;
  const DecodeOptions& options = options_;
  const cv::Size size = st.size;
  const int width = size.width, height = size.height;
  const AxisPlan& col = st.axes[0];
  const AxisPlan& row = st.axes[1];
  const cv::Mat& white = st.held[st.white];
  const cv::Mat& black = st.held[st.black];
  cv::Mat& out_x = result->projector_x;
  cv::Mat& out_y = result->projector_y;
  out_x.create(size, CV_32F);
  out_y.create(size, CV_32F);
  result->amplitude.create(size, CV_32F);
  result->valid.create(size, CV_8U);
  weight_.create(size, CV_32F);
  sigma_.create(size, CV_32F);
  std::atomic<int> lit{0}, saturated{0}, bad_bits{0}, bad_mod{0}, bad_unwrap{0};

  cv::parallel_for_(cv::Range(0, height), [&](const cv::Range& range) {
    RowScratch scratch(width);
    std::vector<uint8_t> on(width);
    std::vector<float> mod_x(width, 0.0f), mod_y(width, 0.0f);
    Counters count;
    auto axis_row = [&](int a, int y, float* coordinate, float* modulation, const float* amp) {
      const AxisPlan& plan = st.axes[a];
      const bool phase = plan.steps > 0;
      CoordinatesRow(plan, st.code[a].ptr<uint16_t>(y), st.uncertain[a].ptr<uint16_t>(y),
                     phase ? st.cos_sum[a].ptr<int32_t>(y) : nullptr,
                     phase ? st.sin_sum[a].ptr<int32_t>(y) : nullptr, options, on.data(), amp,
                     width, &scratch, coordinate, modulation, &count);
    };
    for (int y = range.start; y < range.end; ++y) {
      const uint8_t* wr = white.ptr<uint8_t>(y);
      const uint8_t* br = black.ptr<uint8_t>(y);
      float* amp = result->amplitude.ptr<float>(y);
      const int min_contrast = static_cast<int>(std::ceil(options.min_contrast_dn));
      for (int x = 0; x < width; ++x) {
        const int contrast = static_cast<int>(wr[x]) - static_cast<int>(br[x]);
        amp[x] = 0.5f * static_cast<float>(contrast);
        const bool has_light = contrast >= min_contrast;
        const bool clipped = wr[x] >= options.saturation_dn;
        on[x] = has_light & !clipped;
        count.lit += has_light;
        count.saturated += has_light & clipped;
      }
      float* px = out_x.ptr<float>(y);
      float* py = out_y.ptr<float>(y);
      if (col.present) {
        axis_row(0, y, px, mod_x.data(), amp);
        // A pixel rejected by the column code is not counted again by the row code.
        for (int x = 0; x < width; ++x) on[x] = on[x] & (px[x] == px[x]);
      } else {
        std::fill(px, px + width, kNaN);
      }
      if (row.present) {
        axis_row(1, y, py, mod_y.data(), amp);
        for (int x = 0; x < width; ++x) px[x] = py[x] == py[x] ? px[x] : kNaN;
      } else {
        std::fill(py, py + width, kNaN);
      }
      // Fit weight = signal power of the weaker axis (inverse coordinate variance); sigma = the
      // coordinate noise expected from it.
      float* w = weight_.ptr<float>(y);
      float* sg = sigma_.ptr<float>(y);
      const float* valid_axis = col.present ? px : py;
      for (int x = 0; x < width; ++x) {
        float b = col.present ? mod_x[x] : mod_y[x];
        float s = static_cast<float>(col.present ? col.sigma_scale : row.sigma_scale);
        if (col.present && row.present) {
          b = std::min(mod_x[x], mod_y[x]);
          s = static_cast<float>(std::max(col.sigma_scale / mod_x[x], row.sigma_scale / mod_y[x]));
        } else {
          s = col.steps + row.steps > 0 ? s / b : s;
        }
        if (col.steps + row.steps == 0) {
          // Gray code alone: its quantisation, half a stripe.
          s = 0.5f * static_cast<float>(1 << std::max(col.first_bit, row.first_bit));
        }
        const float rel = b / kReferenceAmplitudeDn;
        const bool valid = valid_axis[x] == valid_axis[x];
        w[x] = valid ? rel * rel : 0.0f;
        sg[x] = valid ? std::max(s, 0.01f) : 1.0f;
      }
    }
    lit += count.lit;
    saturated += count.saturated;
    bad_bits += count.bits;
    bad_mod += count.modulation;
    bad_unwrap += count.unwrap;
  });
  stats->lit = lit;
  stats->rejected_saturated = saturated;
  stats->rejected_bits = bad_bits;
  stats->rejected_modulation = bad_mod;
  stats->rejected_unwrap = bad_unwrap;
}

// The coordinates (`raw`, one per encoded axis) fitted locally (LocalLinearFit, weighted by
// weight_), with robust reweighting and the curvature put back; the fit kept where it agrees
// with the pixel, else the raw decode. Returns the pixels that kept their raw decode.
int Decoder::Smooth(std::vector<cv::Mat>* raw_inout) {
  std::vector<cv::Mat>& raw = *raw_inout;
  const DecodeOptions& options = options_;
  const cv::Size size = stream_->size;
  const int width = size.width, height = size.height;
  std::atomic<int> fallbacks{0};
  const float cut = static_cast<float>(options.outlier_sigmas);
  // Largest |raw - fit| over the axes, in units of the pixel's expected noise (NaN fit: inf).
  // Row y's largest |raw - fit| over the axes, in units of each pixel's expected noise
  // (a NaN fit counts as infinitely far).
  auto residual_row = [&](int y, float* out) {
    const float* sg = sigma_.ptr<float>(y);
    std::fill(out, out + width, 0.0f);
    for (size_t p = 0; p < raw.size(); ++p) {
      const float* r = raw[p].ptr<float>(y);
      const float* f = fit_[p].ptr<float>(y);
      for (int x = 0; x < width; ++x) {
        const float d = std::fabs(r[x] - f[x]);
        out[x] = d == d ? std::max(out[x], d) : std::numeric_limits<float>::infinity();
      }
    }
    for (int x = 0; x < width; ++x) out[x] /= sg[x];
  };
  LocalLinearFit(raw, weight_, options.smooth_radius_px, &fit_);
  // Robust reweighting: a pixel far from its own local fit (a depth step, a bad decode) loses
  // its weight in its neighbours' fits (Tukey biweight).
  for (int pass = 1; pass < options.smooth_passes; ++pass) {
    robust_weight_.create(size, CV_32F);
    cv::parallel_for_(cv::Range(0, height), [&](const cv::Range& range) {
      std::vector<float> res(width);
      for (int y = range.start; y < range.end; ++y) {
        residual_row(y, res.data());
        const float* w = weight_.ptr<float>(y);
        float* rw = robust_weight_.ptr<float>(y);
        for (int x = 0; x < width; ++x) {
          const float u = res[x] / cut;
          const float t = u < 1.0f ? 1.0f - u * u : 0.0f;
          rw[x] = w[x] > 0 ? w[x] * t * t : 0.0f;
        }
      }
    });
    LocalLinearFit(raw, robust_weight_, options.smooth_radius_px, &fit_);
  }
  CorrectCurvature(raw);
  // Keep the fit where it agrees with the pixel; where it does not (a depth step inside the
  // window, or a pixel that lost its robust weight) keep the raw decode: unbiased, noisier.
  cv::parallel_for_(cv::Range(0, height), [&](const cv::Range& range) {
    std::vector<float> res(width);
    int n = 0;
    for (int y = range.start; y < range.end; ++y) {
      residual_row(y, res.data());
      const float* w = weight_.ptr<float>(y);
      for (int x = 0; x < width; ++x) n += (w[x] > 0) & (res[x] > cut);
      for (size_t p = 0; p < raw.size(); ++p) {
        float* r = raw[p].ptr<float>(y);
        const float* f = fit_[p].ptr<float>(y);
        for (int x = 0; x < width; ++x) r[x] = ((w[x] > 0) & (res[x] <= cut)) ? f[x] : r[x];
      }
    }
    fallbacks += n;
  });
  return fallbacks;
}

// Where the surface curves, a plane fitted over the window is biased: the same fit of what it
// left (twicing) puts that back, where it stands out of its own noise (fit_ corrected in
// place). With the phase only: a Gray code's coordinates step by its stripe, and what the fit
// leaves there is the staircase, not a curve.
void Decoder::CorrectCurvature(const std::vector<cv::Mat>& raw) {
  const Stream& st = *stream_;
  const DecodeOptions& options = options_;
  const AxisPlan& col = st.axes[0];
  const AxisPlan& row = st.axes[1];
  const cv::Size size = st.size;
  const int width = size.width, height = size.height;
  // With the phase only: a Gray code's coordinates step by its stripe, and what the fit leaves
  // there is the staircase, not a curve.
  const bool phase = (!col.present || col.steps > 0) && (!row.present || row.steps > 0);
  if (!options.correct_curvature || !phase) return;
  {
    // A plane fitted over the window is biased where the surface curves: it rounds a crease's
    // apex and lowers a ripple's crests by the curvature times the window's second moment.
    // The same fit of what it left (twicing) puts that back: the two together fit a
    // quadratic's value, at some more noise.
    const cv::Mat& w = options.smooth_passes > 1 ? robust_weight_ : weight_;
    residual_.resize(raw.size());
    for (size_t p = 0; p < raw.size(); ++p) residual_[p].create(size, CV_32F);
    cv::parallel_for_(cv::Range(0, height), [&](const cv::Range& range) {
      for (int y = range.start; y < range.end; ++y) {
        const float* wy = w.ptr<float>(y);
        for (size_t p = 0; p < raw.size(); ++p) {
          const float* r = raw[p].ptr<float>(y);
          const float* f = fit_[p].ptr<float>(y);
          float* out = residual_[p].ptr<float>(y);
          for (int x = 0; x < width; ++x) {
            const float d = r[x] - f[x];
            out[x] = (wy[x] > 0) & (d == d) ? d : 0.0f;
          }
        }
      }
    });
    LocalLinearFit(residual_, w, options.smooth_radius_px, &correction_);
    // Only where the correction stands out of its own noise (the fit of a pixel's noise over
    // the window: its expected noise over the window's side): on a flat or gently curved leaf
    // it is that noise, and would only add it.
    const float side = static_cast<float>(2 * options.smooth_radius_px + 1);
    const float least = static_cast<float>(options.curvature_sigmas) / side;
    cv::parallel_for_(cv::Range(0, height), [&](const cv::Range& range) {
      for (int y = range.start; y < range.end; ++y) {
        const float* sg = sigma_.ptr<float>(y);
        for (size_t p = 0; p < raw.size(); ++p) {
          const float* c = correction_[p].ptr<float>(y);
          float* f = fit_[p].ptr<float>(y);
          for (int x = 0; x < width; ++x) f[x] += std::fabs(c[x]) > least * sg[x] ? c[x] : 0.0f;
        }
      }
    });
  }
}

void Decoder::Finish(DecodeResult* result) {
  Stream& st = *stream_;
  const DecodeOptions& options = options_;
  result->stats = DecodeStats();
  result->status = st.status;
  if (!st.status.ok()) return;
  const int n = static_cast<int>(st.received.size());
  if (st.count < n) {
    int first = 0;
    while (st.received[first]) ++first;
    result->status = st.status = Status::Error(
        "frame " + std::to_string(first) + " (pattern '" + Describe(st.sequence.patterns[first]) +
        "') never came: " + std::to_string(st.count) + " of " + std::to_string(n) + " frames");
    return;
  }
  Digest();
  st.status = Status::Error("decode finished; begin the next");
  const cv::Size size = st.size;
  const int width = size.width, height = size.height;
  const AxisPlan& col = st.axes[0];
  const AxisPlan& row = st.axes[1];
  DecodeStats counted;
  Coordinates(result, &counted);
  st.held.assign(n, cv::Mat());  // The white and black frames too: the stream is done.
  cv::Mat& out_x = result->projector_x;
  cv::Mat& out_y = result->projector_y;
  std::vector<cv::Mat> raw;
  if (col.present) raw.push_back(out_x);
  if (row.present) raw.push_back(out_y);
  const int fallbacks = options.smooth_radius_px > 0 ? Smooth(&raw) : 0;
  result->valid = weight_ > 0;
  result->has_columns = col.present;
  result->has_rows = row.present;
  DecodeStats& stats = result->stats;
  stats.pixels = width * height;
  stats.lit = counted.lit;
  stats.valid = cv::countNonZero(result->valid);
  stats.rejected_saturated = counted.rejected_saturated;
  stats.rejected_bits = counted.rejected_bits;
  stats.gray_stripe_px = 1 << std::max(col.first_bit, row.first_bit);
  stats.step_px = col.steps + row.steps == 0 ? stats.gray_stripe_px : 0;
  stats.rejected_modulation = counted.rejected_modulation;
  stats.rejected_unwrap = counted.rejected_unwrap;
  stats.fit_fallbacks = fallbacks;
  stats.pairs = st.pairs;
  std::sort(stats.pairs.begin(), stats.pairs.end(), [](const auto& a, const auto& b) {
    return std::tie(a.axis, a.bit) < std::tie(b.axis, b.bit);
  });
  result->status = Status::Ok();
}

DecodeResult Decode(const PatternSequence& sequence, const std::vector<cv::Mat>& frames,
                    const DecodeOptions& options) {
  Decoder decoder(options);
  DecodeResult result;
  decoder.Decode(sequence, frames, &result);
  return result;
}

}  // namespace vellum
