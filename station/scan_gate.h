// Which messages the decoder records (scan identity): only those of the scan its own
// station's projector started (SCAN_STARTED, with that scan's session), each pattern once, and
// never anything of a scan that is over. A finished scan's folder is never reopened; captures
// of unknown, finished or other sessions' scans are refused before they touch the disk, so a
// flood of them costs nothing but a counter.
//
// The gate decides on the LCM thread, before a message is appended to the scan's log; the
// worker closes a scan it gives up. After a restart of the decoder in the middle of a scan, the
// scan is taken up again from its folder: a log that starts with the scan's SCAN_STARTED, no
// scan.yaml (not finished) and no failed.txt (not given up).
#pragma once

#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "station/scan_store.h"
#include "vellum/calibration_t.hpp"
#include "vellum/capture_t.hpp"
#include "vellum/scan_started_t.hpp"

namespace vellum::station {

class ScanGate {
 public:
  enum class Verdict {
    kRecord,     // Record it.
    kRefuse,     // Not of the scan in progress: refused, counted (why: what it was).
    kDuplicate,  // A second capture of a pattern already recorded: the scan cannot be trusted.
  };
  struct Decision {
    Verdict verdict = Verdict::kRefuse;
    std::string why;       // For kRefuse and kDuplicate: names the scan and what was wrong.
    std::string counter;   // The status counter it goes to.
    bool resumed = false;  // The scan was taken up again from its folder (a restart).
  };

  explicit ScanGate(std::string data_dir) : data_(std::move(data_dir)) {}

  // SCAN_STARTED: opens the scan. Refused when the message is not a valid scan, or when the
  // scan's folder already exists (a scan id is recorded once: a finished or failed scan is never
  // reopened). The same announcement again is recorded once (kRefuse with an empty why).
  Decision Start(const scan_started_t& m);
  // A CAPTURE (already through CheckCapture).
  Decision Admit(const capture_t& c);
  // A CALIBRATION: recorded only for the scan in progress, with its session, before its first
  // capture (a calibration never changes under a scan). scan_id 0 is a station calibration for
  // the scans to come: not recorded here (why empty).
  Decision AdmitCalibration(const calibration_t& c);
  // The scan is over (complete, failed or given up): nothing more of it is recorded.
  void Close(int64_t scan_id);
  // Whether this is the scan in progress, with its session.
  bool Holds(int64_t scan_id, int64_t session) const;

 private:
  // Takes up a scan from its folder after a restart; false when the folder is not a scan in
  // progress with this session (*why says what it is).
  bool Resume(int64_t scan_id, int64_t session, std::string* why);
  void Remember(int64_t scan_id);  // A closed scan (the last few, for quick refusal).
  bool Closed(int64_t scan_id) const;

  std::string data_;
  mutable std::mutex mutex_;  // The LCM thread decides, the worker closes.
  int64_t scan_id_ = 0, session_ = 0;
  int count_ = 0;
  std::vector<std::string> lights_;  // The extra lights' names (SCAN_STARTED), in order.
  std::vector<char> logged_;         // [0] texture, [k + 1] pattern k, [count + k + 1] light k.
  int received_ = 0;
  bool calibration_ = false;
  std::deque<int64_t> closed_;         // The last scans closed, newest last.
  std::deque<int64_t> not_resumable_;  // Folders probed after a restart that were not.
};

}  // namespace vellum::station
