// vellum-decoder's node: records each scan's captures to disk as they arrive (the scan's raw
// folder: captures.lcmlog and the scan directory of docs/formats.md): only the scans this station's
// projector started, each pattern once, never a scan that is over (station/scan_gate.h). A scan
// given up is marked so on disk (raw/failed.txt, with the reason). Its TEXTURE goes on as soon
// as it is recorded; once the scan is complete the decoder sends it down the chain: the extra
// lights' images, then the decoded CORRESPONDENCE (in row chunks) with the decode stage's
// report (and the TEXTURE first when the scan is sent again from its folder). It hosts the
// station's supervisor (station/supervisor.h), which sends a scan again when a processing daemon
// died holding it.
#pragma once

#include <atomic>
#include <chrono>
#include <map>
#include <memory>
#include <string>

#include "core/decode/decode.h"
#include "core/patterns/scan.h"
#include "pipeline/stages.h"
#include "station/node.h"
#include "station/scan_gate.h"
#include "station/scan_store.h"
#include "station/supervisor.h"
#include "vellum/calibration_t.hpp"
#include "vellum/capture_t.hpp"
#include "vellum/light_t.hpp"
#include "vellum/scan_started_t.hpp"

namespace vellum::station {

struct DecoderNodeOptions {
  std::string data_dir = "scans";  // Station data folder: <data_dir>/scan-<id>/raw, /results.
  DecodeOptions decode;
  WarningLimits
      limits;  // What makes its decode doubtful (frame_contradicts), as `vellum process` has.
  double scan_timeout_s = 30;  // An incomplete scan with no capture for this long is given up.
  bool Check(std::string* why) const;
};

class DecoderNode {
 public:
  // Throws std::runtime_error when another decoder records into options.data_dir (DataLock).
  DecoderNode(Node* node, const DecoderNodeOptions& options);
  // Waits for the jobs it posted: none runs after it is gone.
  ~DecoderNode() { node_->Drain(); }

  // On the LCM thread, about every tick: gives up an incomplete scan whose captures stopped.
  void Tick();

 private:
  // LCM thread: whether the gate's decision is to record; a refusal is counted, and reported
  // (as an error of error_scan_id, 0: of none) at most once a second per reason.
  bool Admitted(const ScanGate::Decision& d, int64_t error_scan_id);
  // LCM thread: appends a message to its scan's log at once (a failure is reported).
  bool Log(const char* channel, int64_t scan_id, int64_t utime, const std::vector<uint8_t>& bytes);
  // Worker thread:
  void OnCalibration(const calibration_t& msg);
  void OnCapture(const capture_t& msg);
  bool Begin(int64_t scan_id);           // Opens the scan's folder on its first message.
  void Abandon(const std::string& why);  // Gives up the scan being recorded.
  void Fail(int64_t scan_id, const std::string& why);  // Marks it failed (raw/failed.txt).
  void Stop();                                         // No scan is being recorded.
  void Complete();
  Status Send(int64_t id, const Scan& scan);  // Decodes and publishes (the supervisor's Send).
  // Publishes a scan's TEXTURE, announcing `light_count` extra lights to follow: as its capture
  // is recorded (the processing daemons have it before the last frame), or with the rest when
  // the scan is sent from its folder (which may be another scan than the one being recorded).
  void SendTexture(int64_t id, const cv::Mat& texture, int light_count);
  // Takes a pattern capture up into the decoder as it comes, while the scan is the station's own
  // sequence (MakePatternSequence for its projector) and every capture came to this process;
  // otherwise (a scan resumed from its log, another sequence) the decoder reads the frames from
  // the scan's folder once it is complete. No frame is held for the whole scan either way.
  void Stream(const capture_t& msg, const cv::Mat& image);
  void StreamFrame(int64_t scan_id, cv::Size projector, int count, int index,
                   const PatternSpec& spec, const cv::Mat& image);

  Node* node_;
  DecoderNodeOptions options_;
  std::unique_ptr<DataLock> lock_;  // Held for the node's life.
  // Worker thread only:
  Decoder decoder_;  // Keeps its buffers between scans.
  DecodeResult decoded_;
  int64_t stream_id_ = 0;     // The scan the decoder takes up as it comes; 0: none.
  int64_t texture_sent_ = 0;  // The scan whose TEXTURE went on as it was recorded; 0: none.
  bool stream_begun_ = false;
  PatternSequence stream_sequence_;  // Its sequence, as the station's projector shows it.
  CaptureSet set_;
  int64_t recording_ = 0;   // The scan whose folder is open.
  scan_started_t started_;  // Its SCAN_STARTED (identity, leaf hint), for scan.yaml and report.
  ScanRecorder recorder_;
  Supervisor supervisor_;
  ScanGate gate_;  // Decides on the LCM thread; the worker closes scans it gives up.
  // LCM thread only:
  CaptureLog log_;
  std::map<std::string, Clock::time_point> refusal_reported_;  // By reason.
  Clock::time_point last_capture_;
  // The scan's projector waits for an extra light (LIGHT_REQUEST; an operator switching by hand
  // may take minutes): no timeout until the light's capture, or the lights off (the projector's
  // own light timeout fails the scan then, and this one runs again).
  bool awaiting_light_ = false;
  std::atomic<bool> waiting_{false};  // A scan is being captured (set by the worker).
};

}  // namespace vellum::station
