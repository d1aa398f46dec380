// Reads an X window dump (XWD, as Xvfb -fbdir keeps its screen: Xvfb_screen0) into a BGR
// image: the screenshot of a virtual display, for tests of windows under Xvfb.
#pragma once

#include <cstdint>
#include <fstream>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace vellum::testing {

inline cv::Mat ReadXwd(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                             std::istreambuf_iterator<char>());
  if (bytes.size() < 100) return cv::Mat();
  auto field = [&](int k) {  // The header's 32-bit big-endian fields.
    const uint8_t* p = bytes.data() + 4 * k;
    return static_cast<uint32_t>(p[0]) << 24 | p[1] << 16 | p[2] << 8 | p[3];
  };
  const uint32_t header_size = field(0), width = field(4), height = field(5);
  const uint32_t byte_order = field(7), bits_per_pixel = field(11), bytes_per_line = field(12);
  const uint32_t ncolors = field(19);
  const size_t offset = header_size + 12 * static_cast<size_t>(ncolors);
  if (bits_per_pixel != 32 ||
      offset + static_cast<size_t>(bytes_per_line) * height > bytes.size()) {
    return cv::Mat();
  }
  cv::Mat out(static_cast<int>(height), static_cast<int>(width), CV_8UC3);
  for (uint32_t y = 0; y < height; ++y) {
    const uint8_t* row = bytes.data() + offset + static_cast<size_t>(y) * bytes_per_line;
    for (uint32_t x = 0; x < width; ++x) {
      const uint8_t* px = row + 4 * x;
      // LSBFirst (0): B G R X in memory; MSBFirst: X R G B.
      out.at<cv::Vec3b>(y, x) =
          byte_order == 0 ? cv::Vec3b(px[0], px[1], px[2]) : cv::Vec3b(px[3], px[2], px[1]);
    }
  }
  return out;
}

}  // namespace vellum::testing
