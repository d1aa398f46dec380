#include "daemons/camera/recorded_device.h"

#include <linux/videodev2.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <ctime>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "daemons/camera/v4l2_formats.h"

namespace vellum::station {
namespace {

int64_t MonotonicUs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1000000 + ts.tv_nsec / 1000;
}

int Fail(int error) {
  errno = error;
  return -1;
}

// The controls' names as v4l2-ctl lists them.
const std::map<std::string, uint32_t>& ControlIds() {
  static const std::map<std::string, uint32_t> ids = {
      {"auto_exposure", V4L2_CID_EXPOSURE_AUTO},
      {"exposure_time_absolute", V4L2_CID_EXPOSURE_ABSOLUTE},
      {"exposure", V4L2_CID_EXPOSURE},
      {"gain", V4L2_CID_GAIN},
      {"analogue_gain", V4L2_CID_ANALOGUE_GAIN},
      {"gain_automatic", V4L2_CID_AUTOGAIN},
      {"white_balance_automatic", V4L2_CID_AUTO_WHITE_BALANCE},
  };
  return ids;
}

int BytesPerPixel(uint32_t fourcc) {
  if (fourcc == V4L2_PIX_FMT_BGR24) return 3;
  if (fourcc == V4L2_PIX_FMT_YUYV) return 2;
  return FormatBits(fourcc) > 8 ? 2 : 1;
}

// RGGB: red at even rows and columns, blue at odd ones, green between.
cv::Mat Mosaic(const cv::Mat& bgr16) {
  cv::Mat out(bgr16.size(), CV_16U);
  for (int y = 0; y < out.rows; ++y) {
    for (int x = 0; x < out.cols; ++x) {
      const cv::Vec3w& p = bgr16.at<cv::Vec3w>(y, x);
      out.at<uint16_t>(y, x) = y % 2 == 0 ? (x % 2 == 0 ? p[2] : p[1]) : (x % 2 == 0 ? p[1] : p[0]);
    }
  }
  return out;
}

std::vector<uint8_t> Bytes(const cv::Mat& m) {
  const cv::Mat c = m.isContinuous() ? m : m.clone();
  return std::vector<uint8_t>(c.datastart, c.dataend);
}

}  // namespace

Status ReadRecordedCamera(const std::string& path, RecordedCamera* camera) {
  std::ifstream in(path);
  if (!in) return Status::Error(path + ": cannot read");
  try {
    const nlohmann::json j = nlohmann::json::parse(in);
    const size_t slash = path.find_last_of('/');
    camera->name = path.substr(slash + 1, path.rfind('.') - slash - 1);
    camera->driver = j.at("driver").get<std::string>();
    camera->card = j.at("card").get<std::string>();
    camera->frame_period_us = j.at("frame_period_us").get<int64_t>();
    camera->end_of_frame_stamps = j.at("timestamps").get<std::string>() == "end of frame";
    for (const auto& f : j.at("formats")) {
      RecordedCamera::Format format;
      format.fourcc = FourccFromText(f.at("fourcc").get<std::string>());
      format.compressed = f.value("compressed", false);
      for (const auto& s : f.at("sizes")) {
        const std::string text = s.get<std::string>();
        format.sizes.emplace_back(std::stoi(text), std::stoi(text.substr(text.find('x') + 1)));
      }
      camera->formats.push_back(format);
    }
    for (const auto& [name, c] : j.at("controls").items()) {
      const auto id = ControlIds().find(name);
      if (id == ControlIds().end()) return Status::Error(path + ": unknown control '" + name + "'");
      RecordedControl control;
      control.id = id->second;
      const std::string type = c.at("type").get<std::string>();
      control.type = type == "menu"   ? V4L2_CTRL_TYPE_MENU
                     : type == "bool" ? V4L2_CTRL_TYPE_BOOLEAN
                                      : V4L2_CTRL_TYPE_INTEGER;
      control.minimum = c.at("min").get<int>();
      control.maximum = c.at("max").get<int>();
      control.step = c.value("step", 1);
      control.default_value = c.at("default").get<int>();
      control.value = c.value("value", control.default_value);
      control.on_set = c.value("on_set", "");
      camera->controls[control.id] = control;
    }
  } catch (const std::exception& e) {
    return Status::Error(path + ": " + e.what());
  }
  return Status::Ok();
}

