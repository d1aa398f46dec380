#include "core/patterns/display_lag.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace vellum {
namespace {

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

std::string Ms(double ms) {
  char text[32];
  std::snprintf(text, sizeof text, "%.1f", ms);
  return text;
}

// A frame that saw less than this share of the new level saw none of it; more than 1 minus it,
// all of it (noise and the level's own flicker).
constexpr double kSeen = 0.1;
// The flashes' white and black must differ by this much (levels) to be told apart.
constexpr double kMinContrast = 20;
// The handshake's margin over the slowest flash: the display's and the camera's clocks jitter
// by some tens of microseconds.
constexpr double kJitterMs = 1;

}  // namespace

std::string DisplayLag::Describe() const {
  if (!status.ok()) return "display lag not measured: " + status.message();
  std::string text = "display lag " + Ms(median_ms) + " ms";
  if (refresh_hz > 0) {
    char r[64];
    std::snprintf(r, sizeof r, " (%.2f refreshes at %.0f Hz)", refreshes(), refresh_hz);
    text += r;
  }
  text += exact > 0
              ? ": median of " + std::to_string(exact) + " flashes caught within an exposure, " +
                    Ms(min_ms) + " to " + Ms(max_ms) + " ms"
              : ": at most, from frames before and after each change (none fell within "
                "an exposure)";
  return text + "; " + std::to_string(seen) + " of " + std::to_string(flashes) +
         " flashes seen; the handshake waits " + Ms(wait_ms) + " ms after vsync";
}

DisplayLag EstimateDisplayLag(const std::vector<FlashFrames>& flashes, double refresh_hz) {
  DisplayLag lag;
  lag.flashes = static_cast<int>(flashes.size());
  lag.refresh_hz = refresh_hz;
  // Each level as the camera sees it steady: the last frame of each flash.
  std::vector<double> whites, blacks;
  // A flash is taken when its frames are whole: a level and a start each, finite, in order.
  const auto whole = [](const FlashFrames& f) {
    if (f.level.empty() || f.level.size() != f.start_us.size() || f.exposure_us < 0) return false;
    for (size_t j = 0; j < f.level.size(); ++j) {
      if (!std::isfinite(f.level[j]) || (j > 0 && f.start_us[j] <= f.start_us[j - 1])) return false;
    }
    return true;
  };
  for (const FlashFrames& f : flashes) {
    if (!whole(f)) continue;
    (f.white ? whites : blacks).push_back(f.level.back());
  }
  const double white = Median(whites), black = Median(blacks);
  if (whites.empty() || blacks.empty() || white - black < kMinContrast) {
    lag.status =
        Status::Error("the camera saw no flash (white " + Ms(white) + ", black " + Ms(black) +
                      "): is it looking at the projector's light, with its "
                      "exposure fixed?");
    return lag;
  }
  std::vector<double> exact;
  double lower = -std::numeric_limits<double>::infinity();
  double upper = std::numeric_limits<double>::infinity();
  for (const FlashFrames& f : flashes) {
    if (!whole(f)) continue;
    const auto share = [&](size_t j) {
      const double s = (f.level[j] - black) / (white - black);
      return std::clamp(f.white ? s : 1 - s, 0.0, 1.0);
    };
    size_t j = 0;
    while (j < f.level.size() && share(j) <= kSeen) ++j;
    if (j == f.level.size()) continue;
    ++lag.seen;
    const double e = static_cast<double>(f.exposure_us);
    // In doubles: a hostile message's times may be anything, and their difference overflow.
    const double handed = static_cast<double>(f.handed_us);
    const double start = static_cast<double>(f.start_us[j]) - handed;
    if (e > 0 && share(j) < 1 - kSeen) {
      exact.push_back((start + e * (1 - share(j))) / 1000);  // Where the change fell.
      continue;
    }
    upper = std::min(upper, (start + e * kSeen) / 1000);
    if (j > 0) lower = std::max(lower, (static_cast<double>(f.start_us[j - 1]) - handed) / 1000);
  }
  if (!exact.empty()) {
    lag.exact = static_cast<int>(exact.size());
    lag.median_ms = Median(exact);
    lag.min_ms = *std::min_element(exact.begin(), exact.end());
    lag.max_ms = *std::max_element(exact.begin(), exact.end());
    lag.wait_ms = lag.max_ms + kJitterMs;
  } else if (std::isfinite(upper)) {
    lag.median_ms = lag.max_ms = upper;
    lag.wait_ms = upper + kJitterMs;
    lag.min_ms = std::isfinite(lower) ? std::max(0.0, lower) : 0.0;
  } else {
    lag.status = Status::Error("no flash was seen changing within its frames (" +
                               std::to_string(lag.flashes) + " flashes)");
    return lag;
  }
  // A lag beyond a second is no display's: clocks that disagree, or frames not of these flashes.
  if (!(lag.min_ms >= -kJitterMs && lag.wait_ms < 1000)) {
    lag.status = Status::Error("a lag of " + Ms(lag.median_ms) + " ms (" + Ms(lag.min_ms) + " to " +
                               Ms(lag.max_ms) + ") is no display's: are the camera's and the " +
                               "projector's clocks one?");
    return lag;
  }
  lag.status = Status::Ok();
  return lag;
}

}  // namespace vellum
