// Sample depth: the station's images are 8 or 16 bits a sample (a deeper camera's texture and
// lights are 16-bit, full scale). Where a step wants 8 bits (a picture, a preview, the outline's
// cues), it takes them here: the top 8 bits, rounded.
#pragma once

#include <opencv2/core.hpp>

namespace vellum {

// `image` at 8 bits a sample: itself (not copied) when it is 8-bit, else scaled by 255/65535.
inline cv::Mat EightBit(const cv::Mat& image) {
  if (image.depth() == CV_8U) return image;
  cv::Mat out;
  image.convertTo(out, CV_8U, 255.0 / 65535.0);
  return out;
}

}  // namespace vellum
