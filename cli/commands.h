// The subcommands of the `vellum` tool. Each returns the process exit status.
#pragma once

#include <string>
#include <vector>

#include "cli/flags.h"
#include "core/patterns/patterns.h"

namespace vellum {

// Pattern flags shared by `patterns` and `render`.
std::vector<Flags::Spec> PatternFlagSpecs();
PatternOptions PatternOptionsFromFlags(const Flags& flags, cv::Size projector);

int RunPatterns(const std::vector<std::string>& args);
int RunRender(const std::vector<std::string>& args);
int RunProcess(const std::vector<std::string>& args);

}  // namespace vellum
