// Recorded scan logs <-> scan directories (`vellum export` / `vellum import`): a log as the
// decoder records it (CALIBRATION, then the texture and every frame on CAPTURE) read as a scan,
// and a scan directory written as such a log that lcm-logplayer can play into the station.
#pragma once

#include <cstdint>
#include <string>

#include "core/common/status.h"
#include "core/patterns/scan.h"
#include "vellum/calibration_t.hpp"
#include "vellum/capture_t.hpp"

namespace vellum::station {

// Reads a recorded log: the captures of its scan (`scan_id` 0: the log must hold exactly one
// scan) and its calibration, if any. Errors name the log and what is missing.
Status ReadScanLog(const std::string& log_path, int64_t scan_id, Scan* scan, bool* has_calibration,
                   calibration_t* calibration, int64_t* found_scan_id);
// Writes a scan directory as a log a station would have recorded: CALIBRATION (if given), then
// the texture and every frame on CAPTURE, `interval_us` apart.
Status WriteScanLog(const std::string& log_path, const Scan& scan, int64_t scan_id,
                    const calibration_t* calibration, int64_t interval_us = 20000);

// The capture message of one image of a scan (pattern_index -1: the texture).
capture_t MakeCapture(const Scan& scan, int64_t scan_id, int pattern_index, int64_t utime);

}  // namespace vellum::station
