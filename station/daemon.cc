#include "station/daemon.h"

#include <chrono>
#include <filesystem>
#include <memory>
#include <opencv2/core/utility.hpp>

#include "core/common/text.h"
#include "io/calibration_io.h"

namespace vellum::station {

std::vector<Flags::Spec> DaemonFlagSpecs(bool with_data) {
  std::vector<Flags::Spec> specs = {
      {"url", "URL", "LCM bus", kDefaultUrl},
      StationSpec(),
      {"config", "FILE", "YAML file of flag: value (the command line wins)", ""},
      {"stuck-after", "S",
       "a job on the worker running longer is a hung stage: reported, and systemd's watchdog "
       "is no longer fed (systemd restarts the daemon)",
       "600"},
      {"stop-grace", "S",
       "on SIGTERM, wait this long for the worker's jobs, then exit anyway (status 1)", "20"},
  };
  if (with_data) {
    specs.push_back(
        {"data", "DIR", "station data folder: <DIR>/scan-<id>/raw and /results", "scans"});
    specs.push_back({"pace", "MB/S",
                     "publish chunked products at most this fast: below the slowest link and "
                     "what every receiver drains (udpm drops a message with any lost fragment)",
                     "800"});
  }
  return specs;
}

Flags::Spec StationSpec() {
  return {"station", "ID",
          "this station's id: messages of other stations on the bus are ignored (and counted); "
          "every process of a station has the same",
          kDefaultStation};
}

void SetStationFromFlags(const Flags& flags, Node* node) {
  const std::string id = flags.Get("station");
  const std::string why = CheckStationId(id);
  if (!why.empty()) throw UsageError("--station \"" + Printable(id, 80) + "\": " + why);
  node->SetStation(id);
}

Flags::Spec FallbackCalibrationSpec() {
  return {"calibration", "FILE", "calibration used when a scan comes without a CALIBRATION message",
          ""};
}

std::optional<Calibration> FallbackCalibrationFromFlags(const Flags& flags) {
  const std::string path = flags.Get("calibration");
  if (path.empty()) return std::nullopt;
  Calibration c;
  const Status s = ReadCalibration(path, &c);
  if (!s.ok()) throw UsageError(s.message());
  return c;
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
    SetStationFromFlags(flags, &node);
    node.SetWorkLimits(flags.GetDouble("stuck-after", 1, 86400),
                       flags.GetDouble("stop-grace", 0.1, 3600));
    if (flags.Has("pace")) node.SetPace(flags.GetDouble("pace", 0.1, 10000) * 1e6);
    node.ExitWhenHung();
    return body(flags, node);
  } catch (const UsageError& e) {
    std::fprintf(stderr, "%s: %s\n", process.c_str(), e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: error: %s\n", process.c_str(), e.what());
    return 1;
  }
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
