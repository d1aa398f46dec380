// Running a command as a user would, for the tests that drive vellum's programs and the tools
// beside them (exiftool, curl, chromium).
#pragma once

#include <sys/wait.h>

#include <cstdio>
#include <string>
#include <utility>

namespace vellum {

struct ShellResult {
  int exit_code = -1;  // -1: killed by a signal (a crash).
  std::string output;  // Its stdout and stderr.
};

inline ShellResult Shell(const std::string& command) {
  ShellResult r;
  FILE* p = popen((command + " 2>&1").c_str(), "r");
  if (!p) return r;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof(buf), p)) > 0) r.output.append(buf, n);
  const int status = pclose(p);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

// The same, for tests that keep the exit code apart: the output, and the exit code in `*status`.
inline std::string Shell(const std::string& command, int* status) {
  ShellResult r = Shell(command);
  *status = r.exit_code;
  return std::move(r.output);
}

}  // namespace vellum
