// A recorded V4L2 camera for the tests: what a real camera's driver answers (its capabilities,
// formats, frame sizes, controls and frame period, from a JSON file in tests/data/v4l2/), and
// frames of a given scene encoded in the format streamed, with sequence numbers and timestamps
// as the driver stamps them (start of exposure or end of frame, on CLOCK_MONOTONIC). Frames
// come as fast as they are asked for, each stamped one frame period after the last.
//
// Faults a test asks for: every Nth frame dropped (a sequence gap), a frame flagged
// V4L2_BUF_FLAG_ERROR, the camera unplugged after a number of frames (and plugged back in).
#pragma once

#include <cstdint>
#include <map>
#include <opencv2/core.hpp>
#include <set>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "daemons/camera/v4l2_device.h"

namespace vellum::station {

struct RecordedControl {
  uint32_t id = 0;
  int type = 1;  // V4L2_CTRL_TYPE_INTEGER, _BOOLEAN or _MENU.
  int minimum = 0, maximum = 0, step = 1, default_value = 0;
  int value = 0;
  // What the camera does when set: "" takes the value (clamped to its range), "keeps" answers
  // success and keeps its value (firmware that ignores the request), "refuses" fails with EIO.
  std::string on_set;
};

struct RecordedCamera {
  std::string name;  // The file's stem: uvc_webcam, mono_industrial, bayer_rggb.
  std::string driver, card;
  int64_t frame_period_us = 33333;
  bool end_of_frame_stamps = false;  // V4L2_BUF_FLAG_TSTAMP_SRC_EOF, else _SOE.
  struct Format {
    uint32_t fourcc = 0;
    bool compressed = false;
    std::vector<cv::Size> sizes;
  };
  std::vector<Format> formats;
  std::map<uint32_t, RecordedControl> controls;
};

// Reads tests/data/v4l2/<name>.json. An error names the file and the key.
Status ReadRecordedCamera(const std::string& path, RecordedCamera* camera);

class RecordedDevice : public V4l2Device {
 public:
  // `scene`: what the camera sees, 16-bit BGR at any size (resized to the frame).
  RecordedDevice(RecordedCamera camera, cv::Mat scene);

  // Faults, set before or while streaming.
  void DropEvery(int n) { drop_every_ = n; }  // Sequence numbers n-1, 2n-1, ... never come.
  void FlagError(uint32_t sequence) { flagged_.insert(sequence); }
  void UnplugAfter(int frames) { unplug_after_ = frames; }  // Frames delivered, then ENODEV.
  void Replug() {
    unplugged_ = false;
    unplug_after_ = -1;
  }
  RecordedControl& control(uint32_t id) { return camera_.controls.at(id); }
  // The CLOCK_MONOTONIC start of exposure of the frame with this sequence number.
  int64_t StartOf(uint32_t sequence) const;
  int opens() const { return opens_; }

  int Open(const std::string& path) override;
  int Ioctl(unsigned long request, void* arg) override;
  void* Map(size_t length, long offset) override;
  void Unmap(void*, size_t) override {}
  int Poll(int timeout_ms) override;
  void Close() override { open_ = false; }

 private:
  int SetFormat(void* arg);
  int Dequeue(void* arg);
  int Control(unsigned long request, void* arg);
  std::vector<uint8_t> Encode() const;  // The scene in the current format.

  RecordedCamera camera_;
  cv::Mat scene_;
  bool open_ = false, streaming_ = false, unplugged_ = false;
  int opens_ = 0;
  uint32_t fourcc_ = 0;
  cv::Size size_;
  uint32_t bytes_per_line_ = 0, size_image_ = 0;
  std::vector<std::vector<uint8_t>> buffers_;
  std::vector<bool> queued_;
  std::vector<uint8_t> frame_;  // The encoded scene, once per format.
  int64_t t0_us_ = 0;           // CLOCK_MONOTONIC at STREAMON.
  uint32_t next_sequence_ = 0;
  int delivered_ = 0;
  int drop_every_ = 0, unplug_after_ = -1;
  std::set<uint32_t> flagged_;
};

}  // namespace vellum::station
