#include "pipeline/qc.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace vellum {
namespace {

std::string Percent(double share) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.1f%%", 100 * share);
  return buf;
}

// FADGI's star levels for manuscripts as vellum reads them: sampling (ppi, met by 95% of the
// page within the tolerance), bits per channel, and reproduction scale error (%); the 4-star
// row is the one we quote (400 ppi, 16 bits, 1%). Check against the edition in force.
struct FadgiLevel {
  int stars;
  double ppi, ppi_tolerance, bits, scale_error_percent;
};
constexpr FadgiLevel kFadgiLevels[] = {
    {4, 400, 0.01, 16, 1}, {3, 400, 0.02, 8, 2}, {2, 300, 0.03, 8, 3}, {1, 300, 0.05, 8, 5}};

// The most stars whose level `meets` holds, 0 if none.
template <typename Meets>
int Stars(Meets meets) {
  for (const FadgiLevel& level : kFadgiLevels)
    if (meets(level)) return level.stars;
  return 0;
}

const FadgiLevel* LevelOf(int stars) {
  for (const FadgiLevel& level : kFadgiLevels)
    if (level.stars == stars) return &level;
  return nullptr;
}

// The check named `name` of `qc`, added (passing, with `detail`) if it is not there.
QcCheck& CheckNamed(QcResult* qc, const std::string& name, const std::string& detail) {
  for (QcCheck& c : qc->checks)
    if (c.name == name) return c;
  qc->checks.push_back({name, QcVerdict::kPass, detail, ""});
  return qc->checks.back();
}

// A figure short of the target: its check fails, saying by how much.
void FallsShort(QcResult* qc, const std::string& check, const std::string& why) {
  QcCheck& c = CheckNamed(qc, check, "");
  c.verdict = QcVerdict::kFail;
  c.detail += (c.detail.empty() ? "" : "; ") + why;
  c.shortfall += (c.shortfall.empty() ? "" : "; ") + why;
  qc->verdict = QcVerdict::kFail;
}

// The station's target (report.target): each page's true sampling, bit depth and (for a FADGI
// level) scale error against it. A figure short of it fails the check named after it
// ("sampling", "bit depth", "scale error"), saying what the target asks; one that meets it says
// so.
void JudgeTarget(const ProcessReport& report, QcResult* qc) {
  const QcTarget& t = report.target;
  const FadgiLevel* level = LevelOf(t.fadgi_stars);
  const std::string target = "the target (" + t.Describe() + ")";
  char text[200];
  for (const std::string& page : report.Pages()) {
    if (!report.Find("restored", "dpi", page)) continue;
    const std::string which = page.empty() ? "" : page + " page: ";
    // Sampling: the page's true sampling at 95% of it.
    const double want_ppi = std::max(t.ppi, level ? level->ppi * (1 - level->ppi_tolerance) : 0.0);
    if (want_ppi > 0) {
      if (!report.Find("sampling", "p5_ppi", page)) {
        FallsShort(qc, "sampling",
                   which + target + " asks " +
                       std::to_string(static_cast<int>(std::lround(want_ppi))) +
                       " ppi at a true scale");
      } else if (const double p5 = report.Number("sampling", "p5_ppi", page); p5 < want_ppi) {
        std::snprintf(text, sizeof(text), "%s%.0f ppi at 95%% of the page; %s asks %.0f",
                      which.c_str(), p5, target.c_str(), want_ppi);
        FallsShort(qc, "sampling", text);
      }
    }
    // Bit depth: the master's samples.
    const int want_bits = std::max(t.bits, level ? static_cast<int>(level->bits) : 0);
    if (want_bits > 0) {
      const double bits = report.Number("restored", "bits_per_channel", page);
      std::snprintf(text, sizeof(text), "%.0f bits per channel", bits);
      QcCheck& c = CheckNamed(qc, "bit depth", std::string(text) + ", as " + target + " asks");
      if (bits < want_bits) {
        if (c.verdict == QcVerdict::kPass) c.detail.clear();  // A spread's other page kept.
        FallsShort(qc, "bit depth",
                   which + text + "; " + target + " asks " + std::to_string(want_bits));
      }
    }
    // Scale error, for a FADGI level.
    if (level) {
      QcCheck& c = CheckNamed(qc, "scale error", "within " + target);
      if (!report.Find("restored", "scale_error_percent", page)) {
        if (c.verdict == QcVerdict::kPass) c.detail.clear();
        FallsShort(qc, "scale error", which + "no true scale (camera view)");
      } else if (const double e = report.Number("restored", "scale_error_percent", page);
                 e > level->scale_error_percent) {
        std::snprintf(text, sizeof(text), "%s%.3f%%; %s asks %.0f%% at most", which.c_str(), e,
                      target.c_str(), level->scale_error_percent);
        if (c.verdict == QcVerdict::kPass) c.detail.clear();
        FallsShort(qc, "scale error", text);
      }
    }
  }
}

}  // namespace

