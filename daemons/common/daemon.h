// What every daemon's main shares: the common flags (--url, --config, --data), the per-scan
// inputs that arrive on their own channels (calibration, texture), and a main() wrapper that
// turns bad flags and config files into a clear message and exit status 2.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "cli/flags.h"
#include "core/common/status.h"
#include "core/geometry/calibration.h"
#include "daemons/common/node.h"

namespace vellum::station {

// --url, --config, and (with_data) --data.
std::vector<Flags::Spec> DaemonFlagSpecs(bool with_data);

// --calibration FILE of the processing daemons: used when a scan comes without CALIBRATION.
Flags::Spec FallbackCalibrationSpec();

// Parses the flags (printing --help), opens the node and calls body; returns the exit status.
int DaemonMain(int argc, char** argv, const std::string& process, const std::string& summary,
               const std::vector<Flags::Spec>& specs,
               const std::function<int(const Flags&, Node&)>& body);

// The calibration of each scan, from CALIBRATION messages; for a scan whose message this
// process has not seen (it restarted since), the one the decoder recorded in the scan's folder
// under `data_dir`; else the fallback file.
class CalibrationBook {
 public:
  // `fallback_path` may be empty (then a scan without a CALIBRATION message fails).
  CalibrationBook(Node* node, const std::string& fallback_path, const std::string& data_dir);
  Status Get(int64_t scan_id, Calibration* calibration) const;

 private:
  Node* node_;
  mutable std::mutex mutex_;
  std::map<int64_t, Calibration> by_scan_;
  bool has_fallback_ = false;
  Calibration fallback_;
  std::string data_dir_;
};

// The texture (CAPTURE with pattern_index -1) of each recent scan; for a scan whose texture
// this process has not seen (it restarted since), the one the decoder recorded under
// `data_dir`.
class TextureBook {
 public:
  TextureBook(Node* node, const std::string& data_dir);
  Status Get(int64_t scan_id, cv::Mat* texture) const;

 private:
  Node* node_;
  mutable std::mutex mutex_;
  std::map<int64_t, cv::Mat> by_scan_;
  std::string data_dir_;
};

// Wraps f so that calling it often (Node::Run's tick) runs it at most once a second.
std::function<void()> EverySecond(std::function<void()> f);

// Seconds since `start`.
double SecondsSince(int64_t start_utime);

}  // namespace vellum::station
