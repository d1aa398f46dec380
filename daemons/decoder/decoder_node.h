// vellum-decoder's node: records each scan's captures to disk as they arrive (the scan's raw
// folder: captures.lcmlog and the scan directory of DESIGN.md), and once a scan is complete
// sends it down the chain: TEXTURE, then the decoded CORRESPONDENCE (in row chunks) with the
// decode stage's report. It hosts the station's supervisor (station/supervisor.h), which sends
// a scan again when a processing daemon died holding it.
#pragma once

#include <atomic>
#include <chrono>
#include <string>

#include "core/decode/decode.h"
#include "core/patterns/scan.h"
#include "station/node.h"
#include "station/scan_store.h"
#include "station/supervisor.h"
#include "vellum/calibration_t.hpp"
#include "vellum/capture_t.hpp"

namespace vellum::station {

struct DecoderNodeOptions {
  std::string data_dir = "scans";  // Station data folder: <data_dir>/scan-<id>/raw, /results.
  DecodeOptions decode;
  double scan_timeout_s = 30;  // An incomplete scan with no capture for this long is given up.
};

class DecoderNode {
 public:
  DecoderNode(Node* node, const DecoderNodeOptions& options);
  // Waits for the jobs it posted: none runs after it is gone.
  ~DecoderNode() { node_->Drain(); }

  // On the LCM thread, about every tick: gives up an incomplete scan whose captures stopped.
  void Tick();

 private:
  // LCM thread: appends a message to its scan's log at once; false (reported) for a message
  // of no scan (scan_id <= 0), which is dropped.
  bool Log(const char* channel, int64_t scan_id, int64_t utime, const std::vector<uint8_t>& bytes);
  // Worker thread:
  void OnCalibration(const calibration_t& msg);
  void OnCapture(const capture_t& msg);
  bool Begin(int64_t scan_id);  // Opens the scan's folder on its first message.
  void Abandon(const std::string& why);
  void Stop();  // No scan is being recorded.
  void Complete();
  Status Send(int64_t id, const Scan& scan);  // Decodes and publishes (the supervisor's Send).

  Node* node_;
  DecoderNodeOptions options_;
  // Worker thread only:
  Decoder decoder_;  // Keeps its buffers between scans.
  DecodeResult decoded_;
  CaptureSet set_;
  int64_t recording_ = 0;  // The scan whose folder is open.
  ScanRecorder recorder_;
  Supervisor supervisor_;
  // LCM thread only:
  CaptureLog log_;
  std::chrono::steady_clock::time_point last_capture_;
  std::atomic<bool> waiting_{false};  // A scan is being captured (set by the worker).
};

}  // namespace vellum::station
