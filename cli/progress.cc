#include "cli/progress.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>

namespace vellum {

Progress::Progress() : Progress(isatty(2) != 0) {}

Progress::Progress(bool enabled) : enabled_(enabled), start_(std::chrono::steady_clock::now()) {}

Progress::~Progress() { Clear(); }

void Progress::Update(const std::string& stage, double fraction) {
  if (!enabled_) return;
  fraction = std::clamp(fraction, 0.0, 1.0);
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  char left[32] = "";
  if (fraction > 0.02 && fraction < 1) {
    const double remaining = elapsed * (1 - fraction) / fraction;
    std::snprintf(left, sizeof(left), remaining < 10 ? ", ~%.1f s left" : ", ~%.0f s left",
                  remaining);
  }
  std::fprintf(stderr, "\r\033[K[%3.0f%%] %s%s", 100 * fraction, stage.c_str(), left);
  std::fflush(stderr);
  shown_ = true;
}

void Progress::Clear() {
  if (!enabled_ || !shown_) return;
  std::fputs("\r\033[K", stderr);
  std::fflush(stderr);
  shown_ = false;
}

}  // namespace vellum
