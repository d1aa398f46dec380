// A V4L2 camera: the format chosen from what the camera offers (v4l2_formats.h) and converted
// here, mmap streaming, automatic exposure and gain switched off and read back, and the frame
// whose exposure starts after a given time. It talks to the device through V4l2Device
// (v4l2_device.h): libv4l2 at the station, a recorded camera in the tests.
//
// What it never takes as a capture: a frame the driver flagged as bad, a short or undecodable
// one, one that started before the pattern was shown. Sequence gaps (frames the driver dropped)
// are counted. A camera unplugged mid-scan fails that frame's request clearly; the next request
// opens it again once it is back.
#pragma once

#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "daemons/camera/camera.h"
#include "daemons/camera/v4l2_device.h"

namespace vellum::station {

struct V4l2Options {
  std::string device = "/dev/video0";
  cv::Size size{1600, 1200};
  // "auto" (the camera's best, v4l2_formats.h), "GREY" (gray first) or a FourCC to insist on.
  std::string format = "auto";
  // V4L2_CID_EXPOSURE_ABSOLUTE in 100 us units (or, where the camera has only V4L2_CID_EXPOSURE,
  // in its own units); -1: keep the camera's value, still with automatic exposure off.
  int exposure = -1;
  int gain = -1;  // V4L2_CID_GAIN (or V4L2_CID_ANALOGUE_GAIN); -1: keep the camera's value.

  bool Check(std::string* why) const;
};

class V4l2Camera : public Camera {
 public:
  explicit V4l2Camera(std::unique_ptr<V4l2Device> device = MakeLibV4l2Device());
  ~V4l2Camera() override;
  // An error names the device and what it would not do. A camera whose automatic exposure or
  // gain will not switch off opens (for the preview and focusing) but refuses every scan.
  Status Open(const V4l2Options& options);
  cv::Size size() const { return size_; }
  uint32_t format() const { return fourcc_; }
  std::string Describe() const override;
  // The first good frame whose exposure starts at or after request.shown_utime: 8-bit, or
  // 16-bit where the camera gives more than 8 bits; gray or BGR as the format gives.
  Status Capture(const FrameRequest& request, cv::Mat* image, int64_t* exposure_utime) override;
  Status Preview(cv::Mat* image, int64_t* exposure_utime) override;
  // Frames the driver dropped (sequence gaps) and frames it gave that were not taken (the
  // error flag, short or undecodable), in all.
  int64_t dropped_frames() const override { return dropped_; }
  int64_t bad_frames() const override { return bad_; }
  // The raw and monochrome formats (Bayer, GREY, Y10-Y16); not YUYV, MJPEG or BGR3, which a
  // camera's processing gamma-encodes.
  bool linear() const override;
  int64_t frame_period_us() const override { return frame_period_us_; }
  // V4L2_CID_EXPOSURE_ABSOLUTE's value (100 us units) as read back; 0 where the camera has
  // only its own units.
  int64_t exposure_us() const override { return exposure_us_; }

 private:
  Status Negotiate();
  Status SwitchOffAutomatics();
  Status SetControl(uint32_t id, int value, const char* name, int* read_back);
  Status StartStreaming();
  Status CaptureAfter(int64_t after_utime, cv::Mat* image, int64_t* exposure_utime);
  Status Gone(const std::string& what);  // The device went away: closes it, says so.
  // Opens a camera that went away again: at once for a scan's frame, at most once a second for
  // the preview.
  Status ReopenIfGone(bool at_once);
  void Close();

  std::unique_ptr<V4l2Device> device_;
  V4l2Options options_;
  bool open_ = false;
  std::string card_, format_why_, controls_;
  std::string refusal_;  // Why scans are refused (automatic exposure or gain left on).
  cv::Size size_;
  uint32_t fourcc_ = 0;
  uint32_t bytes_per_line_ = 0;
  int64_t frame_period_us_ = 0;
  int64_t exposure_us_ = 0;
  struct Buffer {
    void* start = nullptr;
    size_t length = 0;
  };
  std::vector<Buffer> buffers_;
  bool have_sequence_ = false;
  uint32_t last_sequence_ = 0;
  int64_t dropped_ = 0, bad_ = 0;
  int64_t next_reopen_us_ = 0;  // CLOCK_MONOTONIC: no second try before it.
};

}  // namespace vellum::station
