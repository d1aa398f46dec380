#include "station/scan_gate.h"

#include <algorithm>
#include <lcm/lcm-cpp.hpp>

#include "core/common/text.h"
#include "io/scan_io.h"
#include "station/messages.h"
#include "station/node.h"

namespace vellum::station {
namespace {

constexpr size_t kRemembered = 64;  // Closed scans and probed folders kept in memory.

std::string ScanText(int64_t scan_id) { return "scan " + std::to_string(scan_id); }

ScanGate::Decision Refuse(std::string why, std::string counter) {
  ScanGate::Decision d;
  d.verdict = ScanGate::Verdict::kRefuse;
  d.why = std::move(why);
  d.counter = std::move(counter);
  return d;
}

ScanGate::Decision Record() {
  ScanGate::Decision d;
  d.verdict = ScanGate::Verdict::kRecord;
  return d;
}

void Bounded(std::deque<int64_t>* q, int64_t id) {
  q->push_back(id);
  while (q->size() > kRemembered) q->pop_front();
}

bool Contains(const std::deque<int64_t>& q, int64_t id) {
  return std::find(q.begin(), q.end(), id) != q.end();
}

// The extra lights' names a SCAN_STARTED announces; false (with *why) when there are more than
// kMaxLights, one is not a valid light, or a name comes twice.
bool LightNames(const scan_started_t& m, std::vector<std::string>* names, std::string* why) {
  names->clear();
  if (m.light_count < 0 || m.light_count > kMaxLights) {
    *why = "light_count " + std::to_string(m.light_count) + " outside 0.." +
           std::to_string(kMaxLights);
    return false;
  }
  for (const light_spec_t& spec : m.lights) {
    ScanLight light;
    const Status s = FromMessage(spec, &light);
    if (!s.ok()) {
      *why = s.message();
      return false;
    }
    if (std::find(names->begin(), names->end(), light.name) != names->end()) {
      *why = "the light '" + light.name + "' comes twice";
      return false;
    }
    names->push_back(light.name);
  }
  return true;
}

}  // namespace

bool ScanGate::Holds(int64_t scan_id, int64_t session) const {
  std::lock_guard<std::mutex> lock(mutex_);
  return scan_id != 0 && scan_id == scan_id_ && session == session_;
}

ScanGate::Decision ScanGate::Start(const scan_started_t& m) {
  const std::string what = ScanText(m.scan_id);
  if (m.scan_id <= 0)
    return Refuse("SCAN_STARTED with scan_id " + std::to_string(m.scan_id), "scans refused");
  if (m.session <= 0) return Refuse(what + ": SCAN_STARTED without a session", "scans refused");
  if (m.pattern_count <= 0 || m.pattern_count > kMaxPatterns) {
    return Refuse(what + ": SCAN_STARTED with pattern_count " + std::to_string(m.pattern_count),
                  "scans refused");
  }
  ObjectKind object;
  if (!m.object.empty() && !ParseObjectKind(m.object, &object)) {
    return Refuse(
        what + ": SCAN_STARTED with object '" + Printable(m.object, 40) + "' (leaf, book or auto)",
        "scans refused");
  }
  int sides = 0;
  if (!ParseViewSides(m.live_off_view, &sides)) {
    return Refuse(what + ": SCAN_STARTED with live_off_view '" + Printable(m.live_off_view, 40) +
                      "' (the view's sides left, right, top, bottom, joined by commas)",
                  "scans refused");
  }
  std::vector<std::string> names;
  std::string bad;
  if (!LightNames(m, &names, &bad)) {
    return Refuse(what + ": SCAN_STARTED refused: " + bad, "scans refused");
  }
  std::lock_guard<std::mutex> lock(mutex_);
  if (m.scan_id == scan_id_ && m.session == session_) return Refuse("", "");  // Heard again.
  if (m.scan_id == scan_id_) {
    return Refuse(what +
                      ": SCAN_STARTED again with another session while it is recorded; "
                      "refused (the scan keeps its first session)",
                  "scans refused");
  }
  const ScanFolder folder = ScanFolder::For(data_, m.scan_id);
  if (Closed(m.scan_id) || PathExists(folder.root)) {
    return Refuse(what + ": refused, its folder " + folder.root +
                      " already exists (a scan id is recorded once; the archive there is kept "
                      "as it is)",
                  "scans refused");
  }
  if (scan_id_ != 0) Bounded(&closed_, scan_id_);  // Superseded (the worker gives it up).
  scan_id_ = m.scan_id;
  session_ = m.session;
  count_ = m.pattern_count;
  lights_ = std::move(names);
  logged_.assign(count_ + lights_.size() + 1, false);
  received_ = 0;
  calibration_ = false;
  return Record();
}

ScanGate::Decision ScanGate::Admit(const capture_t& c) {
  const std::string what =
      ScanText(c.scan_id) + ", " +
      (c.pattern_index < 0                  ? std::string("texture")
       : c.pattern_index >= c.pattern_count ? "the light '" + Printable(c.light.name, 40) + "'"
                                            : "pattern " + std::to_string(c.pattern_index));
  if (c.scan_id <= 0) {
    return Refuse(what + ": CAPTURE refused: no scan (scan_id must be > 0)",
                  "captures refused (unknown scan)");
  }
  std::lock_guard<std::mutex> lock(mutex_);
  Decision d;
  if (c.scan_id != scan_id_ || c.session != session_) {
    if (Closed(c.scan_id)) {
      return Refuse(what +
                        ": CAPTURE refused: the scan is over (finished or given up); its "
                        "archive is kept as it is",
                    "captures refused (scan over)");
    }
    if (c.scan_id == scan_id_) {
      return Refuse(what +
                        ": CAPTURE refused: its session is not the scan's (a stale capture, "
                        "or another projector)",
                    "captures refused (other session)");
    }
    std::string why;
    if (!Resume(c.scan_id, c.session, &why)) {
      return Refuse(what + ": CAPTURE refused: " + why, "captures refused (unknown scan)");
    }
    d.resumed = true;
  }
  if (c.pattern_count != count_) {
    return Refuse(what + ": CAPTURE refused: " + std::to_string(c.pattern_count) +
                      " patterns, the scan has " + std::to_string(count_),
                  "captures refused (mismatch)");
  }
  const int lights = static_cast<int>(lights_.size());
  if (c.light_count != lights) {
    return Refuse(what + ": CAPTURE refused: " + std::to_string(c.light_count) +
                      " extra lights, the scan has " + std::to_string(lights),
                  "captures refused (mismatch)");
  }
  if (c.pattern_index >= count_ && c.light.name != lights_[c.pattern_index - count_]) {
    return Refuse(what + ": CAPTURE refused: the scan's light " +
                      std::to_string(c.pattern_index - count_) + " is '" +
                      lights_[c.pattern_index - count_] + "'",
                  "captures refused (mismatch)");
  }
  char& seen = logged_[c.pattern_index + 1];  // CheckCapture bounded the index by its count.
  if (seen) {
    d.verdict = Verdict::kDuplicate;
    d.why = what +
            ": captured twice (is a second camera on this station's bus, under the same "
            "station id?); the scan cannot say which frame is its own";
    d.counter = "captures twice";
    return d;
  }
  seen = true;
  if (++received_ == count_ + lights + 1) {
    Bounded(&closed_, scan_id_);  // Whole: nothing more of it.
    scan_id_ = 0;
    session_ = 0;
  }
  d.verdict = Verdict::kRecord;
  return d;
}

ScanGate::Decision ScanGate::AdmitCalibration(const calibration_t& c) {
  if (c.scan_id == 0) return Refuse("", "");  // The projector's business (next scan on).
  std::lock_guard<std::mutex> lock(mutex_);
  const std::string what = ScanText(c.scan_id) + ": CALIBRATION from " + c.source + " refused: ";
  if (c.scan_id != scan_id_ || c.session != session_) {
    return Refuse(what +
                      "not the scan in progress with its session (a calibration applies from "
                      "the next scan)",
                  "calibrations refused");
  }
  if (calibration_ || received_ > 0) {
    return Refuse(
        what + "the scan has " +
            (calibration_ ? std::string("its calibration already") : "begun (its texture is in)") +
            " (a calibration applies from the next scan)",
        "calibrations refused");
  }
  calibration_ = true;
  return Record();
}

void ScanGate::Close(int64_t scan_id) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!Closed(scan_id)) Bounded(&closed_, scan_id);
  if (scan_id == scan_id_) {
    scan_id_ = 0;
    session_ = 0;
  }
}

