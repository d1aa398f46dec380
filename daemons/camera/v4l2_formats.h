// Which of a V4L2 camera's formats the station takes, and a frame in it turned into the image
// the station wants: 8-bit or, where the camera gives more, 16-bit (full scale), gray or BGR.
// Pure: no device (the camera, v4l2_camera.h, asks the device what it offers).
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"

namespace vellum::station {

// One format a device offers (VIDIOC_ENUM_FMT), with its discrete frame sizes
// (VIDIOC_ENUM_FRAMESIZES; empty: stepwise or not listed, the driver decides).
struct DeviceFormat {
  uint32_t fourcc = 0;
  bool emulated = false;    // libv4l2's conversion, not the camera's own.
  bool compressed = false;  // MJPEG.
  std::vector<cv::Size> sizes;
};

// "YUYV", "Y16 ", ... (unprintable bytes as '?').
std::string FourccText(uint32_t fourcc);
// "Y16" -> 'Y16 ' (padded with spaces); 0 for text longer than four characters.
uint32_t FourccFromText(const std::string& text);
// Bits per sample the station keeps of a format it takes (8, 10, 12 or 16); 0: not taken.
int FormatBits(uint32_t fourcc);
bool FormatIsColour(uint32_t fourcc);

// The format to stream at `size`: `want` is "auto" (the camera's best: colour where it has
// colour, then the most bits, uncompressed before MJPEG, its own before libv4l2's), "GREY"
// (gray first: a monochrome pattern camera) or a FourCC to insist on. Sets *why to one line for
// the log. An error names what the device offers.
Status ChooseFormat(const std::vector<DeviceFormat>& offered, const std::string& want,
                    cv::Size size, uint32_t* chosen, std::string* why);

// A frame as the device filled its buffer: `bytes_per_line` bytes a row (0: packed), `used`
// bytes in all. Gives CV_8UC1 / CV_8UC3 for 8-bit formats and CV_16UC1 / CV_16UC3 for deeper
// ones, scaled to the full 16 bits (a 10-bit 1023 becomes 65472). A short or undecodable frame
// is an error, never a picture.
Status ConvertFrame(uint32_t fourcc, cv::Size size, uint32_t bytes_per_line, const uint8_t* data,
                    size_t used, cv::Mat* image);

}  // namespace vellum::station
