// vellum-viewer: what the operator at the gantry watches. An SDL2 window with the live camera
// preview (the PREVIEW channel, never full frames), the scan's progress, every daemon's status
// from its heartbeat (alive, state, last error), and for each finished scan its texture, depth
// map, strain map and the restored page side by side. Keys: s = start a scan, left/right =
// step through the scans of this session, q or Esc = quit.
#include <SDL.h>

#include <chrono>
#include <deque>
#include <filesystem>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "cli/options.h"
#include "daemons/common/daemon.h"
#include "daemons/common/messages.h"
#include "daemons/common/sdl_close.h"
#include "vellum/pattern_shown_t.hpp"
#include "vellum/restored_t.hpp"
#include "vellum/scan_request_t.hpp"
#include "vellum/status_t.hpp"

namespace vellum::station {
namespace {

using Clock = std::chrono::steady_clock;
namespace fs = std::filesystem;

const char* const kProcesses[] = {"vellum-camera",       "vellum-projector", "vellum-decoder",
                                  "vellum-triangulator", "vellum-flattener", "vellum-restorer"};

struct Result {
  int64_t scan_id = 0;
  std::string summary, results;
  cv::Mat texture, depth, strain, restored;
};

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

class Viewer {
 public:
  Viewer(Node* node, const Flags& flags) : node_(node), size_(flags.GetSize("size")) {
    if (SDL_Init(SDL_INIT_VIDEO) != 0) {
      throw std::runtime_error(std::string("SDL video: ") + SDL_GetError() +
                               " (no display? run under Xvfb or set SDL_VIDEODRIVER)");
    }
    window_ = SDL_CreateWindow("vellum station", SDL_WINDOWPOS_CENTERED, SDL_WINDOWPOS_CENTERED,
                               size_.width, size_.height,
                               flags.GetBool("fullscreen") ? SDL_WINDOW_FULLSCREEN_DESKTOP : 0);
    if (!window_) throw std::runtime_error(std::string("SDL window: ") + SDL_GetError());
    renderer_ = SDL_CreateRenderer(window_, -1, 0);
    if (!renderer_) renderer_ = SDL_CreateRenderer(window_, -1, SDL_RENDERER_SOFTWARE);
    if (!renderer_) throw std::runtime_error(std::string("SDL renderer: ") + SDL_GetError());
    SDL_RenderSetLogicalSize(renderer_, size_.width, size_.height);
    texture_ = SDL_CreateTexture(renderer_, SDL_PIXELFORMAT_BGR24, SDL_TEXTUREACCESS_STREAMING,
                                 size_.width, size_.height);
    if (!texture_) throw std::runtime_error(std::string("SDL texture: ") + SDL_GetError());

    node->Subscribe<image_t>(channel::kPreview, [this](const image_t& m) {
      cv::Mat image;
      if (FromMessage(m, &image).ok()) preview_ = image;
    });
    node->Subscribe<pattern_shown_t>(channel::kPatternShown, [this](const pattern_shown_t& m) {
      progress_ = "scan " + std::to_string(m.scan_id) + ": " +
                  (m.pattern_index < 0 ? std::string("texture")
                                       : "pattern " + std::to_string(m.pattern_index + 1) + " of " +
                                             std::to_string(m.pattern_count));
    });
    for (const char* process : kProcesses) {
      node->Subscribe<status_t>(StatusChannel(process), [this](const status_t& m) {
        statuses_[m.process] = m;
        seen_[m.process] = Clock::now();
        if (m.state == "busy")
          progress_ =
              "scan " + std::to_string(m.scan_id) + ": " + m.process.substr(7) + " " + m.detail;
      });
    }
    node->Subscribe<restored_t>(channel::kRestored, [this](const restored_t& m) { OnRestored(m); });
  }

  ~Viewer() { CloseSdl(texture_, renderer_, window_); }

