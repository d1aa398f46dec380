#include "daemons/camera/v4l2_camera.h"

#include <fcntl.h>
#include <libv4l2.h>
#include <linux/videodev2.h>
#include <sys/mman.h>
#include <sys/select.h>

#include <cerrno>
#include <cstring>
#include <ctime>

namespace vellum::station {
namespace {

int Ioctl(int fd, unsigned long request, void* arg) {
  int r;
  do {
    r = v4l2_ioctl(fd, request, arg);
  } while (r == -1 && errno == EINTR);
  return r;
}

int64_t ClockUs(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1000000 + ts.tv_nsec / 1000;
}

}  // namespace

V4l2Camera::~V4l2Camera() { Close(); }

void V4l2Camera::Close() {
  if (fd_ < 0) return;
  v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  Ioctl(fd_, VIDIOC_STREAMOFF, &type);
  for (Buffer& b : buffers_) v4l2_munmap(b.start, b.length);
  buffers_.clear();
  v4l2_close(fd_);
  fd_ = -1;
}

bool V4l2Options::Check(std::string* why) const {
  if (device.empty() || size.width < 1 || size.height < 1 || exposure < -1 || gain < -1) {
    *why = "v4l2: the device must be named, its size at least 1 x 1, exposure and gain >= -1";
    return false;
  }
  return true;
}

Status V4l2Camera::Open(const V4l2Options& o) {
  if (std::string why; !o.Check(&why)) return Status::Error(why);
  Close();
  device_ = o.device;
  const std::string& dev = o.device;
  fd_ = v4l2_open(dev.c_str(), O_RDWR | O_NONBLOCK, 0);
  if (fd_ < 0) return Status::Error(dev + ": cannot open: " + std::strerror(errno));
  v4l2_format fmt{};
  fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  fmt.fmt.pix.width = o.size.width;
  fmt.fmt.pix.height = o.size.height;
  const uint32_t want = o.gray ? V4L2_PIX_FMT_GREY : V4L2_PIX_FMT_BGR24;
  const char* want_name = o.gray ? "GREY" : "BGR24";
  channels_ = o.gray ? 1 : 3;
  fmt.fmt.pix.pixelformat = want;
  fmt.fmt.pix.field = V4L2_FIELD_NONE;
  if (Ioctl(fd_, VIDIOC_S_FMT, &fmt) < 0) {
    return Status::Error(dev + ": cannot set " + std::to_string(o.size.width) + "x" +
                         std::to_string(o.size.height) + " " + want_name + ": " +
                         std::strerror(errno));
  }
  if (fmt.fmt.pix.pixelformat != want) {
    return Status::Error(dev + ": libv4l2 cannot convert this camera's format to " + want_name);
  }
  size_ = cv::Size(static_cast<int>(fmt.fmt.pix.width), static_cast<int>(fmt.fmt.pix.height));
  if (size_ != o.size) {
    return Status::Error(dev + ": asked for " + std::to_string(o.size.width) + "x" +
                         std::to_string(o.size.height) + ", the camera gives " +
                         std::to_string(size_.width) + "x" + std::to_string(size_.height));
  }
  auto set_control = [&](uint32_t id, int value, const char* name) -> Status {
    v4l2_control c{};
    c.id = id;
    c.value = value;
    if (Ioctl(fd_, VIDIOC_S_CTRL, &c) < 0) {
      return Status::Error(dev + ": cannot set " + name + " to " + std::to_string(value) + ": " +
                           std::strerror(errno));
    }
    return Status::Ok();
  };
  if (o.exposure >= 0) {
    Status s = set_control(V4L2_CID_EXPOSURE_AUTO, V4L2_EXPOSURE_MANUAL, "manual exposure");
    if (s.ok()) s = set_control(V4L2_CID_EXPOSURE_ABSOLUTE, o.exposure, "exposure");
    if (!s.ok()) return s;
  }
  if (o.gain >= 0) {
    Status s = set_control(V4L2_CID_GAIN, o.gain, "gain");
    if (!s.ok()) return s;
  }
  v4l2_streamparm parm{};
  parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (Ioctl(fd_, VIDIOC_G_PARM, &parm) == 0 && parm.parm.capture.timeperframe.denominator > 0) {
    frame_period_us_ = 1000000LL * parm.parm.capture.timeperframe.numerator /
                       parm.parm.capture.timeperframe.denominator;
  }
  v4l2_requestbuffers req{};
  req.count = 4;
  req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  req.memory = V4L2_MEMORY_MMAP;
  if (Ioctl(fd_, VIDIOC_REQBUFS, &req) < 0 || req.count < 2) {
    return Status::Error(dev + ": cannot get capture buffers: " + std::strerror(errno));
  }
  for (uint32_t i = 0; i < req.count; ++i) {
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.index = i;
    if (Ioctl(fd_, VIDIOC_QUERYBUF, &buf) < 0) return Status::Error(dev + ": VIDIOC_QUERYBUF");
    Buffer b;
    b.length = buf.length;
    b.start = v4l2_mmap(nullptr, buf.length, PROT_READ | PROT_WRITE, MAP_SHARED, fd_, buf.m.offset);
    if (b.start == MAP_FAILED) return Status::Error(dev + ": cannot map a capture buffer");
    buffers_.push_back(b);
    if (Ioctl(fd_, VIDIOC_QBUF, &buf) < 0) return Status::Error(dev + ": VIDIOC_QBUF");
  }
  v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (Ioctl(fd_, VIDIOC_STREAMON, &type) < 0) {
    return Status::Error(dev + ": cannot start streaming: " + std::strerror(errno));
  }
  return Status::Ok();
}

std::string V4l2Camera::Describe() const {
  return "v4l2 camera " + device_ + ", " + std::to_string(size_.width) + "x" +
         std::to_string(size_.height) + (channels_ == 1 ? " GREY" : " BGR3");
}

Status V4l2Camera::Capture(const FrameRequest& request, cv::Mat* image, int64_t* exposure_utime) {
  return CaptureAfter(request.shown_utime, image, exposure_utime);
}

Status V4l2Camera::Preview(cv::Mat* image, int64_t* exposure_utime) {
  return CaptureAfter(ClockUs(CLOCK_REALTIME), image, exposure_utime);
}

Status V4l2Camera::CaptureAfter(int64_t after_utime, cv::Mat* image, int64_t* exposure_utime) {
  if (fd_ < 0) return Status::Error("camera not open");
  // Buffer timestamps are CLOCK_MONOTONIC: move the deadline onto that clock.
  const int64_t offset = ClockUs(CLOCK_REALTIME) - ClockUs(CLOCK_MONOTONIC);
  const int64_t after_mono = after_utime - offset;
  for (int tries = 0; tries < 100; ++tries) {
    fd_set fds;
    FD_ZERO(&fds);
    FD_SET(fd_, &fds);
    timeval tv{2, 0};
    const int r = select(fd_ + 1, &fds, nullptr, nullptr, &tv);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) return Status::Error("camera: no frame within 2 s");
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    if (Ioctl(fd_, VIDIOC_DQBUF, &buf) < 0) {
      if (errno == EAGAIN) continue;
      return Status::Error(std::string("camera: VIDIOC_DQBUF: ") + std::strerror(errno));
    }
    int64_t start = static_cast<int64_t>(buf.timestamp.tv_sec) * 1000000 + buf.timestamp.tv_usec;
    if ((buf.flags & V4L2_BUF_FLAG_TSTAMP_SRC_MASK) == V4L2_BUF_FLAG_TSTAMP_SRC_EOF) {
      start -= frame_period_us_;  // Stamped at the end of the frame: back to its start.
    }
    const bool good =
        start >= after_mono && buf.bytesused >= static_cast<uint32_t>(size_.area() * channels_);
    if (good) {
      cv::Mat(size_, CV_8UC(channels_), buffers_[buf.index].start).copyTo(*image);
      *exposure_utime = start + offset;
    }
    if (Ioctl(fd_, VIDIOC_QBUF, &buf) < 0) return Status::Error("camera: VIDIOC_QBUF");
    if (good) return Status::Ok();
  }
  return Status::Error("camera: 100 frames and none started after the pattern was shown");
}

}  // namespace vellum::station
