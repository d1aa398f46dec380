// Structured-light pattern sequences: Gray code (columns and rows, each with its inverse), full
// white and black, and phase-shifted sinusoids that the Gray code unwraps (Brown & Seales 2004,
// section 3.2 uses Gray code; the phase shift adds sub-pixel projector coordinates).
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace vellum {

enum class PatternKind { kWhite, kBlack, kGray, kPhase };
enum class Axis { kColumn, kRow };

const char* ToString(PatternKind kind);
const char* ToString(Axis axis);
bool ParsePatternKind(const std::string& text, PatternKind* kind);
bool ParseAxis(const std::string& text, Axis* axis);

// One projector image of a sequence.
struct PatternSpec {
  PatternKind kind = PatternKind::kWhite;
  Axis axis = Axis::kColumn;  // kGray, kPhase: which projector coordinate it encodes.
  int bit = 0;                // kGray: bit of the reflected Gray code, 0 = finest.
  bool inverted = false;      // kGray: the inverse of the bit pattern.
  int step = 0;               // kPhase: shift index k, phase offset 2 pi k / steps.
  int steps = 0;              // kPhase: number of shifts N.
  int period_px = 0;          // kPhase: sinusoid period, projector pixels.

  bool operator==(const PatternSpec& other) const;
};

struct PatternOptions {
  cv::Size projector_size{1024, 768};  // Projector image size, pixels; any size, not only 2^n.
  bool columns = true;                 // Encode projector columns.
  bool rows = true;                    // Encode projector rows.
  int phase_steps = 8;                 // Phase shifts per axis; 0 = Gray code only.
  int phase_period_px = 16;            // Sinusoid period, projector pixels (>= 4).
  // Other rigs' sequences: Gray code without inverse patterns (bits thresholded against the
  // white and black frames), and one that leaves out its finest bits (stripes of 2^skip px).
  bool gray_inverses = true;
  int gray_skip_bits = 0;

  bool Check(std::string* why) const;
};

// The ordered list of projector images of one scan.
struct PatternSequence {
  cv::Size projector_size;
  std::vector<PatternSpec> patterns;

  bool Check(std::string* why) const;
  // Index of the first pattern matching the predicate fields, or -1.
  int Find(PatternKind kind, Axis axis = Axis::kColumn, int bit = 0, bool inverted = false,
           int step = 0) const;
  // Number of Gray-code bits present for an axis (0 if the axis is not encoded): the finest
  // coded bit is FirstGrayBit, the coarsest GrayBits - 1.
  int GrayBits(Axis axis) const;
  // The finest Gray bit present (0 unless the sequence leaves out its finest bits): the code
  // tells stripes of 2^FirstGrayBit projector pixels apart.
  int FirstGrayBit(Axis axis) const;
  // The Gray code of an axis comes with inverse patterns (all of its bits have one).
  bool GrayInverses(Axis axis) const;
  // Phase steps and period for an axis; steps 0 if no phase patterns for it.
  int PhaseSteps(Axis axis) const;
  int PhasePeriod(Axis axis) const;
};

// A pattern in words, for messages: "gray column bit 3 inverse", "phase row step 2 of 8".
std::string Describe(const PatternSpec& spec);

// The largest projector extent a sequence may describe (a 2^16-pixel-wide projector is far
// beyond any made; larger claims are refused before any loop runs over them).
constexpr int kMaxProjectorExtent = 1 << 16;

// Bits needed to give every one of `extent` projector columns (or rows) its own code.
int GrayBitsFor(int extent);

PatternSequence MakePatternSequence(const PatternOptions& options);

// The 8-bit projector image for one pattern, in the virtual (unmirrored) projector's frame.
cv::Mat RenderPattern(const PatternSpec& spec, cv::Size projector_size);

}  // namespace vellum