  void Tick() {
    SDL_Event e;
    while (SDL_PollEvent(&e)) {
      if (e.type == SDL_QUIT) node_->Stop();
      if (e.type != SDL_KEYDOWN) continue;
      switch (e.key.keysym.sym) {
        case SDLK_q:
        case SDLK_ESCAPE:
          node_->Stop();
          break;
        case SDLK_s: {
          scan_request_t r{};
          r.scan_id = NowUtime();
          r.label = "from vellum-viewer";
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
    if (Clock::now() < next_draw_) return;
    next_draw_ = Clock::now() + std::chrono::milliseconds(100);
    Draw();
  }

 private:
  void OnRestored(const restored_t& m) {
    Result r;
    r.scan_id = m.scan_id;
    r.results = m.results;
    char summary[160];
    std::snprintf(summary, sizeof(summary), "scan %lld: %dx%d %s",
                  static_cast<long long>(m.scan_id), m.width, m.height,
                  m.view == "orthographic"
                      ? (std::to_string(static_cast<int>(m.dpi)) + " dpi").c_str()
                      : "camera view");
    r.summary = summary;
    FromMessage(m.preview, &r.restored);
    // The other pictures from the scan's report (the restorer writes it before RESTORED).
    auto load = [&](const char* name) {
      const fs::path p = fs::path(m.results) / "report" / name;
      return fs::exists(p) ? cv::imread(p.string(), cv::IMREAD_COLOR) : cv::Mat();
    };
    r.texture = load("texture.png");
    r.depth = load("depth.png");
    r.strain = load("strain.png");
    results_.push_back(r);
    if (results_.size() > 50) results_.pop_front();
    shown_ = static_cast<int>(results_.size()) - 1;
    progress_ = r.summary + " restored";
  }

  void Draw() {
    cv::Mat canvas(size_, CV_8UC3, cv::Scalar(30, 30, 30));
    const int w = size_.width, h = size_.height, top = 44;
    cv::putText(canvas, "vellum station", cv::Point(12, 28), cv::FONT_HERSHEY_SIMPLEX, 0.8,
                cv::Scalar(255, 255, 255), 2, cv::LINE_AA);
    cv::putText(canvas, progress_, cv::Point(230, 28), cv::FONT_HERSHEY_SIMPLEX, 0.6,
                cv::Scalar(120, 220, 255), 1, cv::LINE_AA);
    cv::putText(canvas, "s: scan   left/right: results   q: quit", cv::Point(w - 330, 28),
                cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(160, 160, 160), 1, cv::LINE_AA);
    // Left: live preview and the daemons.
    const int left_w = w / 3;
    Panel(canvas, cv::Rect(8, top, left_w - 12, (h - top) / 2), preview_, "camera preview");
    int y = top + (h - top) / 2 + 24;
    for (const char* process : kProcesses) {
      auto it = statuses_.find(process);
      const bool alive =
          it != statuses_.end() && Clock::now() - seen_[process] < std::chrono::seconds(3);
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
    Panel(canvas, cv::Rect(mid_x, top, mid_w - 8, third - 4), show.texture, "texture");
    Panel(canvas, cv::Rect(mid_x, top + third, mid_w - 8, third - 4), show.depth, "depth (mm)");
    Panel(canvas, cv::Rect(mid_x, top + 2 * third, mid_w - 8, third - 4), show.strain,
          "flattening strain");
    Panel(canvas, cv::Rect(mid_x + mid_w, top, w - mid_x - mid_w - 8, h - top - 8), show.restored,
          "restored page");
    SDL_UpdateTexture(texture_, nullptr, canvas.data, static_cast<int>(canvas.step));
    SDL_RenderClear(renderer_);
    SDL_RenderCopy(renderer_, texture_, nullptr, nullptr);
    SDL_RenderPresent(renderer_);
  }

  Node* node_;
  cv::Size size_;
  SDL_Window* window_ = nullptr;
  SDL_Renderer* renderer_ = nullptr;
  SDL_Texture* texture_ = nullptr;
  cv::Mat preview_;
  std::string progress_ = "waiting for the station";
  std::map<std::string, status_t> statuses_;
  std::map<std::string, Clock::time_point> seen_;
  std::deque<Result> results_;
  int shown_ = -1;
  Clock::time_point next_draw_;
};

}  // namespace
}  // namespace vellum::station

int main(int argc, char** argv) {
  using namespace vellum;
  using namespace vellum::station;
  const std::vector<Flags::Spec> own = {
      {"size", "WxH", "window size", "1280x720"},
      {"fullscreen", "BOOL", "full screen", "false"},
  };
  return DaemonMain(argc, argv, "vellum-viewer",
                    "The operator's window: live camera preview, scan progress, the daemons'\n"
                    "status, and each finished scan's texture, depth, strain and restored page.\n"
                    "Keys: s = start a scan, left/right = step through results, q = quit.",
                    Join(DaemonFlagSpecs(false), own), [](const Flags& flags, Node& node) {
                      Viewer viewer(&node, flags);
                      return node.Run([&] { viewer.Tick(); }, 20);
                    });
}
