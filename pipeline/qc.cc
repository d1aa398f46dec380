#include "pipeline/qc.h"

#include <algorithm>
#include <cstdio>

namespace vellum {
namespace {

std::string Percent(double share) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.1f%%", 100 * share);
  return buf;
}

}  // namespace

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
    qc.verdict = std::max(qc.verdict, c.verdict);
    qc.checks.push_back(c);
  };
  const bool has_outline = report.Find("outline", "leaf_pixels") != nullptr;
  check("leaf in view", {}, {"page_cut_off"}, false,
        report.Number("outline", "touches_border") > 0 ? "the leaf touches the view's edge"
                                                       : "the leaf lies inside the view");
  const double valid = report.Number("outline", "valid_in_leaf");
  check("measured", {"valid_low"}, {}, has_outline && valid < limits.fail_valid_in_leaf,
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
  check("outline", {"outline_uncertain"}, {}, false,
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
  return qc;
}

}  // namespace vellum
