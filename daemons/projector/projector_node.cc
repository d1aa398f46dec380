#include "daemons/projector/projector_node.h"

#include <algorithm>
#include <thread>

#include "core/common/text.h"
#include "station/messages.h"
#include "vellum/calibration_t.hpp"
#include "vellum/latency_probe_t.hpp"
#include "vellum/pattern_shown_t.hpp"
#include "vellum/scan_started_t.hpp"

namespace vellum::station {

bool ProjectorNodeOptions::Check(std::string* why) const {
  if (settle.count() < 0 || display_lag.count() < 0 || !(capture_timeout.count() > 0) ||
      !(light_timeout.count() > 0)) {
    *why = "projector: settle and display_lag must be >= 0, capture_timeout and light_timeout > 0";
    return false;
  }
  return patterns.Check(why) && (!calibration || calibration->Check(why));
}

ProjectorNode::ProjectorNode(Node* node, std::unique_ptr<Projector> projector,
                             const ProjectorNodeOptions& options)
    : node_(node),
      projector_(std::move(projector)),
      options_(options),
      sequence_(MakePatternSequence(options.patterns)) {
  black_ = cv::Mat::zeros(projector_->size(), CV_8U);
  projector_->Show(black_);
  node->Subscribe<scan_request_t>(channel::kScanRequest,
                                  [this](const scan_request_t& m) { OnRequest(m); });
  node->Subscribe<capture_t>(channel::kCapture, [this](const capture_t& m) { OnCapture(m); });
  node->Subscribe<calibration_t>(channel::kCalibration,
                                 [this](const calibration_t& m) { OnCalibration(m); });
  node->Subscribe<light_t>(channel::kLightOn, [this](const light_t& m) { OnLightOn(m); });
  node->Subscribe<status_t>(StatusChannel("vellum-decoder"),
                            [this](const status_t& m) { OnDecoderStatus(m); });
  node->Subscribe<status_t>(StatusChannel("vellum-camera"),
                            [this](const status_t&) { camera_heard_ = true; });
  node->Subscribe<latency_request_t>(channel::kLatencyRequest,
                                     [this](const latency_request_t& m) { OnLatencyRequest(m); });
  node->Subscribe<latency_seen_t>(channel::kLatencySeen,
                                  [this](const latency_seen_t& m) { OnLatencySeen(m); });
  std::string lights;
  for (const ScanLight& l : options_.lights) lights += (lights.empty() ? "" : ", ") + l.name;
  node->Log("projector " + SizeText(projector_->size()) + ", " +
            std::to_string(sequence_.patterns.size()) + " patterns per scan" +
            (lights.empty() ? "" : "; then the extra lights " + lights));
}

void ProjectorNode::Tick() {
  if (!projector_->Poll()) node_->Stop();
  if (options_.measure_lag && !lag_measured_ && camera_heard_ && latency_.session == 0 &&
      scan_id_ == 0) {
    lag_measured_ = true;  // Once: a failure keeps the configured lag.
    StartLatency(NewSession(), options_.lag_flashes);
  }
  if (latency_.session != 0 && node_->Now() > latency_.deadline) {
    EndLatency("no LATENCY_SEEN for flash " + std::to_string(latency_.index) +
               " within 3 s (is vellum-camera running and on the same bus?)");
  }
  if (scan_id_ == 0) return;
  const auto waited = node_->Now() - shown_at_;
  if (awaiting_light_ && waited > options_.light_timeout) {
    Fail("no LIGHT_ON for " + What(index_) + " within " + Fixed(options_.light_timeout.count(), 1) +
         " s (is vellum-lights running and on the same bus? with its manual backend the operator "
         "answers in the viewer)");
  } else if (!awaiting_light_ && waited > options_.capture_timeout) {
    Fail("no CAPTURE of " + What(index_) + " within " +
         std::to_string(static_cast<int>(options_.capture_timeout.count() * 1000)) +
         " ms (is vellum-camera running and on the same bus?)");
  }
}

std::string ProjectorNode::What(int index) const {
  if (index >= Patterns()) return "the light '" + options_.lights[index - Patterns()].name + "'";
  return index < 0 ? std::string("the texture")
                   : "pattern " + std::to_string(index) + " of " +
                         std::to_string(sequence_.patterns.size());
}

void ProjectorNode::OnRequest(const scan_request_t& m) {
  if (m.scan_id <= 0) {
    node_->Error("SCAN_REQUEST with scan_id " + std::to_string(m.scan_id) + " refused");
    return;
  }
  if (scan_id_ != 0) {
    node_->Error("scan " + std::to_string(m.scan_id) + " refused: scan " +
                     std::to_string(scan_id_) + " is in progress",
                 m.scan_id);
    return;
  }
  if (latency_.session != 0) {  // Measuring the display's lag: a second at most, then this.
    deferred_ = m;
    return;
  }
  scan_id_ = m.scan_id;
  session_ = NewSession();
  const std::string label = m.identity.label;
  node_->Log("scan " + std::to_string(scan_id_) + " started" +
             (label.empty() ? "" : " (" + Printable(label) + ")"));
  // The scan is announced first: the decoder records captures only of a scan this station's
  // projector started, with this session.
  scan_started_t started{};
  started.scan_id = scan_id_;
  started.session = session_;
  started.pattern_count = static_cast<int32_t>(sequence_.patterns.size());
  started.projector_width = sequence_.projector_size.width;
  started.projector_height = sequence_.projector_size.height;
  started.identity = m.identity;
  started.light_count = static_cast<int32_t>(options_.lights.size());
  for (const ScanLight& l : options_.lights) started.lights.push_back(ToMessage(l));
  std::copy(m.leaf_hint, m.leaf_hint + 4, started.leaf_hint);
  started.object = m.object;
  started.live_off_view = m.live_off_view;
  node_->Publish(channel::kScanStarted, &started);
  if (options_.calibration) {
    calibration_t c{};
    c.scan_id = scan_id_;
    c.session = session_;
    c.source = options_.calibration_source;
    ToMessage(*options_.calibration, &c);
    node_->Publish(channel::kCalibration, &c);
  }
  started_ = std::chrono::steady_clock::now();  // For the log: the real time it took.
  ShowPattern(-1);
}

void ProjectorNode::OnLatencyRequest(const latency_request_t& m) {
  if (scan_id_ != 0 || latency_.session != 0) {
    node_->Error("display lag measurement refused: " +
                 (scan_id_ != 0 ? "scan " + std::to_string(scan_id_) + " is in progress"
                                : std::string("one is in progress")));
    return;
  }
  StartLatency(m.session, std::clamp(m.flashes, 2, 100));
}

void ProjectorNode::StartLatency(int64_t session, int flashes) {
  latency_ = Latency();
  latency_.session = session;
  latency_.flashes = flashes;
  node_->SetState("measuring", 0, "the display's lag");
  Flash(0);
}

void ProjectorNode::Flash(int index) {
  latency_.index = index;
  const bool white = index % 2 == 0;
  projector_->Show(white ? cv::Mat(projector_->size(), CV_8U, cv::Scalar(255)) : black_);
  latency_probe_t m{};
  m.handed_utime = NowUtime();
  m.session = latency_.session;
  m.index = index;
  m.flashes = latency_.flashes;
  m.white = white;
  m.window_us = 120000;  // Lags of a few refreshes, and a frame of the new level.
  m.projector_width = sequence_.projector_size.width;
  m.projector_height = sequence_.projector_size.height;
  m.refresh_hz = static_cast<float>(RefreshHz());
  FlashFrames f;
  f.handed_us = m.handed_utime;
  f.white = white;
  latency_.seen.push_back(f);
  latency_.deadline = node_->Now() + std::chrono::seconds(3);
  node_->Publish(channel::kLatencyProbe, &m);
}

void ProjectorNode::OnLatencySeen(const latency_seen_t& m) {
  if (latency_.session == 0 || m.session != latency_.session || m.index != latency_.index) return;
  if (!m.error.empty()) return EndLatency("the camera: " + Printable(m.error, 200));
  FlashFrames& f = latency_.seen.back();
  f.exposure_us = m.exposure_us;
  f.start_us = m.start_utime;
  f.level.assign(m.level.begin(), m.level.end());
  if (latency_.index + 1 < latency_.flashes) return Flash(latency_.index + 1);
  EndLatency("");
}

double ProjectorNode::RefreshHz() const {
  return options_.refresh_hz > 0 ? options_.refresh_hz : projector_->refresh_hz();
}

void ProjectorNode::EndLatency(const std::string& failure) {
  projector_->Show(black_);
  DisplayLag lag;
  if (failure.empty()) lag = EstimateDisplayLag(latency_.seen, RefreshHz());
  latency_ = Latency();
  node_->SetState("idle");
  if (!failure.empty() || !lag.status.ok()) {
    node_->Error("display lag not measured: " + (failure.empty() ? lag.status.message() : failure) +
                 "; the handshake keeps waiting " +
                 Fixed(std::chrono::duration<double, std::milli>(options_.display_lag).count(), 1) +
                 " ms and the settle time");
  } else {
    options_.display_lag = std::chrono::microseconds(static_cast<int64_t>(1000 * lag.wait_ms));
    node_->Log(lag.Describe());
  }
  if (deferred_) {
    const scan_request_t request = *deferred_;
    deferred_.reset();
    OnRequest(request);
  }
}

void ProjectorNode::OnCalibration(const calibration_t& m) {
  if (m.scan_id != 0) return;  // A scan's own (this projector's): nothing to do.
  // A station calibration (scan_id 0): from the next scan on, never for the one in progress.
  Calibration c;
  const Status s = FromMessage(m, &c);
  if (!s.ok()) {
    node_->Error("CALIBRATION from " + Printable(m.source) + " refused: " + s.message());
    return;
  }
  options_.calibration = c;
  options_.calibration_source = m.source;
  node_->Count("calibrations taken");
  node_->Log("calibration from " + Printable(m.source) + " taken: it applies from the next scan" +
             (scan_id_ != 0 ? " (scan " + std::to_string(scan_id_) + " keeps its own)" : ""));
}

void ProjectorNode::OnCapture(const capture_t& m) {
  if (scan_id_ == 0 || m.scan_id != scan_id_ || m.session != session_ ||
      m.pattern_index != index_ || awaiting_light_) {
    return;
  }
  if (index_ + 1 < Patterns()) {
    ShowPattern(index_ + 1);
    return;
  }
  const int lights = static_cast<int>(options_.lights.size());
  if (index_ + 1 < Patterns() + lights) {
    RequestLight(index_ + 1 - Patterns());
    return;
  }
  if (lights > 0) RequestLight(-1);
  const double secs =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count();
  node_->Log("scan " + std::to_string(scan_id_) + ": " + std::to_string(Patterns() + 1 + lights) +
             " captures in " + std::to_string(secs) + " s");
  node_->Count("scans captured");
  projector_->Show(black_);
  node_->SetState("idle", scan_id_, "scan captured");
  scan_id_ = 0;
}

void ProjectorNode::RequestLight(int k) {
  light_t m{};
  m.scan_id = scan_id_;
  m.session = session_;
  m.index = k;
  m.light_count = static_cast<int32_t>(options_.lights.size());
  if (k >= 0) {
    index_ = Patterns() + k;
    projector_->Show(black_);
    m.light = ToMessage(options_.lights[k]);
    awaiting_light_ = true;
    shown_at_ = node_->Now();
    node_->SetState("scanning", scan_id_, "waiting for " + What(index_));
  }
  node_->Publish(channel::kLightRequest, &m);
}

void ProjectorNode::OnLightOn(const light_t& m) {
  if (scan_id_ == 0 || !awaiting_light_ || m.scan_id != scan_id_ || m.session != session_ ||
      m.index != index_ - Patterns() || m.light.name != options_.lights[m.index].name) {
    return;
  }
  awaiting_light_ = false;
  node_->Log("scan " + std::to_string(scan_id_) + ": " + What(index_) + " is on (" +
             Printable(m.source, 40) + ")");
  ShowPattern(index_);
}

void ProjectorNode::ShowPattern(int index) {
  index_ = index;
  PatternSpec spec;
  spec.kind = PatternKind::kBlack;
  const bool pattern = index >= 0 && index < Patterns();
  if (pattern) spec = sequence_.patterns[index];
  projector_->Show(pattern ? RenderPattern(spec, sequence_.projector_size) : black_);
  const int64_t handed = NowUtime();
  std::this_thread::sleep_for(options_.display_lag + options_.settle);
  pattern_shown_t m{};
  m.handed_utime = handed;
  m.scan_id = scan_id_;
  m.session = session_;
  m.pattern_index = index;
  m.pattern_count = static_cast<int32_t>(sequence_.patterns.size());
  m.projector_width = sequence_.projector_size.width;
  m.projector_height = sequence_.projector_size.height;
  m.pattern = ToMessage(spec);
  m.light_count = static_cast<int32_t>(options_.lights.size());
  if (index >= Patterns()) m.light = ToMessage(options_.lights[index - Patterns()]);
  node_->Publish(channel::kPatternShown, &m);
  shown_at_ = node_->Now();
  node_->SetState("scanning", scan_id_, "showing " + What(index));
}

void ProjectorNode::OnDecoderStatus(const status_t& m) {
  const int64_t failed = StatusCounter(m, counter::kScansFailed);
  const bool rose = decoder_failed_ >= 0 && failed > decoder_failed_;
  decoder_failed_ = failed;  // A restarted decoder counts from 0 again.
  if (!rose || scan_id_ == 0 || m.last_error_scan_id != scan_id_) return;
  node_->Count("scans stopped");
  node_->Log("scan " + std::to_string(scan_id_) + " stopped at " + What(index_) +
             ": the decoder failed it (" + Printable(m.last_error, 200) + ")");
  End();
}

void ProjectorNode::Fail(const std::string& why) {
  node_->Count(counter::kScansFailed);  // Before the error goes out with the count.
  node_->Error("scan " + std::to_string(scan_id_) + " failed: " + why, scan_id_);
  End();
}

void ProjectorNode::End() {
  projector_->Show(black_);
  if (!options_.lights.empty()) RequestLight(-1);
  awaiting_light_ = false;
  node_->SetState("idle");
  scan_id_ = 0;
}

}  // namespace vellum::station
