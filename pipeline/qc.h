// Quality control of a processed scan: pass, warn or fail, from stated checks on its report.
// Each check reads the warnings the stages raised (their limits are WarningLimits, in
// pipeline/stages.h) and, for a fail, the figures against QcLimits below. The scan's verdict is
// its worst check's. It is written to report.json (`qc`) and report.html, carried on RESTORED
// to the viewer, and printed by `vellum process` and `vellum scan`.
//
// The checks:
//  - leaf in view: fail when the leaf runs off the camera's view (page_cut_off); warn when the
//    live view saw it run off when the scan was asked and the outline comes near that side but
//    stays inside (seen_off_view);
//  - measured: warn when less of the leaf was measured in 3D than WarningLimits asks
//    (valid_low), fail below QcLimits::fail_valid_in_leaf;
//  - flattening: warn on strain above its limits (strain_high), fail on fold-over (fold_over);
//  - outline: warn when the leaf's rim is not clearly set apart (outline_uncertain);
//  - exposure: warn when the leaf's pixels clip (exposure_clipped), fail above
//    QcLimits::fail_clipped;
//  - scale: warn when the leaf is not the size expected (size_unexpected);
//  - sampling: warn when the page is written at a dpi above what the camera truly sampled
//    (dpi_above_sampling);
//  - with a target (ProcessReport::target, the station's `--target-*`): fail a page whose true
//    sampling ("sampling"), bit depth ("bit depth") or, for a FADGI level, scale error ("scale
//    error") falls short of it, naming the figure and what the target asks.
#pragma once

#include <string>
#include <vector>

#include "pipeline/report.h"

namespace vellum {

enum class QcVerdict { kPass = 0, kWarn = 1, kFail = 2 };
const char* VerdictName(QcVerdict verdict);  // "pass", "warn", "fail"

struct QcLimits {
  double fail_valid_in_leaf = 0.5;  // Share of the leaf's pixels with a 3D point.
  double fail_clipped = 0.05;       // Share of the leaf's pixels at the camera's maximum or 0.
};

struct QcCheck {
  std::string name;  // "leaf in view", "measured", "flattening", "outline", "exposure", "scale",
                     // "sampling"
  QcVerdict verdict = QcVerdict::kPass;
  std::string detail;  // The figure, or the warnings that set the verdict.
  // What a figure alone fails it by, no warning saying so (a share of the leaf measured or
  // clipped past the limit, a figure short of the collection's target); "" when none does.
  std::string shortfall;
};

struct QcResult {
  QcVerdict verdict = QcVerdict::kPass;
  std::vector<QcCheck> checks;  // In the order above.
};

QcResult AssessQuality(const ProcessReport& report, const QcLimits& limits = QcLimits());

// The FADGI figures vellum can vouch for, for each restored page, and the star level each meets
// (0: below one star). The levels are those of kFadgiLevels in qc.cc, vellum's reading of FADGI's
// Technical Guidelines (2016; 2023 edition) for manuscripts; what FADGI also asks and vellum
// does not measure (tone, colour, noise, MTF: they need a target) is not claimed.
struct FadgiFigure {
  std::string name;   // "sampling", "bit depth", "scale error"
  std::string value;  // The figure, with its unit.
  int stars = 0;
  std::string basis;  // What the figure is measured from.
};
struct FadgiPage {
  std::string page;  // "" for a single leaf; "left", "right".
  std::vector<FadgiFigure> figures;
  int stars = 0;  // The least of its figures'.
};
std::vector<FadgiPage> AssessFadgi(const ProcessReport& report);

}  // namespace vellum
