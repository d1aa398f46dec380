// Writing a file whole or not at all: a product cut short (a full disk, a killed process) never
// lies where the whole product would, looking like one.
#pragma once

#include <functional>
#include <string>

#include "core/common/status.h"

namespace vellum {

// Writes `path` through `write`, which is given a temporary name beside it (the same folder and
// extension, hidden: ".part-<name>"), then renames it into place once `write` succeeded; on a
// failure the temporary file is removed, `path` is left as it was, and the error names `path`.
Status WriteWhole(const std::string& path,
                  const std::function<Status(const std::string& temporary)>& write);

// The temporary name WriteWhole gives `path`.
std::string PartName(const std::string& path);

}  // namespace vellum
