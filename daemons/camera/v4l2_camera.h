// A V4L2 camera through libv4l2 (which converts the driver's formats, e.g. YUYV or MJPEG, to
// the BGR24 or GREY we ask for): mmap streaming, manual exposure and gain, and the frame whose
// exposure starts after a given time.
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "daemons/camera/camera.h"

namespace vellum::station {

struct V4l2Options {
  std::string device = "/dev/video0";
  cv::Size size{1600, 1200};
  bool gray = false;  // Ask for GREY (monochrome cameras) instead of BGR24.
  int exposure = -1;  // V4L2_CID_EXPOSURE_ABSOLUTE, 100 us units; -1 = leave as is.
  int gain = -1;      // V4L2_CID_GAIN; -1 = leave as is.

  bool Check(std::string* why) const;
};

class V4l2Camera : public Camera {
 public:
  ~V4l2Camera() override;
  Status Open(const V4l2Options& options);
  cv::Size size() const { return size_; }
  std::string Describe() const override;
  // The first frame whose exposure starts at or after request.shown_utime, as 8-bit BGR (or
  // gray); sets its exposure start.
  Status Capture(const FrameRequest& request, cv::Mat* image, int64_t* exposure_utime) override;
  Status Preview(cv::Mat* image, int64_t* exposure_utime) override;

 private:
  // The first frame whose exposure starts at or after `after_utime`.
  Status CaptureAfter(int64_t after_utime, cv::Mat* image, int64_t* exposure_utime);
  void Close();
  std::string device_;
  int fd_ = -1;
  cv::Size size_;
  int64_t frame_period_us_ = 0;
  int channels_ = 3;
  struct Buffer {
    void* start = nullptr;
    size_t length = 0;
  };
  std::vector<Buffer> buffers_;
};

}  // namespace vellum::station
