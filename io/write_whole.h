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

// Puts the folder `part` (written beside `folder`, on the same filesystem) in the place of
// `folder`: renamed into place when `folder` is absent; else the two are swapped in one step
// (renameat2's RENAME_EXCHANGE: a reader, or a process killed at any instant, sees `folder`
// wholly old or wholly new) and the old one, now under `part`'s name, removed. Where the
// filesystem cannot swap (some network filesystems), `folder` is moved aside (hidden,
// ".old-<name>"), `part` renamed in, and the old one removed. On a failure `folder` is left as it
// was; the caller removes `part`.
Status ReplaceFolder(const std::string& part, const std::string& folder);

}  // namespace vellum