RecordedDevice::RecordedDevice(RecordedCamera camera, cv::Mat scene)
    : camera_(std::move(camera)), scene_(std::move(scene)) {
  const RecordedCamera::Format& first = camera_.formats.at(0);
  fourcc_ = first.fourcc;
  size_ = first.sizes.at(0);
}

int64_t RecordedDevice::StartOf(uint32_t sequence) const {
  return t0_us_ + static_cast<int64_t>(sequence) * camera_.frame_period_us;
}

int RecordedDevice::Open(const std::string&) {
  if (unplugged_) return Fail(ENOENT);
  open_ = true;
  streaming_ = false;
  buffers_.clear();
  ++opens_;
  return 0;
}

std::vector<uint8_t> RecordedDevice::Encode() const {
  cv::Mat bgr16;
  cv::resize(scene_, bgr16, size_, 0, 0, cv::INTER_AREA);
  cv::Mat bgr8, gray16;
  bgr16.convertTo(bgr8, CV_8U, 1.0 / 257);
  cv::cvtColor(bgr16, gray16, cv::COLOR_BGR2GRAY);
  const int bits = FormatBits(fourcc_);
  switch (fourcc_) {
    case V4L2_PIX_FMT_MJPEG: {
      std::vector<uint8_t> jpeg;
      cv::imencode(".jpg", bgr8, jpeg, {cv::IMWRITE_JPEG_QUALITY, 92});
      return jpeg;
    }
    case V4L2_PIX_FMT_BGR24:
      return Bytes(bgr8);
    case V4L2_PIX_FMT_YUYV: {
      // BT.601 at video range (Y 16-235, Cb and Cr 16-240), as UVC cameras give it; Cb and Cr
      // averaged over each pair of pixels.
      std::vector<uint8_t> out(static_cast<size_t>(size_.area()) * 2);
      for (int y = 0; y < size_.height; ++y) {
        for (int x = 0; x + 1 < size_.width; x += 2) {
          double luma[2], cb = 0, cr = 0;
          for (int k = 0; k < 2; ++k) {
            const cv::Vec3b p = bgr8.at<cv::Vec3b>(y, x + k);
            luma[k] = 16 + (65.481 * p[2] + 128.553 * p[1] + 24.966 * p[0]) / 255;
            cb += 0.5 * (128 + (-37.797 * p[2] - 74.203 * p[1] + 112.0 * p[0]) / 255);
            cr += 0.5 * (128 + (112.0 * p[2] - 93.786 * p[1] - 18.214 * p[0]) / 255);
          }
          uint8_t* q = &out[(static_cast<size_t>(y) * size_.width + x) * 2];
          q[0] = cv::saturate_cast<uint8_t>(luma[0]);
          q[1] = cv::saturate_cast<uint8_t>(cb);
          q[2] = cv::saturate_cast<uint8_t>(luma[1]);
          q[3] = cv::saturate_cast<uint8_t>(cr);
        }
      }
      return out;
    }
    default:
      break;
  }
  cv::Mat samples = FormatIsColour(fourcc_) ? Mosaic(bgr16) : gray16;
  cv::Mat shifted;
  samples.convertTo(shifted, CV_16U, 1.0 / (1 << (16 - bits)));
  if (bits == 8) shifted.convertTo(shifted, CV_8U);
  return Bytes(shifted);  // Little-endian on the hosts vellum runs on, as V4L2 stores them.
}

