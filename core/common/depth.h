// Sample depth: the station's images are 8 or 16 bits a sample (a deeper camera's texture and
// lights are 16-bit, full scale). Where a step wants 8 bits (a picture, a preview, the outline's
// cues), it takes them here: the top 8 bits, rounded.
#pragma once

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace vellum {

// `image` at 8 bits a sample: itself (not copied) when it is 8-bit, else scaled by 255/65535.
inline cv::Mat EightBit(const cv::Mat& image) {
  if (image.depth() == CV_8U) return image;
  cv::Mat out;
  image.convertTo(out, CV_8U, 255.0 / 65535.0);
  return out;
}

// `image` as 8-bit gray: a colour one's luma (taken at its own depth), then EightBit.
inline cv::Mat EightBitGray(const cv::Mat& image) {
  cv::Mat gray = image;
  if (gray.channels() == 3) cv::cvtColor(gray, gray, cv::COLOR_BGR2GRAY);
  return EightBit(gray);
}

// `image` as an 8-bit BGR picture to draw on or show: EightBit, a gray one in three channels.
// Itself (not copied) when it is 8-bit BGR already.
inline cv::Mat EightBitBgr(const cv::Mat& image) {
  cv::Mat out = EightBit(image);
  if (out.channels() == 1) cv::cvtColor(out, out, cv::COLOR_GRAY2BGR);
  return out;
}

}  // namespace vellum