bool ScanGate::Closed(int64_t scan_id) const { return Contains(closed_, scan_id); }

bool ScanGate::Resume(int64_t scan_id, int64_t session, std::string* why) {
  const ScanFolder folder = ScanFolder::For(data_, scan_id);
  *why = "no SCAN_STARTED of it from this station's projector";
  if (scan_id <= 0 || Contains(not_resumable_, scan_id) || !PathExists(folder.log())) return false;
  // Once per folder: a flood of captures for it reads it once.
  Bounded(&not_resumable_, scan_id);
  if (PathExists(folder.scan_yaml()) || PathExists(folder.failed())) {
    *why = "the scan is over (" + folder.raw() + " holds it whole, or failed.txt)";
    Bounded(&closed_, scan_id);
    return false;
  }
  lcm::LogFile log(folder.log(), "r");
  const lcm::LogEvent* e = log.good() ? log.readNextEvent() : nullptr;
  scan_started_t started;
  if (!e || e->channel != channel::kScanStarted || !SafeDecode(e->data, e->datalen, &started) ||
      started.scan_id != scan_id || started.pattern_count <= 0 ||
      started.pattern_count > kMaxPatterns) {
    *why = folder.log() + " does not begin with the scan's SCAN_STARTED";
    return false;
  }
  std::vector<std::string> names;
  std::string bad;
  if (!LightNames(started, &names, &bad)) {
    *why = folder.log() + ": its SCAN_STARTED: " + bad;
    return false;
  }
  if (started.session != session) {
    *why = "its session is not the one " + folder.log() + " began with";
    return false;
  }
  if (scan_id_ != 0) {
    *why = "scan " + std::to_string(scan_id_) + " is in progress";
    return false;
  }
  scan_id_ = scan_id;
  session_ = session;
  count_ = started.pattern_count;
  lights_ = std::move(names);
  logged_.assign(count_ + lights_.size() + 1, false);
  received_ = 0;
  calibration_ = true;  // Whatever it had, it keeps.
  for (e = log.readNextEvent(); e; e = log.readNextEvent()) {
    capture_t c;
    if (e->channel != channel::kCapture || !SafeDecode(e->data, e->datalen, &c) ||
        c.scan_id != scan_id || c.session != session || c.pattern_index < -1 ||
        c.pattern_index >= static_cast<int>(logged_.size()) - 1 || logged_[c.pattern_index + 1]) {
      continue;
    }
    logged_[c.pattern_index + 1] = true;
    ++received_;
  }
  not_resumable_.pop_back();  // It was.
  return true;
}

}  // namespace vellum::station