std::vector<FadgiPage> AssessFadgi(const ProcessReport& report) {
  std::vector<FadgiPage> out;
  for (const std::string& page : report.Pages()) {
    if (!report.Find("restored", "dpi", page)) continue;
    FadgiPage p;
    p.page = page;
    char text[96];
    const bool true_scale = report.Find("sampling", "p5_ppi", page) != nullptr;
    FadgiFigure sampling{"sampling", "no true scale (camera view)", 0, "the warp's Jacobian"};
    if (true_scale) {
      const double p5 = report.Number("sampling", "p5_ppi", page);
      std::snprintf(text, sizeof(text), "%.0f ppi at 95%% of the page (median %.0f)", p5,
                    report.Number("sampling", "median_ppi", page));
      sampling.value = text;
      sampling.stars =
          Stars([&](const FadgiLevel& l) { return p5 >= l.ppi * (1 - l.ppi_tolerance); });
      sampling.basis =
          "the camera's true sampling of the page, from the warp's Jacobian (sampling_ppi.tif)";
    }
    p.figures.push_back(sampling);
    const double bits = report.Number("restored", "bits_per_channel", page);
    std::snprintf(text, sizeof(text), "%.0f bits per channel", bits);
    p.figures.push_back({"bit depth", text,
                         Stars([&](const FadgiLevel& l) { return bits >= l.bits; }),
                         "the restored master's samples, as the camera gave them"});
    FadgiFigure scale{"scale error", "no true scale (camera view)", 0, ""};
    if (report.Find("restored", "scale_error_percent", page)) {
      const double error = report.Number("restored", "scale_error_percent", page);
      std::snprintf(text, sizeof(text), "%.3f%%", error);
      scale.value = text;
      scale.stars = Stars([&](const FadgiLevel& l) { return error <= l.scale_error_percent; });
      scale.basis =
          report.Find("restored", "scale_error_calibration_percent", page)
              ? "the calibration's measured scale error (vellum calibrate, on its board) plus the "
                "flattening's mean relative length error"
              : "the flattening's mean relative length error; the calibration's own is not "
                "known (its file has no scale_error_percent: vellum calibrate measures it)";
    }
    p.figures.push_back(scale);
    p.stars = 4;
    for (const FadgiFigure& f : p.figures) p.stars = std::min(p.stars, f.stars);
    out.push_back(p);
  }
  return out;
}

const char* VerdictName(QcVerdict verdict) {
  switch (verdict) {
    case QcVerdict::kPass:
      return "pass";
    case QcVerdict::kWarn:
      return "warn";
    case QcVerdict::kFail:
      return "fail";
  }
  return "fail";
}

