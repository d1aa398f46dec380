// What every daemon's main shares: the common flags (--url, --station, --config, --data,
// --pace), and a
// main() wrapper that turns bad flags and config files into a clear message and exit status 2.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/geometry/calibration.h"
#include "flags/flags.h"
#include "station/node.h"

namespace vellum::station {

// --url, --station, --config, and (with_data) --data and --pace.
std::vector<Flags::Spec> DaemonFlagSpecs(bool with_data);

// --station ID, for every process on the bus (daemons and the CLI's bus commands).
Flags::Spec StationSpec();
// Sets the node's station from --station; an invalid id throws UsageError.
void SetStationFromFlags(const Flags& flags, Node* node);

// --calibration FILE of the processing daemons: used when a scan comes without CALIBRATION.
Flags::Spec FallbackCalibrationSpec();
// The calibration that flag names, or none when it is empty; a bad file throws UsageError.
std::optional<Calibration> FallbackCalibrationFromFlags(const Flags& flags);

// Parses the flags (printing --help), opens the node and calls body; returns the exit status.
int DaemonMain(int argc, char** argv, const std::string& process, const std::string& summary,
               const std::vector<Flags::Spec>& specs,
               const std::function<int(const Flags&, Node&)>& body);

// Throws UsageError with the options' own reason when they fail their Check() (every daemon's
// options, once its flags are read).
template <class Options>
void RequireValid(const Options& options) {
  if (std::string why; !options.Check(&why)) throw UsageError(why);
}

// Wraps f so that calling it often (Node::Run's tick) runs it at most once a second.
std::function<void()> EverySecond(std::function<void()> f);

// Seconds since `start`.
double SecondsSince(int64_t start_utime);

}  // namespace vellum::station
