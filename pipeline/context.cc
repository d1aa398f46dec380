#include "pipeline/context.h"

#include "io/calibration_io.h"

namespace vellum {

ScanContext ScanContext::Of(const Scan& scan) {
  ScanContext c;
  c.identity = scan.identity;
  c.leaf_hint = scan.leaf_hint;
  c.object = scan.object;
  c.live_off_view = scan.live_off_view;
  return c;
}

ScanContext ScanContext::For(const Scan& scan, const Calibration& calibration) {
  ScanContext c = Of(scan);
  c.MeasuredWith(calibration);
  return c;
}

void ScanContext::MeasuredWith(const Calibration& calibration) {
  calibration_sha256 = CalibrationSha256(calibration);
  scale_error_percent = calibration.scale_error_percent;
}

}  // namespace vellum
