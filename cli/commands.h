// The subcommands of the `vellum` tool. Each returns the process exit status.
#pragma once

#include <string>
#include <vector>

#include "flags/flags.h"

namespace vellum {

// The exit status of a scan restored with warnings: written, but not to be delivered unchecked.
constexpr int kExitDoubtful = 3;

int RunPatterns(const std::vector<std::string>& args);
int RunRender(const std::vector<std::string>& args);
int RunProcess(const std::vector<std::string>& args);
int RunScan(const std::vector<std::string>& args);
int RunWatch(const std::vector<std::string>& args);
int RunSheet(const std::vector<std::string>& args);
int RunManifest(const std::vector<std::string>& args);
int RunIiif(const std::vector<std::string>& args);
int RunCollection(const std::vector<std::string>& args);
int RunExport(const std::vector<std::string>& args);
int RunImport(const std::vector<std::string>& args);
int RunCalibrate(const std::vector<std::string>& args);
int RunCalibrateCapture(const std::vector<std::string>& args);
int RunCalibrateLatency(const std::vector<std::string>& args);

}  // namespace vellum
