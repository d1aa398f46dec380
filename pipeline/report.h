// The account of one scan's processing: each stage describes itself in a StageReport (the
// options it ran with, the figures it measured, the files it wrote), and the reports merge, in
// pipeline order, into the ProcessReport that report.json and report.html show. `vellum
// process` and the station's daemons fill the same StageReports in the same stage functions
// (pipeline/stages.h); the station carries them down the chain with the products. So both
// write the same report.json, key for key.
#pragma once

#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/patterns/scan.h"

namespace vellum {

// One figure or option, under its report.json section ("options", "pixels", ...).
struct ReportValue {
  std::string section, key;
  bool is_text = false;
  std::string text;   // When is_text.
  double number = 0;  // Otherwise.
};

// Something that makes the result doubtful (docs/formats.md's `warnings`): a code a program can
// test and a sentence for the operator.
struct Warning {
  // page_cut_off, outline_uncertain, valid_low, edge_unmeasured, exposure_clipped, strain_high,
  // fold_over, size_unexpected, dpi_above_sampling, ... (docs/operator.md's quality checks)
  std::string code;
  std::string message;
};

struct StageReport {
  Status status = Status::Error("stage not run");
  std::string stage;                 // decode, triangulate, outline, mesh, flatten, restore
  std::string page;                  // "" for the scan (or its one leaf); "left", "right".
  double seconds = 0;                // Wall time, writing the stage's products included.
  double peak_memory_mb = 0;         // The process's peak resident memory when it ended.
  std::vector<ReportValue> values;   // In the order they were set.
  std::vector<std::string> outputs;  // Files written, relative to the results folder.
  std::vector<Warning> warnings;     // What makes its product doubtful.

  void Text(const std::string& section, const std::string& key, const std::string& value);
  void Number(const std::string& section, const std::string& key, double value);
  void Warn(const std::string& code, const std::string& message);
};

// The collection's target a scan is judged against (the station's config, `--target-*`): a
// FADGI star level for manuscripts, and/or a least true sampling and bit depth. None by default.
struct QcTarget {
  int fadgi_stars = 0;  // 1 to 4; 0: none.
  double ppi = 0;       // The page's true sampling at 95% of it; 0: none.
  int bits = 0;         // Bits per channel of the master; 0: none.
  bool any() const { return fadgi_stars > 0 || ppi > 0 || bits > 0; }
  // "FADGI 3-star, 300 ppi, 16 bits"; "" for none.
  std::string Describe() const;
  bool Check(std::string* why) const;
};

struct ProcessReport {
  std::string scan, calibration;     // Where the input came from.
  QcTarget target;                   // What the scan is judged against besides its own checks.
  std::vector<StageReport> stages;   // In pipeline order.
  std::vector<std::string> outputs;  // The report's own files (report.html, report.json).

  // The value of section/key for `page` (the last stage that set it), or nullptr.
  const ReportValue* Find(const std::string& section, const std::string& key,
                          const std::string& page = "") const;
  double Number(const std::string& section, const std::string& key,
                const std::string& page = "") const;  // 0 if absent.
  std::string Text(const std::string& section, const std::string& key,
                   const std::string& page = "") const;  // "" if absent.
  // The pages, in order ({""} for a single leaf; "left", "right" for a spread).
  std::vector<std::string> Pages() const;
  // Every warning, each message naming its page on a spread.
  std::vector<Warning> Warnings() const;
  // Every file written for the scan: the stages' outputs, in order, then the report's own.
  std::vector<std::string> Outputs() const;
};

// The value of section/key for `page` in `stages` (the last stage that set it), or nullptr;
// ProcessReport::Find over its stages.
const ReportValue* FindValue(const std::vector<StageReport>& stages, const std::string& section,
                             const std::string& key, const std::string& page = "");

// A leaf hint as text, "x,y,width,height" (camera pixels), and back: false unless the text is
// exactly that, x, y >= 0 and width, height > 0.
std::string LeafHintText(const cv::Rect& hint);
bool ParseLeafHint(const std::string& text, cv::Rect* hint);

// Writes report.html (the warnings, the key figures, the pictures the stages wrote to report/,
// the options) and then report.json (every section; on a spread, `pages` holds each page's
// sections; `warnings`; and `outputs`: the files actually written, itself included). `title`
// heads the page.
Status WriteReports(const std::string& dir, const std::string& title, ProcessReport* report);

}  // namespace vellum
