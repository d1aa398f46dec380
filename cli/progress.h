// Progress of long work on a terminal: one line, rewritten in place, with the stage, the
// percentage done and an estimate of the time left. Silent when stderr is not a terminal
// (logs, CI, systemd), so scripts see only results and errors.
#pragma once

#include <chrono>
#include <string>

namespace vellum {

class Progress {
 public:
  // `enabled` defaults to whether stderr is a terminal.
  Progress();
  explicit Progress(bool enabled);
  ~Progress();

  // Shows `stage` with `fraction` (0..1) of the whole work done.
  void Update(const std::string& stage, double fraction);
  // Clears the line (before printing anything else, and at the end).
  void Clear();
  bool enabled() const { return enabled_; }

 private:
  bool enabled_;
  bool shown_ = false;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace vellum
