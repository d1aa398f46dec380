#include "io/json.h"

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>

#include "io/write_whole.h"

namespace vellum {

Json JsonNumber(double value) {
  if (!std::isfinite(value)) return nullptr;
  if (value == std::floor(value) && std::fabs(value) < 1e15) {
    return static_cast<long long>(value);
  }
  return value;
}

Status WriteJsonFile(const std::string& path, const Json& json) {
  // Text that is not UTF-8 (a path in another encoding) is written with U+FFFD, never thrown.
  return WriteTextFile(path, json.dump(2, ' ', false, Json::error_handler_t::replace) + "\n");
}

Status WriteTextFile(const std::string& path, const std::string& text) {
  return WriteWhole(path, [&](const std::string& part) {
    std::ofstream out(part, std::ios::trunc);
    out << text;
    out.close();
    if (!out) return Status::Error(part + ": cannot write (" + std::strerror(errno) + ")");
    return Status::Ok();
  });
}

}  // namespace vellum
