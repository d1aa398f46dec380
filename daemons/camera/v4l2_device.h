// The seam between vellum's V4L2 camera and a device: the handful of calls V4L2 capture makes
// (open, ioctl, mmap, poll, close). The station's is libv4l2 on a /dev/video node; a test stands
// in a recorded device (recorded_device.h) with a real camera's formats, controls and frames.
#pragma once

#include <cstddef>
#include <memory>
#include <string>

namespace vellum::station {

class V4l2Device {
 public:
  virtual ~V4l2Device() = default;
  // Each returns -1 and sets errno on failure, as the system calls do.
  virtual int Open(const std::string& path) = 0;
  virtual int Ioctl(unsigned long request, void* arg) = 0;
  // The buffer at `offset` (VIDIOC_QUERYBUF's m.offset), mapped for reading and writing; nullptr
  // and errno on failure.
  virtual void* Map(size_t length, long offset) = 0;
  virtual void Unmap(void* start, size_t length) = 0;
  // 1 when a frame can be dequeued, 0 after timeout_ms with none, -1 on an error (errno; ENODEV
  // once the device is gone).
  virtual int Poll(int timeout_ms) = 0;
  virtual void Close() = 0;
};

// A /dev/video node through libv4l2. libv4l2 lists, besides the device's own formats, those it
// can convert them to (flagged V4L2_FMT_FLAG_EMULATED); the camera prefers the device's own.
std::unique_ptr<V4l2Device> MakeLibV4l2Device();

}  // namespace vellum::station