int RecordedDevice::SetFormat(void* arg) {
  auto* fmt = static_cast<v4l2_format*>(arg);
  const RecordedCamera::Format* format = &camera_.formats.front();  // As drivers do.
  for (const RecordedCamera::Format& f : camera_.formats) {
    if (f.fourcc == fmt->fmt.pix.pixelformat) format = &f;
  }
  const cv::Size asked(static_cast<int>(fmt->fmt.pix.width), static_cast<int>(fmt->fmt.pix.height));
  cv::Size best = format->sizes.front();
  for (cv::Size s : format->sizes) {
    if (std::abs(s.area() - asked.area()) < std::abs(best.area() - asked.area())) best = s;
  }
  fourcc_ = format->fourcc;
  size_ = best;
  bytes_per_line_ =
      format->compressed ? 0 : static_cast<uint32_t>(best.width * BytesPerPixel(fourcc_));
  size_image_ = format->compressed ? static_cast<uint32_t>(best.area() * 2)
                                   : bytes_per_line_ * static_cast<uint32_t>(best.height);
  fmt->fmt.pix.pixelformat = fourcc_;
  fmt->fmt.pix.width = static_cast<uint32_t>(best.width);
  fmt->fmt.pix.height = static_cast<uint32_t>(best.height);
  fmt->fmt.pix.bytesperline = bytes_per_line_;
  fmt->fmt.pix.sizeimage = size_image_;
  frame_ = Encode();
  return 0;
}

int RecordedDevice::Control(unsigned long request, void* arg) {
  const uint32_t id = request == VIDIOC_QUERYCTRL ? static_cast<v4l2_queryctrl*>(arg)->id
                                                  : static_cast<v4l2_control*>(arg)->id;
  const auto it = camera_.controls.find(id);
  if (it == camera_.controls.end()) return Fail(EINVAL);
  RecordedControl& c = it->second;
  if (request == VIDIOC_QUERYCTRL) {
    auto* q = static_cast<v4l2_queryctrl*>(arg);
    q->type = static_cast<uint32_t>(c.type);
    q->minimum = c.minimum;
    q->maximum = c.maximum;
    q->step = c.step;
    q->default_value = c.default_value;
    return 0;
  }
  auto* v = static_cast<v4l2_control*>(arg);
  if (request == VIDIOC_G_CTRL) {
    v->value = c.value;
    return 0;
  }
  if (c.on_set == "refuses") return Fail(EIO);
  if (c.on_set == "keeps") return 0;
  if (v->value < c.minimum || v->value > c.maximum) return Fail(ERANGE);
  c.value = c.minimum + (v->value - c.minimum) / c.step * c.step;
  return 0;
}

int RecordedDevice::Dequeue(void* arg) {
  auto* buf = static_cast<v4l2_buffer*>(arg);
  if (unplug_after_ >= 0 && delivered_ >= unplug_after_) unplugged_ = true;
  if (unplugged_) return Fail(ENODEV);
  const auto slot = std::find(queued_.begin(), queued_.end(), true);
  if (slot == queued_.end()) return Fail(EAGAIN);
  const uint32_t index = static_cast<uint32_t>(slot - queued_.begin());
  uint32_t sequence = next_sequence_++;
  if (drop_every_ > 0 && sequence % drop_every_ == static_cast<uint32_t>(drop_every_ - 1)) {
    sequence = next_sequence_++;  // The driver lost this one: the next comes with its number.
  }
  queued_[index] = false;
  std::vector<uint8_t>& data = buffers_[index];
  std::copy(frame_.begin(), frame_.begin() + std::min(frame_.size(), data.size()), data.begin());
  int64_t stamp = StartOf(sequence);
  if (camera_.end_of_frame_stamps) stamp += camera_.frame_period_us;
  buf->index = index;
  buf->sequence = sequence;
  buf->bytesused = static_cast<uint32_t>(std::min(frame_.size(), data.size()));
  buf->timestamp.tv_sec = stamp / 1000000;
  buf->timestamp.tv_usec = stamp % 1000000;
  buf->flags =
      V4L2_BUF_FLAG_MAPPED | V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC |
      (camera_.end_of_frame_stamps ? V4L2_BUF_FLAG_TSTAMP_SRC_EOF : V4L2_BUF_FLAG_TSTAMP_SRC_SOE);
  if (flagged_.count(sequence)) buf->flags |= V4L2_BUF_FLAG_ERROR;
  ++delivered_;
  return 0;
}

