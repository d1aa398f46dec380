#include "daemons/camera/camera_node.h"

#include <opencv2/imgproc.hpp>

#include "core/outline/outline.h"
#include "station/messages.h"
#include "vellum/capture_t.hpp"

namespace vellum::station {
namespace {

// The bus carries 8-bit frames (image_t: GREY, BGR3): a deeper camera's frame is scaled down
// here, its own depth kept up to this point.
cv::Mat EightBit(const cv::Mat& image) {
  if (image.depth() == CV_8U) return image;
  cv::Mat out;
  image.convertTo(out, CV_8U, 255.0 / 65535.0);
  return out;
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
  s = camera_->Capture(request, &image, &exposure);
  CountCameraFaults();
  if (!s.ok()) return node_->Error(where + ": " + s.message(), m.scan_id);
  image = EightBit(image);
  if (m.pattern_index >= 0 && !under_light && image.channels() == 3) {
    cv::cvtColor(image, image, cv::COLOR_BGR2GRAY);
  }
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
  PublishPreview(image, exposure, m.scan_id, m.pattern_index, m.pattern_count);
  if (m.pattern_index == last) node_->SetState("idle", m.scan_id, "scan captured");
}

}  // namespace vellum::station
