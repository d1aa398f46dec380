#include "daemons/camera/v4l2_camera.h"

#include <linux/videodev2.h>

#include <cerrno>
#include <cstring>
#include <ctime>

#include "daemons/camera/v4l2_formats.h"

namespace vellum::station {
namespace {

int64_t ClockUs(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1000000 + ts.tv_nsec / 1000;
}

std::string Errno() { return std::strerror(errno); }

// Whether the camera has the control, enabled.
bool HasControl(V4l2Device* device, uint32_t id) {
  v4l2_queryctrl q{};
  q.id = id;
  return device->Ioctl(VIDIOC_QUERYCTRL, &q) == 0 && !(q.flags & V4L2_CTRL_FLAG_DISABLED);
}

}  // namespace

bool V4l2Options::Check(std::string* why) const {
  if (device.empty() || size.width < 1 || size.height < 1 || exposure < -1 || gain < -1 ||
      format.empty()) {
    *why =
        "v4l2: the device and format must be named, the size at least 1 x 1, exposure and "
        "gain >= -1";
    return false;
  }
  return true;
}

V4l2Camera::V4l2Camera(std::unique_ptr<V4l2Device> device) : device_(std::move(device)) {}

V4l2Camera::~V4l2Camera() { Close(); }

void V4l2Camera::Close() {
  if (!open_) return;
  v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  device_->Ioctl(VIDIOC_STREAMOFF, &type);
  for (Buffer& b : buffers_) device_->Unmap(b.start, b.length);
  buffers_.clear();
  device_->Close();
  open_ = false;
}

Status V4l2Camera::Open(const V4l2Options& o) {
  if (std::string why; !o.Check(&why)) return Status::Error(why);
  Close();
  options_ = o;
  have_sequence_ = false;
  if (device_->Open(o.device) < 0) return Status::Error(o.device + ": cannot open: " + Errno());
  open_ = true;
  Status s = Negotiate();
  if (s.ok()) s = SwitchOffAutomatics();
  if (s.ok()) s = StartStreaming();
  if (!s.ok()) {
    Close();
    return Status::Error(o.device + ": " + s.message());
  }
  return Status::Ok();
}

Status V4l2Camera::Negotiate() {
  v4l2_capability cap{};
  if (device_->Ioctl(VIDIOC_QUERYCAP, &cap) < 0)
    return Status::Error("not a V4L2 device: " + Errno());
  const uint32_t caps =
      (cap.capabilities & V4L2_CAP_DEVICE_CAPS) ? cap.device_caps : cap.capabilities;
  card_ = reinterpret_cast<const char*>(cap.card);
  if (!(caps & V4L2_CAP_VIDEO_CAPTURE) || !(caps & V4L2_CAP_STREAMING)) {
    return Status::Error("'" + card_ + "' is not a streaming capture device (a camera's other " +
                         "node, metadata or output?)");
  }
  std::vector<DeviceFormat> offered;
  for (uint32_t i = 0;; ++i) {
    v4l2_fmtdesc d{};
    d.index = i;
    d.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (device_->Ioctl(VIDIOC_ENUM_FMT, &d) < 0) break;
    DeviceFormat f;
    f.fourcc = d.pixelformat;
    f.emulated = d.flags & V4L2_FMT_FLAG_EMULATED;
    f.compressed = d.flags & V4L2_FMT_FLAG_COMPRESSED;
    for (uint32_t k = 0;; ++k) {
      v4l2_frmsizeenum fs{};
      fs.index = k;
      fs.pixel_format = d.pixelformat;
      if (device_->Ioctl(VIDIOC_ENUM_FRAMESIZES, &fs) < 0 || fs.type != V4L2_FRMSIZE_TYPE_DISCRETE)
        break;
      f.sizes.emplace_back(static_cast<int>(fs.discrete.width),
                           static_cast<int>(fs.discrete.height));
    }
    offered.push_back(f);
  }
  Status s = ChooseFormat(offered, options_.format, options_.size, &fourcc_, &format_why_);
  if (!s.ok()) return s;
  v4l2_format fmt{};
  fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  fmt.fmt.pix.width = options_.size.width;
  fmt.fmt.pix.height = options_.size.height;
  fmt.fmt.pix.pixelformat = fourcc_;
  fmt.fmt.pix.field = V4L2_FIELD_NONE;
  if (device_->Ioctl(VIDIOC_S_FMT, &fmt) < 0) {
    return Status::Error("cannot set " + format_why_.substr(0, format_why_.find(';')) + ": " +
                         Errno());
  }
  size_ = cv::Size(static_cast<int>(fmt.fmt.pix.width), static_cast<int>(fmt.fmt.pix.height));
  if (fmt.fmt.pix.pixelformat != fourcc_ || size_ != options_.size) {
    return Status::Error("asked for " + FourccText(fourcc_) + " at " +
                         std::to_string(options_.size.width) + "x" +
                         std::to_string(options_.size.height) + ", the camera set " +
                         FourccText(fmt.fmt.pix.pixelformat) + " at " +
                         std::to_string(size_.width) + "x" + std::to_string(size_.height));
  }
  bytes_per_line_ = fmt.fmt.pix.bytesperline;
  v4l2_streamparm parm{};
  parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  frame_period_us_ = 0;
  if (device_->Ioctl(VIDIOC_G_PARM, &parm) == 0 && parm.parm.capture.timeperframe.denominator > 0) {
    frame_period_us_ = 1000000LL * parm.parm.capture.timeperframe.numerator /
                       parm.parm.capture.timeperframe.denominator;
  }
  return Status::Ok();
}

Status V4l2Camera::SetControl(uint32_t id, int value, const char* name, int* read_back) {
  v4l2_control c{};
  c.id = id;
  c.value = value;
  if (device_->Ioctl(VIDIOC_S_CTRL, &c) < 0) {
    return Status::Error("would not set " + std::string(name) + " to " + std::to_string(value) +
                         ": " + Errno());
  }
  v4l2_control g{};
  g.id = id;
  if (device_->Ioctl(VIDIOC_G_CTRL, &g) < 0) {
    return Status::Error("would not read " + std::string(name) + " back: " + Errno());
  }
  *read_back = g.value;
  return Status::Ok();
}

// A scan's frames must share one exposure and one gain: the patterns' contrast is read frame
// against frame. Automatic exposure and gain are switched off and read back; a camera that will
// not is refused for scans (refusal_), not silently used.
Status V4l2Camera::SwitchOffAutomatics() {
  refusal_.clear();
  controls_.clear();
  exposure_us_ = 0;
  int value = 0;
  auto refuse = [&](const std::string& why) {
    if (refusal_.empty()) refusal_ = why;
  };
  if (HasControl(device_.get(), V4L2_CID_EXPOSURE_AUTO)) {
    const Status s =
        SetControl(V4L2_CID_EXPOSURE_AUTO, V4L2_EXPOSURE_MANUAL, "manual exposure", &value);
    if (!s.ok()) {
      refuse("automatic exposure stays on: the camera " + s.message());
    } else if (value != V4L2_EXPOSURE_MANUAL) {
      refuse("automatic exposure stays on: asked manual (" + std::to_string(V4L2_EXPOSURE_MANUAL) +
             "), the camera reads " + std::to_string(value));
    }
  }
  if (HasControl(device_.get(), V4L2_CID_AUTOGAIN)) {
    const Status s = SetControl(V4L2_CID_AUTOGAIN, 0, "automatic gain off", &value);
    if (!s.ok() || value != 0) {
      refuse("automatic gain stays on: " +
             (s.ok() ? "the camera reads " + std::to_string(value) : "the camera " + s.message()));
    }
  }
  struct Setting {
    uint32_t id, fallback;
    int asked;
    const char* name;
  };
  for (const Setting& set :
       {Setting{V4L2_CID_EXPOSURE_ABSOLUTE, V4L2_CID_EXPOSURE, options_.exposure, "exposure"},
        Setting{V4L2_CID_GAIN, V4L2_CID_ANALOGUE_GAIN, options_.gain, "gain"}}) {
    const uint32_t id = HasControl(device_.get(), set.id)         ? set.id
                        : HasControl(device_.get(), set.fallback) ? set.fallback
                                                                  : 0;
    if (id == 0) continue;
    if (set.asked >= 0) {
      const Status s = SetControl(id, set.asked, set.name, &value);
      if (!s.ok()) return s;
    } else {
      v4l2_control g{};
      g.id = id;
      if (device_->Ioctl(VIDIOC_G_CTRL, &g) < 0) continue;
      value = g.value;
    }
    if (id == V4L2_CID_EXPOSURE_ABSOLUTE) exposure_us_ = 100LL * value;
    controls_ +=
        std::string(controls_.empty() ? "" : ", ") + set.name + " " + std::to_string(value);
    if (set.asked >= 0 && value != set.asked) {
      controls_ += " (asked " + std::to_string(set.asked) + ": the camera's nearest)";
    }
  }
  return Status::Ok();
}

Status V4l2Camera::StartStreaming() {
  v4l2_requestbuffers req{};
  req.count = 4;
  req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  req.memory = V4L2_MEMORY_MMAP;
  if (device_->Ioctl(VIDIOC_REQBUFS, &req) < 0 || req.count < 2) {
    return Status::Error("cannot get capture buffers: " + Errno());
  }
  for (uint32_t i = 0; i < req.count; ++i) {
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.index = i;
    if (device_->Ioctl(VIDIOC_QUERYBUF, &buf) < 0)
      return Status::Error("VIDIOC_QUERYBUF: " + Errno());
    Buffer b;
    b.length = buf.length;
    b.start = device_->Map(buf.length, buf.m.offset);
    if (b.start == nullptr) return Status::Error("cannot map a capture buffer: " + Errno());
    buffers_.push_back(b);
    if (device_->Ioctl(VIDIOC_QBUF, &buf) < 0) return Status::Error("VIDIOC_QBUF: " + Errno());
  }
  v4l2_buf_type type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  if (device_->Ioctl(VIDIOC_STREAMON, &type) < 0) {
    return Status::Error("cannot start streaming: " + Errno());
  }
  return Status::Ok();
}

bool V4l2Camera::linear() const {
  return fourcc_ != V4L2_PIX_FMT_YUYV && fourcc_ != V4L2_PIX_FMT_MJPEG &&
         fourcc_ != V4L2_PIX_FMT_BGR24;
}

std::string V4l2Camera::Describe() const {
  std::string text = "v4l2 camera " + options_.device + " '" + card_ + "': " + format_why_;
  if (!controls_.empty()) text += "; " + controls_;
  if (!refusal_.empty()) text += "; REFUSES SCANS: " + refusal_;
  return text;
}

Status V4l2Camera::Capture(const FrameRequest& request, cv::Mat* image, int64_t* exposure_utime) {
  if (Status s = ReopenIfGone(/*at_once=*/true); !s.ok()) return s;
  if (!refusal_.empty()) {
    return Status::Error("camera " + options_.device + " refuses to scan: " + refusal_ +
                         ". A scan's frames must share one exposure and gain; see its controls " +
                         "with v4l2-ctl -d " + options_.device + " --list-ctrls");
  }
  return CaptureAfter(request.shown_utime, image, exposure_utime);
}

Status V4l2Camera::Preview(cv::Mat* image, int64_t* exposure_utime) {
  if (Status s = ReopenIfGone(/*at_once=*/false); !s.ok()) return s;
  return CaptureAfter(ClockUs(CLOCK_REALTIME), image, exposure_utime);
}

Status V4l2Camera::Gone(const std::string& what) {
  const std::string why = Errno();
  Close();
  next_reopen_us_ = 0;
  return Status::Error("camera " + options_.device + " is gone (" + what + ": " + why +
                       "): unplugged or reset, this frame was not taken; vellum-camera opens " +
                       "it again once it is back");
}

Status V4l2Camera::ReopenIfGone(bool at_once) {
  if (open_) return Status::Ok();
  const int64_t now = ClockUs(CLOCK_MONOTONIC);
  if (!at_once && now < next_reopen_us_) {
    return Status::Error("camera " + options_.device + " is not back yet");
  }
  const Status s = Open(options_);
  if (!s.ok()) {
    next_reopen_us_ = now + 1000000;  // The preview tries once a second; a scan at once.
    return Status::Error("camera " + options_.device + " is not back yet: " + s.message());
  }
  return Status::Ok();
}

Status V4l2Camera::CaptureAfter(int64_t after_utime, cv::Mat* image, int64_t* exposure_utime) {
  if (!open_) return Status::Error("camera " + options_.device + " is not open");
  // Buffer timestamps are CLOCK_MONOTONIC: move the deadline onto that clock.
  const int64_t offset = ClockUs(CLOCK_REALTIME) - ClockUs(CLOCK_MONOTONIC);
  const int64_t after_mono = after_utime - offset;
  for (int tries = 0; tries < 200; ++tries) {
    const int r = device_->Poll(2000);
    if (r < 0)
      return errno == ENODEV ? Gone("waiting for a frame")
                             : Status::Error("camera: poll: " + Errno());
    if (r == 0) return Status::Error("camera " + options_.device + ": no frame within 2 s");
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    if (device_->Ioctl(VIDIOC_DQBUF, &buf) < 0) {
      if (errno == EAGAIN) continue;
      if (errno == ENODEV || errno == EIO) return Gone("VIDIOC_DQBUF");
      return Status::Error("camera: VIDIOC_DQBUF: " + Errno());
    }
    if (have_sequence_ && buf.sequence > last_sequence_ + 1) {
      dropped_ += buf.sequence - last_sequence_ - 1;
    }
    have_sequence_ = true;
    last_sequence_ = buf.sequence;
    int64_t start = static_cast<int64_t>(buf.timestamp.tv_sec) * 1000000 + buf.timestamp.tv_usec;
    // Stamped at the end of the frame (or the driver does not say): back to its start, at
    // the latest. Only a start-of-exposure stamp is taken as it is.
    if ((buf.flags & V4L2_BUF_FLAG_TSTAMP_SRC_MASK) != V4L2_BUF_FLAG_TSTAMP_SRC_SOE) {
      start -= frame_period_us_;
    }
    bool taken = false;
    if (buf.flags & V4L2_BUF_FLAG_ERROR) {
      ++bad_;
    } else if (start >= after_mono && buf.index < buffers_.size()) {
      const Status s = ConvertFrame(fourcc_, size_, bytes_per_line_,
                                    static_cast<const uint8_t*>(buffers_[buf.index].start),
                                    buf.bytesused, image);
      taken = s.ok();
      if (!taken) ++bad_;
    }
    if (device_->Ioctl(VIDIOC_QBUF, &buf) < 0) {
      return errno == ENODEV ? Gone("VIDIOC_QBUF")
                             : Status::Error("camera: VIDIOC_QBUF: " + Errno());
    }
    if (taken) {
      *exposure_utime = start + offset;
      return Status::Ok();
    }
  }
  return Status::Error("camera " + options_.device +
                       ": 200 frames and none good that started after the pattern was shown");
}

}  // namespace vellum::station
