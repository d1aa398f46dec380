// A status for bad data or bad configuration (tier 2 of STYLE.md): says what and where.
#pragma once

#include <string>
#include <utility>

namespace vellum {

// [[nodiscard]]: a Status dropped on the floor is an error no one hears of.
class [[nodiscard]] Status {
 public:
  static Status Ok() { return Status(true, ""); }
  static Status Error(std::string message) { return Status(false, std::move(message)); }

  bool ok() const { return ok_; }
  const std::string& message() const { return message_; }

 private:
  Status(bool ok, std::string message) : ok_(ok), message_(std::move(message)) {}
  bool ok_;
  std::string message_;
};

}  // namespace vellum
