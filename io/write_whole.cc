#include "io/write_whole.h"

#include <fcntl.h>  // AT_FDCWD
#include <stdio.h>  // renameat2, RENAME_EXCHANGE (glibc 2.28)

#include <cerrno>
#include <cstring>
#include <filesystem>

namespace vellum {

namespace fs = std::filesystem;

std::string PartName(const std::string& path) {
  const fs::path p(path);
  return (p.parent_path() / (".part-" + p.filename().string())).string();
}

Status WriteWhole(const std::string& path,
                  const std::function<Status(const std::string& temporary)>& write) {
  const std::string part = PartName(path);
  Status s = write(part);
  std::error_code ec;
  if (s.ok()) {
    fs::rename(part, path, ec);
    if (ec) s = Status::Error(path + ": cannot put in place (" + ec.message() + ")");
  }
  if (!s.ok()) {
    fs::remove(part, ec);
    // The error as the writer gave it, naming the product rather than its temporary name.
    std::string message = s.message();
    for (size_t at = message.find(part); at != std::string::npos;
         at = message.find(part, at + path.size())) {
      message.replace(at, part.size(), path);
    }
    return Status::Error(message);
  }
  return Status::Ok();
}

Status ReplaceFolder(const std::string& part, const std::string& folder) {
  const fs::path target(folder);
  const fs::path old = target.parent_path() / (".old-" + target.filename().string());
  std::error_code ec;
  fs::remove_all(old, ec);  // A killed run's.
  const bool had = fs::exists(target, ec);
  // One step where the filesystem can swap two names (Linux's renameat2): at every instant
  // `folder` is wholly the old one or wholly the new, even if the process is killed between.
  if (had && renameat2(AT_FDCWD, part.c_str(), AT_FDCWD, folder.c_str(), RENAME_EXCHANGE) == 0) {
    fs::remove_all(part, ec);  // Now the old one.
    return Status::Ok();
  }
  if (had) {
    fs::rename(target, old, ec);
    if (ec)
      return Status::Error(folder + ": cannot move the earlier one aside (" + ec.message() + ")");
  }
  fs::rename(part, target, ec);
  if (ec) {
    const std::string why = ec.message();
    if (had) fs::rename(old, target, ec);
    return Status::Error(folder + ": cannot put in place (" + why + ")");
  }
  if (had) fs::remove_all(old, ec);
  return Status::Ok();
}

}  // namespace vellum
