#include "daemons/viewer/viewer_node.h"

#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "station/chain.h"
#include "station/messages.h"
#include "vellum/pattern_shown_t.hpp"
#include "vellum/scan_request_t.hpp"

namespace vellum::station {
namespace {

namespace fs = std::filesystem;

// Draws `image` scaled to fit `box` of `canvas` (centred), with a caption above.
void Panel(cv::Mat& canvas, cv::Rect box, const cv::Mat& image, const std::string& caption) {
  cv::rectangle(canvas, box, cv::Scalar(70, 70, 70), 1);
  cv::putText(canvas, caption, box.tl() + cv::Point(4, 16), cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(230, 230, 230), 1, cv::LINE_AA);
  const cv::Rect inner(box.x + 2, box.y + 22, box.width - 4, box.height - 24);
  if (image.empty()) {
    cv::putText(canvas, "(none yet)", inner.tl() + cv::Point(8, 24), cv::FONT_HERSHEY_SIMPLEX, 0.5,
                cv::Scalar(140, 140, 140), 1, cv::LINE_AA);
    return;
  }
  cv::Mat bgr = image;
  if (bgr.channels() == 1) cv::cvtColor(bgr, bgr, cv::COLOR_GRAY2BGR);
  const double s = std::min(static_cast<double>(inner.width) / bgr.cols,
                            static_cast<double>(inner.height) / bgr.rows);
  cv::Mat scaled;
  cv::resize(bgr, scaled, cv::Size(), s, s, s < 1 ? cv::INTER_AREA : cv::INTER_LINEAR);
  const cv::Rect at(inner.x + (inner.width - scaled.cols) / 2,
                    inner.y + (inner.height - scaled.rows) / 2, scaled.cols, scaled.rows);
  scaled.copyTo(canvas(at & cv::Rect(0, 0, canvas.cols, canvas.rows)));
}

}  // namespace

ViewerNode::ViewerNode(Node* node, std::unique_ptr<display::Window> window)
    : node_(node), window_(std::move(window)) {
  node->Subscribe<image_t>(channel::kPreview, [this](const image_t& m) {
    cv::Mat image;
    const Status s = FromMessage(m, &image);
    if (!s.ok()) return node_->Error("PREVIEW: " + s.message());
    preview_ = image;
  });
  node->Subscribe<pattern_shown_t>(channel::kPatternShown, [this](const pattern_shown_t& m) {
    progress_ = "scan " + std::to_string(m.scan_id) + ": " +
                (m.pattern_index < 0 ? std::string("texture")
                                     : "pattern " + std::to_string(m.pattern_index + 1) + " of " +
                                           std::to_string(m.pattern_count));
  });
  auto on_status = [this](const status_t& m) {
    statuses_[m.process] = m;
    seen_[m.process] = Clock::now();
    if (m.state == "busy") {
      progress_ = "scan " + std::to_string(m.scan_id) + ": " + m.process.substr(7) + " " + m.detail;
    }
  };
  for (const char* process : kGantry) node->Subscribe<status_t>(StatusChannel(process), on_status);
  for (const ChainLink& link : kChain) {
    node->Subscribe<status_t>(StatusChannel(link.process), on_status);
  }
  node->Subscribe<restored_t>(channel::kRestored, [this](const restored_t& m) { OnRestored(m); });
}

void ViewerNode::Tick() {
  std::vector<SDL_Keycode> keys;
  if (!window_->Poll(&keys)) node_->Stop();
  for (SDL_Keycode key : keys) OnKey(key);
  if (Clock::now() < next_draw_) return;
  next_draw_ = Clock::now() + std::chrono::milliseconds(100);
  window_->Show(Draw());
}

void ViewerNode::OnKey(SDL_Keycode key) {
  switch (key) {
    case SDLK_q:
    case SDLK_ESCAPE:
      node_->Stop();
      break;
    case SDLK_s: {
      scan_request_t r{};
      r.scan_id = NowUtime();
      r.identity.label = "from vellum-viewer";
      node_->Publish(channel::kScanRequest, &r);
      progress_ = "scan " + std::to_string(r.scan_id) + " requested";
      break;
    }
    case SDLK_LEFT:
      if (shown_ > 0) --shown_;
      break;
    case SDLK_RIGHT:
      if (shown_ + 1 < static_cast<int>(results_.size())) ++shown_;
      break;
    default:
      break;
  }
}

void ViewerNode::OnRestored(const restored_t& m) {
  Result r;
  r.scan_id = m.scan_id;
  r.results = m.results;
  char summary[160];
  std::snprintf(summary, sizeof(summary), "scan %lld: %dx%d %s", static_cast<long long>(m.scan_id),
                m.width, m.height,
                m.view == "orthographic"
                    ? (std::to_string(static_cast<int>(m.dpi)) + " dpi").c_str()
                    : "camera view");
  r.summary = summary;
  const Status s = FromMessage(m.preview, &r.restored);
  if (!s.ok()) {
    node_->Error("RESTORED of scan " + std::to_string(m.scan_id) + ": preview: " + s.message(),
                 m.scan_id);
  }
  r.warnings = m.warnings;
  // The other pictures from the scan's report (the restorer writes it before RESTORED): the
  // texture with the leaf's outline, and a spread's left page for its strain.
  auto load = [&](std::initializer_list<const char*> names) {
    for (const char* name : names) {
      const fs::path p = fs::path(m.results) / "report" / name;
      if (fs::exists(p)) return cv::imread(p.string(), cv::IMREAD_COLOR);
    }
    return cv::Mat();
  };
  r.texture = load({"outline.png", "texture.png"});
  r.depth = load({"depth.png"});
  r.strain = load({"strain.png", "strain-left.png"});
  results_.push_back(r);
  if (results_.size() > 50) results_.pop_front();
  shown_ = static_cast<int>(results_.size()) - 1;
  progress_ = r.summary + " restored" +
              (r.warnings.empty() ? std::string()
                                  : " with " + std::to_string(r.warnings.size()) +
                                        " warning(s): check before delivering");
}

std::vector<std::string> ViewerNode::warnings() const {
  if (shown_ < 0 || shown_ >= static_cast<int>(results_.size())) return {};
  return results_[shown_].warnings;
}

cv::Mat ViewerNode::Draw() const {
  const cv::Size size = window_->size();
  cv::Mat canvas(size, CV_8UC3, cv::Scalar(30, 30, 30));
  const int w = size.width, h = size.height, top = 44;
  cv::putText(canvas, "vellum station", cv::Point(12, 28), cv::FONT_HERSHEY_SIMPLEX, 0.8,
              cv::Scalar(255, 255, 255), 2, cv::LINE_AA);
  const bool doubtful = progress_.find("warning(s)") != std::string::npos;
  cv::putText(canvas, progress_, cv::Point(230, 28), cv::FONT_HERSHEY_SIMPLEX, 0.6,
              doubtful ? cv::Scalar(0, 170, 255) : cv::Scalar(120, 220, 255), 1, cv::LINE_AA);
  cv::putText(canvas, "s: scan   left/right: results   q: quit", cv::Point(w - 330, 28),
              cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(160, 160, 160), 1, cv::LINE_AA);
  // Left: live preview and the daemons.
  const int left_w = w / 3;
  Panel(canvas, cv::Rect(8, top, left_w - 12, (h - top) / 2), preview_, "camera preview");
  int y = top + (h - top) / 2 + 24;
  std::vector<const char*> processes(std::begin(kGantry), std::end(kGantry));
  for (const ChainLink& link : kChain) processes.push_back(link.process);
  for (const char* process : processes) {
    auto it = statuses_.find(process);
    const bool alive =
        it != statuses_.end() && Clock::now() - seen_.at(process) < std::chrono::seconds(3);
    std::string line = std::string(process + 7) + ": ";
    if (it == statuses_.end()) {
      line += "not seen";
    } else {
      line += alive ? it->second.state : "silent (" + it->second.state + ")";
      if (!it->second.last_error.empty()) line += " | " + it->second.last_error;
    }
    if (line.size() > 70) line = line.substr(0, 67) + "...";
    const cv::Scalar colour = !alive                          ? cv::Scalar(80, 80, 230)
                              : it->second.last_error.empty() ? cv::Scalar(120, 230, 120)
                                                              : cv::Scalar(80, 190, 240);
    cv::circle(canvas, cv::Point(18, y - 5), 5, colour, cv::FILLED, cv::LINE_AA);
    cv::putText(canvas, line, cv::Point(30, y), cv::FONT_HERSHEY_SIMPLEX, 0.42,
                cv::Scalar(220, 220, 220), 1, cv::LINE_AA);
    y += 22;
  }
  // Middle: texture, depth, strain; right: the restored page, large.
  const Result* r =
      shown_ >= 0 && shown_ < static_cast<int>(results_.size()) ? &results_[shown_] : nullptr;
  const int mid_x = left_w, mid_w = w / 3, third = (h - top) / 3;
  static const Result kEmpty;
  const Result& show = r ? *r : kEmpty;
  Panel(canvas, cv::Rect(mid_x, top, mid_w - 8, third - 4), show.texture,
        "texture and the leaf's outline");
  Panel(canvas, cv::Rect(mid_x, top + third, mid_w - 8, third - 4), show.depth, "depth (mm)");
  Panel(canvas, cv::Rect(mid_x, top + 2 * third, mid_w - 8, third - 4), show.strain,
        "flattening strain");
  // The restored page, and under it a doubtful result's warnings in amber, a line each.
  const int lines = std::min<int>(static_cast<int>(show.warnings.size()), 6);
  const int warn_h = lines > 0 ? 18 * lines + 8 : 0;
  const cv::Rect page(mid_x + mid_w, top, w - mid_x - mid_w - 8, h - top - 8 - warn_h);
  Panel(canvas, page, show.restored,
        show.warnings.empty() ? "restored page" : "restored page: DOUBTFUL, see the warnings");
  const size_t chars = static_cast<size_t>(std::max(20, page.width / 8));
  for (int k = 0; k < lines; ++k) {
    std::string line = "! " + show.warnings[k];
    if (line.size() > chars) line = line.substr(0, chars - 3) + "...";
    cv::putText(canvas, line, cv::Point(page.x + 4, page.y + page.height + 18 * (k + 1)),
                cv::FONT_HERSHEY_SIMPLEX, 0.42, cv::Scalar(0, 170, 255), 1, cv::LINE_AA);
  }
  return canvas;
}

}  // namespace vellum::station