QcResult AssessQuality(const ProcessReport& report, const QcLimits& limits) {
  const std::vector<Warning> warnings = report.Warnings();
  QcResult qc;
  // A check: its verdict from the warnings with `warn_codes` / `fail_codes` (their messages
  // become its detail) and from `figure_fails`; `figure` is the detail when all is well.
  auto check = [&](const std::string& name, const std::vector<std::string>& warn_codes,
                   const std::vector<std::string>& fail_codes, bool figure_fails,
                   const std::string& figure) {
    QcCheck c;
    c.name = name;
    c.verdict = figure_fails ? QcVerdict::kFail : QcVerdict::kPass;
    std::string said;
    for (const Warning& w : warnings) {
      const bool fails =
          std::find(fail_codes.begin(), fail_codes.end(), w.code) != fail_codes.end();
      const bool warns =
          std::find(warn_codes.begin(), warn_codes.end(), w.code) != warn_codes.end();
      if (!fails && !warns) continue;
      c.verdict = std::max(c.verdict, fails ? QcVerdict::kFail : QcVerdict::kWarn);
      said += (said.empty() ? "" : "; ") + w.message;
    }
    c.detail = figure + (said.empty() ? "" : ": " + said);
    if (figure_fails) c.shortfall = figure;
    qc.verdict = std::max(qc.verdict, c.verdict);
    qc.checks.push_back(c);
  };
  const bool has_outline = report.Find("outline", "leaf_pixels") != nullptr;
  check("leaf in view", {"seen_off_view"}, {"page_cut_off"}, false,
        report.Number("outline", "touches_border") > 0 ? "the leaf touches the view's edge"
                                                       : "the leaf lies inside the view");
  const double valid = report.Number("outline", "valid_in_leaf");
  check("measured", {"valid_low", "gutter_hidden", "edge_unmeasured", "edge_on"}, {},
        has_outline && valid < limits.fail_valid_in_leaf,
        Percent(valid) + " of the leaf measured in 3D");
  std::string strain;
  for (const std::string& page : report.Pages()) {
    char buf[160];
    std::snprintf(buf, sizeof(buf), "%s%sstrain mean %.2g, max %.2g, %g folded quads",
                  strain.empty() ? "" : "; ", page.empty() ? "" : (page + " page: ").c_str(),
                  report.Number("flattening", "mean_strain", page),
                  report.Number("flattening", "max_strain", page),
                  report.Number("flattening", "folded_quads", page));
    strain += buf;
  }
  check("flattening", {"strain_high"}, {"fold_over"}, false, strain);
  check("outline", {"outline_uncertain", "leaf_ambiguous", "object_ambiguous"}, {}, false,
        Percent(report.Number("outline", "confidence")) + " of the rim set apart (" +
            report.Text("outline", "method") + ")");
  const double high = report.Number("exposure", "clipped_highlights");
  const double low = report.Number("exposure", "clipped_shadows");
  check("exposure", {"exposure_clipped"}, {}, std::max(high, low) > limits.fail_clipped,
        Percent(high) + " of the leaf clipped white, " + Percent(low) + " black");
  char size[96] = "no leaf size";
  for (const std::string& page : report.Pages()) {
    if (report.Find("restored", "leaf_width_mm", page)) {
      std::snprintf(size, sizeof(size), "leaf %.1f x %.1f mm",
                    report.Number("restored", "leaf_width_mm", page),
                    report.Number("restored", "leaf_height_mm", page));
      break;
    }
  }
  check("scale", {"size_unexpected"}, {}, false, size);
  char sampling[96] = "no true scale";
  for (const std::string& page : report.Pages()) {
    if (report.Find("sampling", "median_ppi", page)) {
      std::snprintf(sampling, sizeof(sampling),
                    "written at %.0f dpi, truly sampled at %.0f ppi at the finest (median %.0f)",
                    report.Number("restored", "dpi", page),
                    report.Number("sampling", "p95_ppi", page),
                    report.Number("sampling", "median_ppi", page));
      break;
    }
  }
  check("sampling", {"dpi_above_sampling"}, {}, false, sampling);
  if (report.target.any()) JudgeTarget(report, &qc);
  // Whatever the run wrote (`--until points` too): the point cloud's own soundness.
  if (report.Find("pixels", "points_of_lit")) {
    check("points", {"decode_low", "frame_contradicts"}, {}, false,
          Percent(report.Number("pixels", "points_of_lit")) +
              " of the pixels the projector lit gave a 3D point");
  }
  return qc;
}

}  // namespace vellum
