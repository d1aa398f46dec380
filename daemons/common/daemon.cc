#include "daemons/common/daemon.h"

#include <chrono>
#include <filesystem>
#include <memory>
#include <opencv2/core/utility.hpp>

#include "core/io/calibration_io.h"
#include "core/io/scan_io.h"
#include "daemons/common/messages.h"
#include "daemons/common/scan_store.h"
#include "vellum/calibration_t.hpp"
#include "vellum/capture_t.hpp"

namespace vellum::station {
namespace {

constexpr size_t kKeepScans = 8;  // Per-scan inputs kept (a few scans in flight at most).

template <class T>
void KeepRecent(std::map<int64_t, T>* m) {
  while (m->size() > kKeepScans) m->erase(m->begin());  // Scan ids grow with time.
}

}  // namespace

std::vector<Flags::Spec> DaemonFlagSpecs(bool with_data) {
  std::vector<Flags::Spec> specs = {
      {"url", "URL", "LCM bus", kDefaultUrl},
      {"config", "FILE", "YAML file of flag: value (the command line wins)", ""},
  };
  if (with_data) {
    specs.push_back(
        {"data", "DIR", "station data folder: <DIR>/scan-<id>/raw and /results", "scans"});
    specs.push_back({"pace", "MB/S",
                     "publish chunked products at most this fast: below the slowest link and "
                     "what every receiver drains (udpm drops a message with any lost fragment)",
                     "100"});
  }
  return specs;
}

Flags::Spec FallbackCalibrationSpec() {
  return {"calibration", "FILE", "calibration used when a scan comes without a CALIBRATION message",
          ""};
}

int DaemonMain(int argc, char** argv, const std::string& process, const std::string& summary,
               const std::vector<Flags::Spec>& specs,
               const std::function<int(const Flags&, Node&)>& body) {
  Flags flags(process, summary, specs);
  try {
    if (!flags.Parse(std::vector<std::string>(argv + 1, argv + argc))) return 0;
  } catch (const UsageError& e) {
    std::fprintf(stderr, "%s: %s\n", process.c_str(), e.what());
    return 2;
  }
  cv::setNumThreads(cv::getNumberOfCPUs());
  try {
    Node node(process, flags.Get("url"));
    if (flags.Has("pace")) node.SetPace(flags.GetDouble("pace", 0.1, 10000) * 1e6);
    return body(flags, node);
  } catch (const UsageError& e) {
    std::fprintf(stderr, "%s: %s\n", process.c_str(), e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: error: %s\n", process.c_str(), e.what());
    return 1;
  }
}

CalibrationBook::CalibrationBook(Node* node, const std::string& fallback_path,
                                 const std::string& data_dir)
    : node_(node), data_dir_(data_dir) {
  if (!fallback_path.empty()) {
    const Status s = ReadCalibration(fallback_path, &fallback_);
    if (!s.ok()) throw UsageError(s.message());
    has_fallback_ = true;
  }
  node->Subscribe<calibration_t>(channel::kCalibration, [this](const calibration_t& msg) {
    Calibration c;
    const Status s = FromMessage(msg, &c);
    if (!s.ok()) {
      node_->Error("CALIBRATION of scan " + std::to_string(msg.scan_id) + ": " + s.message(),
                   msg.scan_id);
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    by_scan_[msg.scan_id] = c;
    KeepRecent(&by_scan_);
  });
}

Status CalibrationBook::Get(int64_t scan_id, Calibration* calibration) const {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = by_scan_.find(scan_id);
  if (it != by_scan_.end()) {
    *calibration = it->second;
    return Status::Ok();
  }
  const std::string recorded = ScanFolder::For(data_dir_, scan_id).calibration();
  if (!data_dir_.empty() && std::filesystem::exists(recorded)) {
    const Status s = ReadCalibration(recorded, calibration);
    return s.ok() ? s : Status::Error("scan " + std::to_string(scan_id) + ": " + s.message());
  }
  if (has_fallback_) {
    *calibration = fallback_;
    return Status::Ok();
  }
  return Status::Error("scan " + std::to_string(scan_id) +
                       ": no CALIBRATION message for it, and no --calibration file configured");
}

TextureBook::TextureBook(Node* node, const std::string& data_dir)
    : node_(node), data_dir_(data_dir) {
  node->Subscribe<capture_t>(channel::kCapture, [this](const capture_t& msg) {
    if (msg.pattern_index != -1) return;
    cv::Mat texture;
    const Status s = FromMessage(msg.image, &texture);
    if (!s.ok()) {
      node_->Error("CAPTURE texture of scan " + std::to_string(msg.scan_id) + ": " + s.message(),
                   msg.scan_id);
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    by_scan_[msg.scan_id] = texture;
    KeepRecent(&by_scan_);
  });
}

Status TextureBook::Get(int64_t scan_id, cv::Mat* texture) const {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = by_scan_.find(scan_id);
  if (it == by_scan_.end()) {
    const std::string raw = ScanFolder::For(data_dir_, scan_id).raw();
    if (!data_dir_.empty() && ReadTexture(raw, texture).ok()) return Status::Ok();
    return Status::Error("scan " + std::to_string(scan_id) +
                         ": its texture (CAPTURE, pattern -1) never arrived, and " + raw +
                         " has none");
  }
  *texture = it->second;
  return Status::Ok();
}

std::function<void()> EverySecond(std::function<void()> f) {
  auto last = std::make_shared<std::chrono::steady_clock::time_point>();
  return [f = std::move(f), last] {
    const auto now = std::chrono::steady_clock::now();
    if (now - *last < std::chrono::seconds(1)) return;
    *last = now;
    f();
  };
}

double SecondsSince(int64_t start_utime) { return (NowUtime() - start_utime) * 1e-6; }

}  // namespace vellum::station
