#include "core/patterns/patterns.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "core/common/check.h"

namespace vellum {

const char* ToString(PatternKind kind) {
  switch (kind) {
    case PatternKind::kWhite:
      return "white";
    case PatternKind::kBlack:
      return "black";
    case PatternKind::kGray:
      return "gray";
    case PatternKind::kPhase:
      return "phase";
  }
  return "?";
}

const char* ToString(Axis axis) { return axis == Axis::kColumn ? "column" : "row"; }

bool ParsePatternKind(const std::string& text, PatternKind* kind) {
  for (PatternKind k :
       {PatternKind::kWhite, PatternKind::kBlack, PatternKind::kGray, PatternKind::kPhase}) {
    if (text == ToString(k)) {
      *kind = k;
      return true;
    }
  }
  return false;
}

bool ParseAxis(const std::string& text, Axis* axis) {
  if (text == "column") {
    *axis = Axis::kColumn;
  } else if (text == "row") {
    *axis = Axis::kRow;
  } else {
    return false;
  }
  return true;
}

bool PatternSpec::operator==(const PatternSpec& o) const {
  return kind == o.kind && axis == o.axis && bit == o.bit && inverted == o.inverted &&
         step == o.step && steps == o.steps && period_px == o.period_px;
}

bool PatternOptions::Check(std::string* why) const {
  if (projector_size.width < 2 || projector_size.height < 2) {
    *why = "projector size must be at least 2x2 pixels";
    return false;
  }
  if (!columns && !rows) {
    *why = "at least one of columns and rows must be encoded";
    return false;
  }
  if (phase_steps != 0 && phase_steps < 3) {
    *why = "phase_steps must be 0 (Gray code only) or at least 3";
    return false;
  }
  if (phase_steps != 0 && phase_period_px < 4) {
    *why = "phase_period_px must be at least 4 projector pixels";
    return false;
  }
  if (projector_size.width > kMaxProjectorExtent || projector_size.height > kMaxProjectorExtent) {
    *why = "projector size above " + std::to_string(kMaxProjectorExtent) + " pixels";
    return false;
  }
  const int bits = std::min(GrayBitsFor(projector_size.width), GrayBitsFor(projector_size.height));
  if (gray_skip_bits < 0 || gray_skip_bits >= bits) {
    *why = "gray_skip_bits must leave at least one Gray bit";
    return false;
  }
  if (phase_steps != 0 && 5 * (1 << gray_skip_bits) > 2 * phase_period_px) {
    *why =
        "with phase patterns, the Gray code's stripes (2^gray_skip_bits px) must stay within "
        "0.4 of the phase period to unwrap it";
    return false;
  }
  return true;
}

int GrayBitsFor(int extent) {
  int bits = 0;
  while (bits < 31 && (int64_t{1} << bits) < extent) ++bits;
  return bits;
}

std::string Describe(const PatternSpec& s) {
  std::string d = ToString(s.kind);
  if (s.kind == PatternKind::kGray) {
    d += std::string(" ") + ToString(s.axis) + " bit " + std::to_string(s.bit) +
         (s.inverted ? " inverse" : "");
  } else if (s.kind == PatternKind::kPhase) {
    d += std::string(" ") + ToString(s.axis) + " step " + std::to_string(s.step) + " of " +
         std::to_string(s.steps);
  }
  return d;
}

PatternSequence MakePatternSequence(const PatternOptions& options) {
  std::string why;
  VELLUM_DEMAND(options.Check(&why));
  PatternSequence seq;
  seq.projector_size = options.projector_size;
  auto& p = seq.patterns;
  p.push_back({PatternKind::kWhite});
  p.push_back({PatternKind::kBlack});
  // Gray code finest bit first, the axes taking turns: the decoder's light estimate needs the
  // finest bits of both axes, and once it has them every later frame is taken up as it comes
  // (Decoder::Add), so a scan is decoded while it is captured in memory that does not grow
  // with its frames.
  int most_bits = 0;
  for (Axis axis : {Axis::kColumn, Axis::kRow}) {
    const bool on = axis == Axis::kColumn ? options.columns : options.rows;
    const int extent =
        axis == Axis::kColumn ? options.projector_size.width : options.projector_size.height;
    if (on) most_bits = std::max(most_bits, GrayBitsFor(extent));
  }
  for (int bit = options.gray_skip_bits; bit < most_bits; ++bit) {
    for (Axis axis : {Axis::kColumn, Axis::kRow}) {
      const bool on = axis == Axis::kColumn ? options.columns : options.rows;
      const int extent =
          axis == Axis::kColumn ? options.projector_size.width : options.projector_size.height;
      if (!on || bit >= GrayBitsFor(extent)) continue;
      for (bool inverted : {false, true}) {
        if (inverted && !options.gray_inverses) continue;
        PatternSpec s;
        s.kind = PatternKind::kGray;
        s.axis = axis;
        s.bit = bit;
        s.inverted = inverted;
        p.push_back(s);
      }
    }
  }
  if (options.phase_steps > 0) {
    for (Axis axis : {Axis::kColumn, Axis::kRow}) {
      if ((axis == Axis::kColumn && !options.columns) || (axis == Axis::kRow && !options.rows)) {
        continue;
      }
      for (int k = 0; k < options.phase_steps; ++k) {
        PatternSpec s;
        s.kind = PatternKind::kPhase;
        s.axis = axis;
        s.step = k;
        s.steps = options.phase_steps;
        s.period_px = options.phase_period_px;
        p.push_back(s);
      }
    }
  }
  return seq;
}

bool PatternSequence::Check(std::string* why) const {
  if (projector_size.width < 2 || projector_size.height < 2) {
    *why = "projector size must be at least 2x2 pixels";
    return false;
  }
  if (projector_size.width > kMaxProjectorExtent || projector_size.height > kMaxProjectorExtent) {
    *why = "projector size " + std::to_string(projector_size.width) + "x" +
           std::to_string(projector_size.height) + " is above " +
           std::to_string(kMaxProjectorExtent) + " pixels";
    return false;
  }
  for (const PatternSpec& s : patterns) {
    if (s.kind == PatternKind::kGray && (s.bit < 0 || s.bit >= 31)) {
      *why = "a Gray pattern's bit " + std::to_string(s.bit) + " is out of range";
      return false;
    }
    // A period, like the projector, within kMaxProjectorExtent: the checks below double it
    // (fuzz/fuzz_files found a scan.yaml's period of 2e9 px overflowing an int).
    if (s.kind == PatternKind::kPhase && (s.period_px < 1 || s.period_px > kMaxProjectorExtent)) {
      *why = "a phase pattern's period of " + std::to_string(s.period_px) + " px is out of range";
      return false;
    }
  }
  if (Find(PatternKind::kWhite) < 0 || Find(PatternKind::kBlack) < 0) {
    *why = "the pattern sequence needs a white and a black pattern";
    return false;
  }
  bool any_axis = false;
  for (Axis axis : {Axis::kColumn, Axis::kRow}) {
    const int bits = GrayBits(axis);
    if (bits == 0) continue;
    any_axis = true;
    const int extent = axis == Axis::kColumn ? projector_size.width : projector_size.height;
    if (bits != GrayBitsFor(extent)) {
      *why = std::string("the ") + ToString(axis) + " Gray code has " + std::to_string(bits) +
             " bits; a projector extent of " + std::to_string(extent) + " needs " +
             std::to_string(GrayBitsFor(extent));
      return false;
    }
    // The bits from the finest coded one up, each with its inverse, or none with one.
    const int first = FirstGrayBit(axis);
    const bool inverses = Find(PatternKind::kGray, axis, bits - 1, true) >= 0;
    for (int bit = first; bit < bits; ++bit) {
      if (Find(PatternKind::kGray, axis, bit, false) < 0 ||
          (inverses && Find(PatternKind::kGray, axis, bit, true) < 0)) {
        *why = std::string("the ") + ToString(axis) + " Gray code lacks bit " +
               std::to_string(bit) + (inverses ? " or its inverse" : "");
        return false;
      }
      if (!inverses && Find(PatternKind::kGray, axis, bit, true) >= 0) {
        *why = std::string("the ") + ToString(axis) + " Gray code has an inverse for bit " +
               std::to_string(bit) + " but not for its coarsest bit";
        return false;
      }
    }
    const int steps = PhaseSteps(axis);
    if (steps > 0 && 5 * (1 << first) > 2 * PhasePeriod(axis)) {
      *why = std::string("the ") + ToString(axis) + " Gray code leaves out bits below " +
             std::to_string(first) + ": its stripes of " + std::to_string(1 << first) +
             " px cannot unwrap a phase period of " + std::to_string(PhasePeriod(axis)) + " px";
      return false;
    }
    if (steps > 0) {
      if (steps < 3 || PhasePeriod(axis) < 4) {
        *why = std::string("the ") + ToString(axis) +
               " phase patterns need >= 3 steps and a period >= 4 px";
        return false;
      }
      for (int k = 0; k < steps; ++k) {
        if (Find(PatternKind::kPhase, axis, 0, false, k) < 0) {
          *why = std::string("the ") + ToString(axis) + " phase patterns lack step " +
                 std::to_string(k);
          return false;
        }
      }
    }
  }
  if (!any_axis) {
    *why = "the pattern sequence encodes neither columns nor rows";
    return false;
  }
  for (const PatternSpec& s : patterns) {
    if (s.kind == PatternKind::kPhase &&
        (s.steps != PhaseSteps(s.axis) || s.period_px != PhasePeriod(s.axis))) {
      *why = "phase patterns of one axis must share their steps and period";
      return false;
    }
    if (s.kind == PatternKind::kPhase && GrayBits(s.axis) == 0) {
      *why = "phase patterns need the Gray code of the same axis to unwrap them";
      return false;
    }
  }
  return true;
}

int PatternSequence::Find(PatternKind kind, Axis axis, int bit, bool inverted, int step) const {
  for (size_t i = 0; i < patterns.size(); ++i) {
    const PatternSpec& s = patterns[i];
    if (s.kind != kind) continue;
    if (kind == PatternKind::kWhite || kind == PatternKind::kBlack) return static_cast<int>(i);
    if (s.axis != axis) continue;
    if (kind == PatternKind::kGray && s.bit == bit && s.inverted == inverted) {
      return static_cast<int>(i);
    }
    if (kind == PatternKind::kPhase && s.step == step) return static_cast<int>(i);
  }
  return -1;
}

int PatternSequence::GrayBits(Axis axis) const {
  int bits = 0;
  for (const PatternSpec& s : patterns) {
    if (s.kind == PatternKind::kGray && s.axis == axis) bits = std::max(bits, s.bit + 1);
  }
  return bits;
}

int PatternSequence::FirstGrayBit(Axis axis) const {
  int first = -1;
  for (const PatternSpec& s : patterns) {
    if (s.kind == PatternKind::kGray && s.axis == axis && (first < 0 || s.bit < first)) {
      first = s.bit;
    }
  }
  return std::max(first, 0);
}

bool PatternSequence::GrayInverses(Axis axis) const {
  const int bits = GrayBits(axis);
  return bits > 0 && Find(PatternKind::kGray, axis, bits - 1, true) >= 0;
}

int PatternSequence::PhaseSteps(Axis axis) const {
  for (const PatternSpec& s : patterns) {
    if (s.kind == PatternKind::kPhase && s.axis == axis) return s.steps;
  }
  return 0;
}

int PatternSequence::PhasePeriod(Axis axis) const {
  for (const PatternSpec& s : patterns) {
    if (s.kind == PatternKind::kPhase && s.axis == axis) return s.period_px;
  }
  return 0;
}

cv::Mat RenderPattern(const PatternSpec& spec, cv::Size size) {
  cv::Mat image(size, CV_8U);
  switch (spec.kind) {
    case PatternKind::kWhite:
      image.setTo(255);
      return image;
    case PatternKind::kBlack:
      image.setTo(0);
      return image;
    case PatternKind::kGray:
    case PatternKind::kPhase:
      break;
  }
  const bool columns = spec.axis == Axis::kColumn;
  const int extent = columns ? size.width : size.height;
  // One projector line (a row for column codes, a column for row codes) as a 1D profile.
  std::vector<uint8_t> profile(extent);
  for (int c = 0; c < extent; ++c) {
    if (spec.kind == PatternKind::kGray) {
      const int gray = c ^ (c >> 1);
      const bool lit = ((gray >> spec.bit) & 1) != spec.inverted;
      profile[c] = lit ? 255 : 0;
    } else {
      // Intensity 1/2 + 1/2 cos(2 pi c / P - 2 pi k / N), pixel centres at integer c.
      const double phase =
          2.0 * M_PI *
          (static_cast<double>(c) / spec.period_px - static_cast<double>(spec.step) / spec.steps);
      profile[c] = cv::saturate_cast<uint8_t>(std::lround(127.5 + 127.5 * std::cos(phase)));
    }
  }
  for (int y = 0; y < size.height; ++y) {
    uint8_t* row = image.ptr<uint8_t>(y);
    if (columns) {
      std::copy(profile.begin(), profile.end(), row);
    } else {
      std::fill(row, row + size.width, profile[y]);
    }
  }
  return image;
}

}  // namespace vellum
