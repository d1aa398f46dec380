// What the stages need to know of a scan beyond its images, as a type: who it is, what the
// operator said of it, and the calibration its points were measured with. It is never read back
// from a report, which only records it. `vellum process` builds it from the scan and its
// calibration (ScanContext::For); at the station the decoder builds the scan's part from
// SCAN_STARTED (ScanContext::Of), the triangulator adds the calibration's (MeasuredWith), and it
// travels down the chain with every product (scan_context_t, station/messages.h).
#pragma once

#include <limits>
#include <opencv2/core.hpp>
#include <string>

#include "core/geometry/calibration.h"
#include "core/patterns/scan.h"

namespace vellum {

struct ScanContext {
  ScanIdentity identity;
  cv::Rect leaf_hint;                     // Camera pixels inside the leaf; empty: none.
  ObjectKind object = ObjectKind::kAuto;  // What the operator said lies there.
  int live_off_view = 0;  // ViewSide bits: where the live view saw the leaf run off the view.
  std::string calibration_sha256;  // Of the calibration the points were measured with.
  // That calibration's measured error of every length, %, NaN when not measured.
  double scale_error_percent = std::numeric_limits<double>::quiet_NaN();

  // The scan's own part (identity, leaf hint, object, what the live view saw); the calibration's
  // not yet known.
  static ScanContext Of(const Scan& scan);
  // The whole context: the scan's part, measured with `calibration`.
  static ScanContext For(const Scan& scan, const Calibration& calibration);
  // Sets the calibration's part (its checksum and measured scale error).
  void MeasuredWith(const Calibration& calibration);
};

}  // namespace vellum
