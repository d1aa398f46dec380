#include "daemons/camera/camera_node.h"

#include <opencv2/imgproc.hpp>

#include "core/common/depth.h"
#include "core/outline/outline.h"
#include "station/messages.h"
#include "vellum/capture_t.hpp"
#include "vellum/latency_seen_t.hpp"

namespace vellum::station {
namespace {

cv::Mat Gray(const cv::Mat& image) {
  if (image.channels() == 1) return image;
  cv::Mat gray;
  cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  return gray;
}

std::string Percent(double share) {
  return std::to_string(static_cast<int>(100 * share + 0.5)) + "%";
}

}  // namespace

bool CameraNodeOptions::Check(std::string* why) const {
  if (!(preview_hz > 0)) {
    *why = "camera: preview_hz must be > 0";
    return false;
  }
  return true;
}

CameraNode::CameraNode(Node* node, std::unique_ptr<Camera> camera, const CameraNodeOptions& options)
    : node_(node), camera_(std::move(camera)), preview_period_(1.0 / options.preview_hz) {
  node->Log(camera_->Describe());
  node->Subscribe<pattern_shown_t>(channel::kPatternShown, [this](const pattern_shown_t& m) {
    busy_until_ = node_->Now() + std::chrono::seconds(2);
    node_->Post([this, m] { OnShown(m); }, "a PATTERN_SHOWN");
  });
  node->Subscribe<latency_probe_t>(channel::kLatencyProbe, [this](const latency_probe_t& m) {
    busy_until_ = node_->Now() + std::chrono::seconds(2);
    node_->Post([this, m] { OnProbe(m); }, "a LATENCY_PROBE");
  });
}

void CameraNode::Tick() {
  const auto now = node_->Now();
  if (now < busy_until_ || now < next_preview_ || node_->Pending() > 0) return;
  next_preview_ = now + std::chrono::duration_cast<Clock::duration>(preview_period_);
  node_->Post([this] {
    cv::Mat image;
    int64_t exposure = 0;
    const Status s = camera_->Preview(&image, &exposure);
    CountCameraFaults();
    // A camera gone at idle is logged once, and again when it is back: not twice a second.
    if (!s.ok() || !preview_error_.empty()) {
      if (s.message() != preview_error_) node_->Log(s.ok() ? "live preview back" : s.message());
      preview_error_ = s.ok() ? "" : s.message();
    }
    if (!s.ok()) return;
    image = EightBit(image);
    PublishPreview(image, exposure, 0, -1, 0);
    // The centre, pixel for pixel.
    const cv::Size crop(std::min(320, image.cols), std::min(240, image.rows));
    image_t focus{};
    ToMessage(image(cv::Rect((image.cols - crop.width) / 2, (image.rows - crop.height) / 2,
                             crop.width, crop.height))
                  .clone(),
              &focus);
    focus.utime = exposure;
    focus.pattern_index = -1;
    node_->Publish(channel::kPreviewFocus, &focus);
  });
}

void CameraNode::CountCameraFaults() {
  const int64_t dropped = camera_->dropped_frames(), bad = camera_->bad_frames();
  if (dropped > dropped_seen_) node_->Count("frames the camera dropped", dropped - dropped_seen_);
  if (bad > bad_seen_) node_->Count("frames the camera flagged bad", bad - bad_seen_);
  dropped_seen_ = dropped;
  bad_seen_ = bad;
}

void CameraNode::OnProbe(const latency_probe_t& m) {
  latency_seen_t seen{};
  seen.session = m.session;
  seen.index = m.index;
  seen.exposure_us = static_cast<int32_t>(camera_->exposure_us());
  FrameRequest request;
  // Flash k as pattern k (the first, white, follows the projector's black).
  request.pattern_index = m.index;
  request.pattern.kind = m.white ? PatternKind::kWhite : PatternKind::kBlack;
  request.projector = cv::Size(m.projector_width, m.projector_height);
  request.handed_utime = m.handed_utime;
  // From up to a frame period before the handover (a frame of the old level to start with),
  // at a phase that differs from flash to flash: where a camera's frames fall against its
  // display drifts anyway; a camera that only gives frames from now on gives those.
  const int64_t period = camera_->frame_period_us();
  const int64_t phase = (static_cast<int64_t>(m.index) * 5 % 12 + 12) % 12;
  request.shown_utime = m.handed_utime - period * phase / 12;
  const int64_t end = m.handed_utime + std::clamp(m.window_us, 0, 2000000);
  cv::Mat frame;
  int64_t start = 0;
  Status s = camera_->Capture(request, &frame, &start);
  while (s.ok()) {
    seen.start_utime.push_back(start);
    seen.level.push_back(static_cast<float>(cv::mean(Gray(EightBit(frame)))[0]));
    if (start > end || seen.start_utime.size() >= 60) break;
    s = Next(request, start, &frame, &start);
  }
  CountCameraFaults();
  if (!s.ok()) seen.error = s.message();
  seen.count = static_cast<int32_t>(seen.start_utime.size());
  node_->Publish(channel::kLatencySeen, &seen);
}

Status CameraNode::Next(const FrameRequest& request, int64_t after, cv::Mat* image,
                        int64_t* exposure) {
  FrameRequest next = request;
  next.shown_utime = after + 1;
  const Status s = camera_->Capture(next, image, exposure);
  if (s.ok()) *image = Gray(EightBit(*image));
  return s;
}

void CameraNode::NameMixed(const std::string& where, const std::string& how) {
  node_->Count("frames mixing two patterns");
  node_->Log(where + ": " + how + ": not sent, taken again from the camera's next frame");
}

Status CameraNode::CheckedCapture(const FrameRequest& request, const std::string& where,
                                  cv::Mat* image, int64_t* exposure) {
  cv::Mat frame;
  Status s = camera_->Capture(request, &frame, exposure);
  if (!s.ok()) return s;
  frame = Gray(EightBit(frame));
  const PatternSpec& spec = request.pattern;
  constexpr int kTries = 3;
  // A Gray-code inverse is checked against its pattern on a linear camera; every other frame
  // (white, black, phase, and a gamma-encoding camera's Gray code) against the next one.
  const bool paired = spec.kind == PatternKind::kGray && camera_->linear();
  if (!paired) {
    // The camera's next frame must show the same.
    for (int tries = 0;; ++tries) {
      cv::Mat next;
      int64_t next_exposure = 0;
      s = Next(request, *exposure, &next, &next_exposure);
      if (!s.ok()) return s;
      const double change = FrameChange(frame, next, check_);
      if (change <= check_.changed_share) break;
      if (tries + 1 == kTries) {
        return Status::Error("the picture kept changing under one pattern (" + Percent(change) +
                             " of the pixels, " + std::to_string(kTries) +
                             " frames): is the display's lag longer than the projector waits? " +
                             "Measure it: vellum calibrate latency");
      }
      NameMixed(where, "the frame changed before the next (" + Percent(change) +
                           " of the pixels): it mixes two patterns or shows the one before");
      frame = next;
      *exposure = next_exposure;
    }
    if (spec.kind == PatternKind::kWhite) kept_.white = frame;
    if (spec.kind == PatternKind::kBlack) kept_.black = frame;
  } else if (spec.inverted && !kept_.pattern.empty() && !kept_.white.empty() &&
             !kept_.black.empty() && kept_.pattern_spec.axis == spec.axis &&
             kept_.pattern_spec.bit == spec.bit) {
    for (int tries = 0;; ++tries) {
      const double mismatch = PairMismatch(kept_.pattern, frame, kept_.white, kept_.black, check_);
      if (mismatch <= check_.mixed_share) break;
      if (tries + 1 == kTries) {
        // The inverse is steady and still does not add up with its pattern: the pattern, sent
        // already, was the mixed frame.
        return Status::Error("pattern " + std::to_string(kept_.pattern_index) + " (" +
                             Describe(kept_.pattern_spec) + ") was taken mixing two patterns (" +
                             Percent(mismatch) + " of the lit pixels off its inverse): the " +
                             "scan cannot be decoded; is the display's lag longer than the " +
                             "projector waits? Measure it: vellum calibrate latency");
      }
      NameMixed(where,
                "the frame does not add up with its pattern (" + Percent(mismatch) +
                    " of the lit pixels off): it mixes two patterns or shows the one before");
      s = Next(request, *exposure, &frame, exposure);
      if (!s.ok()) return s;
    }
  } else if (!spec.inverted) {
    kept_.pattern = frame;
    kept_.pattern_spec = spec;
    kept_.pattern_index = request.pattern_index;
  }
  *image = frame;
  return Status::Ok();
}

void CameraNode::PublishPreview(const cv::Mat& image, int64_t utime, int64_t scan_id, int index,
                                int count) {
  image_t p{};
  ToMessage(PreviewOf(image), &p);
  p.utime = utime;
  p.scan_id = scan_id;
  p.pattern_index = index;
  p.pattern_count = count;
  node_->Publish(channel::kPreview, &p);
}

void CameraNode::OnShown(const pattern_shown_t& m) {
  const std::string where =
      "scan " + std::to_string(m.scan_id) + ", pattern " + std::to_string(m.pattern_index);
  FrameRequest request;
  Status s = FromMessage(m.pattern, &request.pattern);
  if (!s.ok()) return node_->Error(where + ": PATTERN_SHOWN: " + s.message(), m.scan_id);
  if (m.light_count < 0 || m.light_count > kMaxLights) {
    return node_->Error(where + ": PATTERN_SHOWN: light_count " + std::to_string(m.light_count) +
                            " outside 0.." + std::to_string(kMaxLights),
                        m.scan_id);
  }
  const int last = m.pattern_count + m.light_count - 1;
  if (m.pattern_count <= 0 || m.pattern_index < -1 || m.pattern_index > last) {
    return node_->Error(
        where + ": PATTERN_SHOWN: pattern_index outside -1.." + std::to_string(last), m.scan_id);
  }
  const bool under_light = m.pattern_index >= m.pattern_count;
  if (under_light) {
    s = FromMessage(m.light, &request.light);
    if (!s.ok()) return node_->Error(where + ": PATTERN_SHOWN: " + s.message(), m.scan_id);
  } else if (!m.light.name.empty()) {
    return node_->Error(where + ": PATTERN_SHOWN: a light named for a pattern or the texture",
                        m.scan_id);
  }
  request.shown_utime = m.utime;
  request.pattern_index = m.pattern_index;
  request.projector = cv::Size(m.projector_width, m.projector_height);
  node_->SetState("capturing", m.scan_id,
                  under_light ? "under the light '" + request.light.name + "'"
                              : "pattern " + std::to_string(m.pattern_index) + " of " +
                                    std::to_string(m.pattern_count));
  cv::Mat image;
  int64_t exposure = 0;
  request.handed_utime = m.handed_utime;
  if (kept_.scan_id != m.scan_id) {
    kept_ = Kept();
    kept_.scan_id = m.scan_id;
  }
  s = under_light || m.pattern_index < 0 ? camera_->Capture(request, &image, &exposure)
                                         : CheckedCapture(request, where, &image, &exposure);
  CountCameraFaults();
  if (!s.ok()) return node_->Error(where + ": " + s.message(), m.scan_id);
  // The structured-light frames go as 8-bit gray (CheckedCapture); the texture and the lights at
  // the camera's own depth, which reaches the master: 16 bits where the camera gives more than 8.
  capture_t c{};
  c.scan_id = m.scan_id;
  c.session = m.session;  // The station is stamped by Publish.
  c.pattern_index = m.pattern_index;
  c.pattern_count = m.pattern_count;
  c.projector_width = m.projector_width;
  c.projector_height = m.projector_height;
  c.pattern = m.pattern;
  c.shown_utime = m.utime;
  c.light_count = m.light_count;
  c.light = m.light;
  ToMessage(image, &c.image);
  c.image.utime = exposure;
  c.image.scan_id = m.scan_id;
  c.image.pattern_index = m.pattern_index;
  c.image.pattern_count = m.pattern_count;
  c.image.seq = node_->Counter("frames captured");
  node_->Publish(channel::kCapture, &c);
  node_->Count("frames captured");
  PublishPreview(EightBit(image), exposure, m.scan_id, m.pattern_index, m.pattern_count);
  if (m.pattern_index == last) node_->SetState("idle", m.scan_id, "scan captured");
}

}  // namespace vellum::station
