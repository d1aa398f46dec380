// Whether a capture shows its own pattern: a camera whose exposure starts before the projector
// has the pattern on screen (a display lag longer than the handshake waits) takes a frame of the
// previous pattern, or one that mixes the two (an exposure straddling the change; a rolling
// shutter's rows on either side of it). Such a frame must never be decoded: its stripes are
// quietly wrong where the two patterns differ.
//
// Two checks, on 8-bit gray frames of one size:
//  - a Gray-code pair: a pattern and its inverse add up to white plus black wherever the
//    projector lights the page (the camera is linear there: offset plus gain times light);
//    a frame that shows its predecessor, or a share of it, does not. This holds for stripes
//    too fine for the camera as well (blur is linear), and only for a linear camera: one that
//    applies a gamma curve (a webcam's YUYV or MJPEG) makes every blurred edge miss, so the
//    camera says whether it is linear (Camera::linear);
//  - a steady frame: the camera's next frame under the same pattern shows the same picture, up
//    to noise; for the frames that have no pair (white, black).
#pragma once

#include <opencv2/core.hpp>
#include <string>

namespace vellum {

struct FrameCheckOptions {
  // A lit pixel: white above black by at least this much (8-bit levels).
  int min_contrast = 24;
  // A pair's pixel is off when its sum misses white plus black by more than this share of
  // white minus black: a frame holding a third of another pattern misses by a third at every
  // lit pixel where the two differ; noise (a few levels) and blur (linear: a pair's edges still
  // add up) stay far below it.
  double pair_tolerance = 0.2;
  // A frame mixes two patterns when more than this share of the lit pixels are off (a mix is
  // off wherever the two patterns differ: half the page and more).
  double mixed_share = 0.2;
  // A steady frame: at most this share of pixels differ by more than `changed_levels` from the
  // next frame (noise of a few levels reaches `changed_levels` in far fewer).
  int changed_levels = 24;
  double changed_share = 0.02;
  bool Check(std::string* why) const;
};

// The share of lit pixels (white - black >= min_contrast) where pattern + inverse misses
// white + black by more than pair_tolerance (white - black); 0 without lit pixels. Above
// mixed_share, a frame of the pair mixes two patterns.
double PairMismatch(const cv::Mat& pattern, const cv::Mat& inverse, const cv::Mat& white,
                    const cv::Mat& black, const FrameCheckOptions& options = {});

// The share of pixels where two frames differ by more than changed_levels.
double FrameChange(const cv::Mat& a, const cv::Mat& b, const FrameCheckOptions& options = {});

}  // namespace vellum
