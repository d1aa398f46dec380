// Recorded scan logs <-> scan directories (`vellum export` / `vellum import`): a log as the
// decoder records it (SCAN_STARTED, CALIBRATION, then the texture, every frame and the image
// under each extra light on CAPTURE) read as a scan, and a scan directory written as such a log
// that lcm-logplayer can play into the station.
#pragma once

#include <cstdint>
#include <string>

#include "core/common/status.h"
#include "core/patterns/scan.h"
#include "vellum/calibration_t.hpp"
#include "vellum/capture_t.hpp"
#include "vellum/scan_started_t.hpp"

namespace vellum::station {

// Reads a recorded log: the captures of its scan (`scan_id` 0: the log must hold exactly one
// scan) and its calibration, if any. Errors name the log and what is missing.
Status ReadScanLog(const std::string& log_path, int64_t scan_id, Scan* scan, bool* has_calibration,
                   calibration_t* calibration, int64_t* found_scan_id);
// Writes a scan directory as a log station `station` would have recorded: SCAN_STARTED (with a
// new session), CALIBRATION (if given), then the texture and every frame on CAPTURE,
// `interval_us` apart.
Status WriteScanLog(const std::string& log_path, const Scan& scan, int64_t scan_id,
                    const std::string& station, const calibration_t* calibration,
                    int64_t interval_us = 20000);

// The identity a recorded log's scan was started with (its SCAN_STARTED, read without reading
// its captures); false when the log cannot be read or holds none.
bool ReadLoggedIdentity(const std::string& log_path, ScanIdentity* identity);

// The SCAN_STARTED a projector publishes for `scan` (station and seq left to the publisher).
scan_started_t MakeScanStarted(const Scan& scan, int64_t scan_id, int64_t session);

// The capture message of one image of a scan (pattern_index -1: the texture; pattern count + k:
// extra light k); its session is left 0 (the caller's).
capture_t MakeCapture(const Scan& scan, int64_t scan_id, int pattern_index, int64_t utime);

}  // namespace vellum::station