int RecordedDevice::Ioctl(unsigned long request, void* arg) {
  if (unplugged_) return Fail(ENODEV);
  if (!open_) return Fail(EBADF);
  switch (request) {
    case VIDIOC_QUERYCAP: {
      auto* cap = static_cast<v4l2_capability*>(arg);
      std::snprintf(reinterpret_cast<char*>(cap->driver), sizeof cap->driver, "%s",
                    camera_.driver.c_str());
      std::snprintf(reinterpret_cast<char*>(cap->card), sizeof cap->card, "%s",
                    camera_.card.c_str());
      cap->device_caps = V4L2_CAP_VIDEO_CAPTURE | V4L2_CAP_STREAMING;
      cap->capabilities = cap->device_caps | V4L2_CAP_DEVICE_CAPS;
      return 0;
    }
    case VIDIOC_ENUM_FMT: {
      auto* d = static_cast<v4l2_fmtdesc*>(arg);
      if (d->index >= camera_.formats.size()) return Fail(EINVAL);
      const RecordedCamera::Format& f = camera_.formats[d->index];
      d->pixelformat = f.fourcc;
      d->flags = f.compressed ? V4L2_FMT_FLAG_COMPRESSED : 0;
      return 0;
    }
    case VIDIOC_ENUM_FRAMESIZES: {
      auto* fs = static_cast<v4l2_frmsizeenum*>(arg);
      for (const RecordedCamera::Format& f : camera_.formats) {
        if (f.fourcc != fs->pixel_format) continue;
        if (fs->index >= f.sizes.size()) return Fail(EINVAL);
        fs->type = V4L2_FRMSIZE_TYPE_DISCRETE;
        fs->discrete.width = static_cast<uint32_t>(f.sizes[fs->index].width);
        fs->discrete.height = static_cast<uint32_t>(f.sizes[fs->index].height);
        return 0;
      }
      return Fail(EINVAL);
    }
    case VIDIOC_S_FMT:
      return SetFormat(arg);
    case VIDIOC_G_PARM: {
      auto* parm = static_cast<v4l2_streamparm*>(arg);
      parm->parm.capture.timeperframe.numerator = static_cast<uint32_t>(camera_.frame_period_us);
      parm->parm.capture.timeperframe.denominator = 1000000;
      return 0;
    }
    case VIDIOC_QUERYCTRL:
    case VIDIOC_G_CTRL:
    case VIDIOC_S_CTRL:
      return Control(request, arg);
    case VIDIOC_REQBUFS: {
      auto* req = static_cast<v4l2_requestbuffers*>(arg);
      buffers_.assign(req->count, std::vector<uint8_t>(size_image_));
      queued_.assign(req->count, false);
      return 0;
    }
    case VIDIOC_QUERYBUF: {
      auto* buf = static_cast<v4l2_buffer*>(arg);
      if (buf->index >= buffers_.size()) return Fail(EINVAL);
      buf->length = size_image_;
      buf->m.offset = buf->index << 20;
      return 0;
    }
    case VIDIOC_QBUF: {
      auto* buf = static_cast<v4l2_buffer*>(arg);
      if (buf->index >= buffers_.size()) return Fail(EINVAL);
      queued_[buf->index] = true;
      return 0;
    }
    case VIDIOC_DQBUF:
      return Dequeue(arg);
    case VIDIOC_STREAMON:
      streaming_ = true;
      t0_us_ = MonotonicUs();
      next_sequence_ = 0;
      return 0;
    case VIDIOC_STREAMOFF:
      streaming_ = false;
      return 0;
    default:
      return Fail(ENOTTY);
  }
}

void* RecordedDevice::Map(size_t length, long offset) {
  const size_t index = static_cast<size_t>(offset) >> 20;
  if (index >= buffers_.size() || length > buffers_[index].size()) {
    errno = EINVAL;
    return nullptr;
  }
  return buffers_[index].data();
}

int RecordedDevice::Poll(int) {
  if (unplug_after_ >= 0 && delivered_ >= unplug_after_) unplugged_ = true;
  if (unplugged_) return Fail(ENODEV);
  return streaming_ ? 1 : 0;
}

}  // namespace vellum::station
