// The display's lag: from handing an image to the projector's display (its vsync passed) to
// the image on the page, as the camera sees it. Measured from flashes: the projector turns
// white (from black) or black (from white) at a known time and the camera takes frames around
// it, each with its exposure's start and its mean level. A frame whose exposure the change fell
// within saw part of each level: with its exposure's length known, where the change fell is
// read off its level (the camera is linear in the light), to a fraction of a frame. A frame
// before the change and one after it bound it. Pure: the projector (at start-up) and `vellum
// calibrate latency` use it on what the bus brought.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/common/status.h"

namespace vellum {

struct FlashFrames {
  int64_t handed_us = 0;          // When the flash was handed to the display.
  bool white = true;              // To white (from black), or to black (from white).
  int64_t exposure_us = 0;        // Each frame's exposure; 0: not known (bounds only).
  std::vector<int64_t> start_us;  // Each frame's exposure start, in time order.
  std::vector<double> level;      // Each frame's mean level.
};

struct DisplayLag {
  Status status = Status::Error("not measured");
  int flashes = 0;  // Given.
  int seen = 0;     // Whose change a frame saw.
  int exact = 0;    // Whose change fell within a frame's exposure.
  // Over the exact ones; with none, the bounds' narrowest (median = the upper bound).
  double median_ms = 0, min_ms = 0, max_ms = 0;
  // What the projector must wait after vsync for a frame to show the new image: the slowest
  // flash seen, or the tightest upper bound, and a millisecond.
  double wait_ms = 0;
  double refresh_hz = 0;  // The display's (0: not known).
  double refreshes() const { return refresh_hz > 0 ? median_ms * refresh_hz / 1000 : 0; }
  // "display lag 33.3 ms (2.00 refreshes at 60 Hz): ..."
  std::string Describe() const;
};

// An error when the flashes' levels do not differ (the camera does not see the projector) or
// no flash was seen changing.
DisplayLag EstimateDisplayLag(const std::vector<FlashFrames>& flashes, double refresh_hz);

}  // namespace vellum
