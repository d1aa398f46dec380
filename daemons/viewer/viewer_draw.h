// The operator's window drawn from the viewer's state (viewer_state.h): the header with the
// progress (red with a failure), on the left the live preview (clipped pixels red, the leaf
// outlined, the leaf hint in cyan, NO SIGNAL when the camera falls silent), its histogram, every
// daemon's status and the next scan's identity (or its form); in the middle the texture with the
// leaf's outline, the depth and the strain; on the right the restored page under its quality
// verdict, its warnings in amber; over them the contact sheet, a light prompt in blue and a
// failure in red. A pure function of the state, the window's size and the time.
#pragma once

#include <opencv2/core.hpp>
#include <vector>

#include "daemons/viewer/viewer_state.h"
#include "station/clock.h"

namespace vellum::station {

// The film strip's height along the window's bottom, its margin below it included (pixels).
inline constexpr int kFilmStripHeight = 88;

// Where the parts went on the window (for the mouse).
struct ViewerLayout {
  cv::Rect preview;  // The live preview's pixels; empty when none is drawn (none yet, zoomed).
  // The film strip's tiles, left to right: the session's scans in book order (as many as fit).
  std::vector<cv::Rect> strip;
};

// The window's picture (8-bit BGR of `size`) at time `now`, and its layout.
cv::Mat DrawViewer(const ViewerState& state, cv::Size size, Clock::time_point now,
                   ViewerLayout* layout);

}  // namespace vellum::station
