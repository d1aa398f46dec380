#include "station/scan_log.h"

#include <filesystem>
#include <lcm/lcm-cpp.hpp>

#include "io/scan_io.h"
#include "station/messages.h"
#include "station/node.h"
#include "station/scan_store.h"

namespace vellum::station {
scan_started_t MakeScanStarted(const Scan& scan, int64_t scan_id, int64_t session) {
  scan_started_t m{};
  m.scan_id = scan_id;
  m.session = session;
  m.pattern_count = static_cast<int32_t>(scan.sequence.patterns.size());
  m.projector_width = scan.sequence.projector_size.width;
  m.projector_height = scan.sequence.projector_size.height;
  m.identity = ToMessage(scan.identity);
  if (!scan.leaf_hint.empty() && scan.camera_size.area() > 0) {
    const cv::Rect& h = scan.leaf_hint;
    const double w = scan.camera_size.width, ht = scan.camera_size.height;
    ToLeafHint(cv::Rect2d(h.x / w, h.y / ht, h.width / w, h.height / ht), m.leaf_hint);
  }
  m.light_count = static_cast<int32_t>(scan.lights.size());
  for (const ScanLight& light : scan.lights) m.lights.push_back(ToMessage(light));
  m.object = ToString(scan.object);
  m.live_off_view = ViewSidesText(scan.live_off_view);
  return m;
}

capture_t MakeCapture(const Scan& scan, int64_t scan_id, int pattern_index, int64_t utime) {
  capture_t c{};
  c.utime = utime;
  c.seq = 0;
  c.scan_id = scan_id;
  c.pattern_index = pattern_index;
  c.pattern_count = static_cast<int32_t>(scan.sequence.patterns.size());
  c.projector_width = scan.sequence.projector_size.width;
  c.projector_height = scan.sequence.projector_size.height;
  c.light_count = static_cast<int32_t>(scan.lights.size());
  PatternSpec black;
  black.kind = PatternKind::kBlack;
  const int patterns = c.pattern_count;
  const bool pattern = pattern_index >= 0 && pattern_index < patterns;
  c.pattern = ToMessage(pattern ? scan.sequence.patterns[pattern_index] : black);
  c.shown_utime = utime - 1000;
  const cv::Mat* image = &scan.texture;
  if (pattern) image = &scan.frames[pattern_index];
  if (pattern_index >= patterns) {
    const ScanLight& light = scan.lights[pattern_index - patterns];
    c.light = ToMessage(light);
    image = &light.image;
  }
  ToMessage(*image, &c.image);
  c.image.utime = utime - 500;
  c.image.seq = 0;
  c.image.scan_id = scan_id;
  c.image.pattern_index = pattern_index;
  c.image.pattern_count = c.pattern_count;
  return c;
}

Status WriteScanLog(const std::string& log_path, const Scan& scan, int64_t scan_id,
                    const std::string& station, const calibration_t* calibration,
                    int64_t interval_us) {
  lcm::LogFile log(log_path, "w");
  if (!log.good()) return Status::Error(log_path + ": cannot create");
  int64_t utime = NowUtime();
  int64_t seq = 0;
  auto write = [&](const std::string& channel, const std::vector<uint8_t>& bytes) {
    lcm::LogEvent event;
    event.eventnum = 0;
    event.timestamp = utime;
    event.channel = channel;
    event.datalen = static_cast<int32_t>(bytes.size());
    event.data = const_cast<uint8_t*>(bytes.data());
    return log.writeEvent(&event) == 0;
  };
  const int64_t session = NewSession();
  scan_started_t started = MakeScanStarted(scan, scan_id, session);
  started.utime = utime;
  started.station = station;
  if (!write(channel::kScanStarted, Encode(started))) {
    return Status::Error(log_path + ": write failed");
  }
  if (calibration) {
    calibration_t c = *calibration;
    c.utime = utime;
    c.seq = 0;
    c.station = station;
    c.scan_id = scan_id;
    c.session = session;
    if (!write(channel::kCalibration, Encode(c))) return Status::Error(log_path + ": write failed");
  }
  for (int k = -1; k < static_cast<int>(scan.frames.size() + scan.lights.size()); ++k) {
    utime += interval_us;
    capture_t c = MakeCapture(scan, scan_id, k, utime);
    c.seq = seq++;
    c.station = station;
    c.session = session;
    if (!write(channel::kCapture, Encode(c))) return Status::Error(log_path + ": write failed");
  }
  return Status::Ok();
}

bool ReadLoggedIdentity(const std::string& log_path, ScanIdentity* identity) {
  if (!PathExists(log_path)) return false;
  lcm::LogFile log(log_path, "r");
  if (!log.good()) return false;
  // SCAN_STARTED is the log's first event; a few more are looked at for a log that began
  // otherwise (a calibration first), never the whole scan.
  int events = 0;
  for (const lcm::LogEvent* e = log.readNextEvent(); e && events < 8; e = log.readNextEvent()) {
    ++events;
    if (e->channel != channel::kScanStarted) continue;
    scan_started_t m;
    if (!SafeDecode(e->data, e->datalen, &m)) return false;
    *identity = SanitizedIdentity(FromMessage(m.identity));
    return true;
  }
  return false;
}

Status ReadScanLog(const std::string& log_path, int64_t scan_id, Scan* scan, bool* has_calibration,
                   calibration_t* calibration, int64_t* found_scan_id) {
  if (!PathExists(log_path)) return Status::Error(log_path + ": file is missing");
  lcm::LogFile log(log_path, "r");
  if (!log.good()) return Status::Error(log_path + ": cannot open as an LCM log");
  CaptureSet set;
  scan_started_t started{};
  *has_calibration = false;
  int64_t other = 0;
  int events = 0;
  for (const lcm::LogEvent* e = log.readNextEvent(); e; e = log.readNextEvent()) {
    ++events;
    if (e->channel == channel::kCapture) {
      capture_t c;
      if (!SafeDecode(e->data, e->datalen, &c)) {
        return Status::Error(log_path + ": event " + std::to_string(e->eventnum) +
                             " on CAPTURE does not decode as vellum.capture_t");
      }
      if (scan_id == 0 && set.Started() && c.scan_id != set.scan_id()) other = c.scan_id;
      if (scan_id != 0 && c.scan_id != scan_id) continue;
      if (scan_id == 0 && set.Started() && c.scan_id != set.scan_id()) continue;
      if (set.Has(c.pattern_index)) continue;  // A replay appended to the same log.
      Status s = set.Add(c);
      if (!s.ok()) return Status::Error(log_path + ": " + s.message());
    } else if (e->channel == channel::kScanStarted) {
      scan_started_t m;
      if (SafeDecode(e->data, e->datalen, &m) && (scan_id == 0 || m.scan_id == scan_id)) {
        started = m;
      }
    } else if (e->channel == channel::kCalibration) {
      calibration_t c;
      if (!SafeDecode(e->data, e->datalen, &c)) {
        return Status::Error(log_path + ": event " + std::to_string(e->eventnum) +
                             " on CALIBRATION does not decode as vellum.calibration_t");
      }
      if (scan_id != 0 && c.scan_id != scan_id) continue;
      *calibration = c;
      *has_calibration = true;
    }
  }
  if (events == 0) return Status::Error(log_path + ": no events (not an LCM log, or empty)");
  if (other != 0) {
    return Status::Error(log_path + ": holds more than one scan (" + std::to_string(set.scan_id()) +
                         ", " + std::to_string(other) + ", ...); pick one with --scan-id");
  }
  if (!set.Started()) {
    return Status::Error(log_path + ": no CAPTURE of scan " +
                         (scan_id ? std::to_string(scan_id) : std::string("(any)")));
  }
  if (!set.Complete()) {
    return Status::Error(log_path + ": scan " + std::to_string(set.scan_id()) +
                         " is incomplete: " + set.Missing());
  }
  *scan = set.ToScan();
  FromStarted(started, scan);
  *found_scan_id = set.scan_id();
  return Status::Ok();
}

}  // namespace vellum::station
