// vellum-projector's node: the scan's conductor. On SCAN_REQUEST it draws the scan's session
// and publishes SCAN_STARTED and the station's CALIBRATION, then for the texture and each pattern
// k: shows it (projector black for the texture), waits the settle time, publishes PATTERN_SHOWN(k)
// and waits for the camera's CAPTURE(k) (of this station and session) before the next. A capture
// that does not come fails the scan with a clear status. Then, for each extra light of the station,
// with the projector black: LIGHT_REQUEST(k) to vellum-lights, and on its LIGHT_ON(k)
// (or the operator's, from the viewer) PATTERN_SHOWN(pattern_count + k) for the camera; after the
// last, or when the scan fails, LIGHT_REQUEST(-1) turns them all off. A scan the decoder fails
// (its status: "scans failed" rose, the error names the scan) is stopped at once: the projector
// goes black and takes the next request. A CALIBRATION with scan_id 0 replaces the station's
// calibration from the next scan on.
//
// The display's lag (core/patterns/display_lag.h): on LATENCY_REQUEST, or at start-up once the
// camera is heard (measure_lag), the projector flashes white and black in turn, publishing
// LATENCY_PROBE with each handover; the camera answers LATENCY_SEEN with its frames' starts and
// levels. From then on the handshake waits the lag measured. A scan asked meanwhile starts when
// the measurement ends.
#pragma once

#include <chrono>
#include <memory>
#include <optional>
#include <string>

#include "core/geometry/calibration.h"
#include "core/patterns/display_lag.h"
#include "core/patterns/patterns.h"
#include "core/patterns/scan.h"
#include "daemons/projector/projector.h"
#include "station/node.h"
#include "vellum/calibration_t.hpp"
#include "vellum/capture_t.hpp"
#include "vellum/latency_request_t.hpp"
#include "vellum/latency_seen_t.hpp"
#include "vellum/light_t.hpp"
#include "vellum/scan_request_t.hpp"
#include "vellum/status_t.hpp"

namespace vellum::station {

struct ProjectorNodeOptions {
  PatternOptions patterns;                 // The sequence (its projector_size: the screen's).
  std::optional<Calibration> calibration;  // Published as CALIBRATION with every scan.
  std::string calibration_source;          // Where it came from (the message says).
  // The display's lag from vsync to the image on the page (measured; 0: not measured), and
  // the wait after it: PATTERN_SHOWN goes out vsync + display_lag + settle after the handover,
  // and the camera takes the first frame exposed after that.
  std::chrono::microseconds display_lag{0};
  std::chrono::milliseconds settle{30};
  // Measure the display's lag at start-up (once the camera is heard), in about a second, and
  // wait what it measured instead of display_lag; a LATENCY_REQUEST (`vellum calibrate
  // latency`) measures it again whenever no scan runs.
  bool measure_lag = false;
  // White and black in turn; the camera's phase against them drifts over twelve.
  int lag_flashes = 12;
  double refresh_hz = 0;  // The display's, where SDL does not know it (0: ask SDL).
  std::chrono::duration<double> capture_timeout{5.0};  // Longest wait for each CAPTURE.
  // The station's extra lights, taken after the patterns in this order (names and directions;
  // no images). Empty: none.
  std::vector<ScanLight> lights;
  // Longest wait for a light's LIGHT_ON (an operator switching by hand needs time).
  std::chrono::duration<double> light_timeout{120.0};
  bool Check(std::string* why) const;
};

class ProjectorNode {
 public:
  // `projector` shows images of options.patterns.projector_size.
  ProjectorNode(Node* node, std::unique_ptr<Projector> projector,
                const ProjectorNodeOptions& options);

  // On the LCM thread, often (every few ms): the window's events and the capture timeout.
  void Tick();
  // The scan in progress (0: none).
  int64_t scan_id() const { return scan_id_; }

 private:
  std::string What(int index) const;
  void OnRequest(const scan_request_t& m);
  void OnCapture(const capture_t& m);
  void OnCalibration(const calibration_t& m);
  void OnLightOn(const light_t& m);
  void OnDecoderStatus(const status_t& m);
  void OnLatencyRequest(const latency_request_t& m);
  void OnLatencySeen(const latency_seen_t& m);
  void StartLatency(int64_t session, int flashes);
  void Flash(int index);
  void EndLatency(const std::string& failure);
  // The display's refresh rate: --refresh-hz where given, else as SDL knows it.
  double RefreshHz() const;
  void ShowPattern(int index);
  void RequestLight(int k);  // k -1: all off.
  int Patterns() const { return static_cast<int>(sequence_.patterns.size()); }
  void Fail(const std::string& why);
  void End();  // Black, lights off, idle: ready for the next request.

  Node* node_;
  std::unique_ptr<Projector> projector_;
  ProjectorNodeOptions options_;
  PatternSequence sequence_;
  cv::Mat black_;
  // LCM thread only (the projector runs its scans there, one message at a time):
  int64_t scan_id_ = 0;  // The scan in progress, 0 if none.
  int64_t session_ = 0;  // Its session (SCAN_STARTED): captures of other sessions are not its.
  int index_ = -1;       // What is on screen: -1 the texture, k pattern k, Patterns() + k light k.
  bool awaiting_light_ = false;  // LIGHT_REQUEST sent, LIGHT_ON not yet come.
  Clock::time_point shown_at_;   // By the node's clock.
  std::chrono::steady_clock::time_point started_;
  int64_t decoder_failed_ = -1;  // The decoder's "scans failed" (-1: no status yet).
  struct Latency {
    int64_t session = 0;  // 0: not measuring.
    int flashes = 0, index = 0;
    Clock::time_point deadline;
    std::vector<FlashFrames> seen;
  } latency_;
  bool camera_heard_ = false, lag_measured_ = false;
  std::optional<scan_request_t> deferred_;  // Asked while the lag was measured.
};

}  // namespace vellum::station
