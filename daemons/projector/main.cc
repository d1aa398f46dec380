// vellum-projector: the scan's conductor. On SCAN_REQUEST it publishes the station's
// CALIBRATION, then for the texture and each pattern k: shows it full screen (mirror flip
// applied), waits for vsync and the settle time, publishes PATTERN_SHOWN(k) and waits for the
// camera's CAPTURE(k) before the next. A missing capture fails the scan with a clear status.
#include <SDL.h>

#include <chrono>
#include <opencv2/imgproc.hpp>
#include <thread>

#include "cli/options.h"
#include "core/io/calibration_io.h"
#include "daemons/common/daemon.h"
#include "daemons/common/messages.h"
#include "daemons/common/sdl_close.h"
#include "vellum/calibration_t.hpp"
#include "vellum/capture_t.hpp"
#include "vellum/pattern_shown_t.hpp"
#include "vellum/scan_request_t.hpp"

namespace vellum::station {
namespace {

class Screen {
 public:
  Screen(cv::Size size, int display, bool fullscreen, int flip) : size_(size), flip_(flip) {
    if (SDL_Init(SDL_INIT_VIDEO) != 0) {
      throw std::runtime_error(std::string("SDL video: ") + SDL_GetError() +
                               " (no display? set SDL_VIDEODRIVER=offscreen to run headless)");
    }
    const int displays = SDL_GetNumVideoDisplays();
    if (display < 0 || display >= displays) {
      throw UsageError("--display " + std::to_string(display) + ": there are " +
                       std::to_string(displays) + " display(s)");
    }
    const Uint32 flags = fullscreen ? SDL_WINDOW_FULLSCREEN_DESKTOP : 0;
    window_ =
        SDL_CreateWindow("vellum-projector", SDL_WINDOWPOS_UNDEFINED_DISPLAY(display),
                         SDL_WINDOWPOS_UNDEFINED_DISPLAY(display), size.width, size.height, flags);
    if (!window_) throw std::runtime_error(std::string("SDL window: ") + SDL_GetError());
    SDL_ShowCursor(SDL_DISABLE);
    renderer_ = SDL_CreateRenderer(window_, -1, SDL_RENDERER_PRESENTVSYNC);
    if (!renderer_) renderer_ = SDL_CreateRenderer(window_, -1, SDL_RENDERER_SOFTWARE);
    if (!renderer_) throw std::runtime_error(std::string("SDL renderer: ") + SDL_GetError());
    SDL_RenderSetLogicalSize(renderer_, size.width, size.height);
    texture_ = SDL_CreateTexture(renderer_, SDL_PIXELFORMAT_RGB24, SDL_TEXTUREACCESS_STREAMING,
                                 size.width, size.height);
    if (!texture_) throw std::runtime_error(std::string("SDL texture: ") + SDL_GetError());
  }
  ~Screen() { CloseSdl(texture_, renderer_, window_); }

  // Shows an 8-bit gray image of the projector's size; returns after the next vsync.
  void Show(const cv::Mat& gray) {
    cv::cvtColor(gray, rgb_, cv::COLOR_GRAY2RGB);
    SDL_UpdateTexture(texture_, nullptr, rgb_.data, static_cast<int>(rgb_.step));
    SDL_RenderClear(renderer_);
    SDL_RenderCopyEx(renderer_, texture_, nullptr, nullptr, 0.0, nullptr,
                     static_cast<SDL_RendererFlip>(flip_));
    SDL_RenderPresent(renderer_);
  }

  // False when the window was closed.
  bool Poll() {
    SDL_Event e;
    while (SDL_PollEvent(&e)) {
      if (e.type == SDL_QUIT) return false;
    }
    return true;
  }

 private:
  cv::Size size_;
  int flip_;
  SDL_Window* window_ = nullptr;
  SDL_Renderer* renderer_ = nullptr;
  SDL_Texture* texture_ = nullptr;
  cv::Mat rgb_;
};

int ParseFlip(const std::string& text) {
  if (text == "none") return SDL_FLIP_NONE;
  if (text == "horizontal") return SDL_FLIP_HORIZONTAL;
  if (text == "vertical") return SDL_FLIP_VERTICAL;
  if (text == "both") return SDL_FLIP_HORIZONTAL | SDL_FLIP_VERTICAL;
  throw UsageError("--flip must be none, horizontal, vertical or both, got '" + text + "'");
}

class ProjectorNode {
 public:
  ProjectorNode(Node* node, const Flags& flags) : node_(node) {
    calibration_path_ = flags.Get("calibration");
    cv::Size size = flags.GetSize("projector");
    if (!calibration_path_.empty()) {
      const Status s = ReadCalibration(calibration_path_, &calibration_);
      if (!s.ok()) throw UsageError(s.message());
      if (flags.Has("projector") && size != calibration_.projector.size) {
        throw UsageError("--projector " + SizeText(size) + " but " + calibration_path_ +
                         " calibrates a " + SizeText(calibration_.projector.size) + " projector");
      }
      size = calibration_.projector.size;
    }
    sequence_ = MakePatternSequence(PatternOptionsFromFlags(flags, size));
    settle_ = std::chrono::milliseconds(flags.GetInt("settle-ms", 0, 10000));
    timeout_ = std::chrono::duration<double>(flags.GetDouble("capture-timeout", 0.1, 600));
    screen_ = std::make_unique<Screen>(size, flags.GetInt("display", 0, 63),
                                       flags.GetBool("fullscreen"), ParseFlip(flags.Get("flip")));
    black_ = cv::Mat::zeros(size, CV_8U);
    screen_->Show(black_);
    node->Subscribe<scan_request_t>(channel::kScanRequest,
                                    [this](const scan_request_t& m) { OnRequest(m); });
    node->Subscribe<capture_t>(channel::kCapture, [this](const capture_t& m) { OnCapture(m); });
    node->Log("projector " + SizeText(size) + ", " + std::to_string(sequence_.patterns.size()) +
              " patterns per scan");
  }

  void Tick() {
    if (!screen_->Poll()) node_->Stop();
    if (scan_id_ != 0 && std::chrono::steady_clock::now() - shown_at_ > timeout_) {
      Fail("no CAPTURE of " + What(index_) + " within " +
           std::to_string(static_cast<int>(timeout_.count() * 1000)) +
           " ms (is vellum-camera running and on the same bus?)");
    }
  }

 private:
  std::string What(int index) const {
    return index < 0 ? std::string("the texture")
                     : "pattern " + std::to_string(index) + " of " +
                           std::to_string(sequence_.patterns.size());
  }

  void OnRequest(const scan_request_t& m) {
    if (m.scan_id <= 0) {
      node_->Error("SCAN_REQUEST with scan_id " + std::to_string(m.scan_id) + " refused");
      return;
    }
    if (scan_id_ != 0) {
      node_->Error("scan " + std::to_string(m.scan_id) + " refused: scan " +
                       std::to_string(scan_id_) + " is in progress",
                   m.scan_id);
      return;
    }
    scan_id_ = m.scan_id;
    node_->Log("scan " + std::to_string(scan_id_) + " started" +
               (m.label.empty() ? "" : " (" + m.label + ")"));
    if (!calibration_path_.empty()) {
      calibration_t c{};
      c.scan_id = scan_id_;
      c.source = calibration_path_;
      ToMessage(calibration_, &c);
      node_->Publish(channel::kCalibration, &c);
    }
    started_ = std::chrono::steady_clock::now();
    ShowPattern(-1);
  }

  void OnCapture(const capture_t& m) {
    if (scan_id_ == 0 || m.scan_id != scan_id_ || m.pattern_index != index_) return;
    if (index_ + 1 < static_cast<int>(sequence_.patterns.size())) {
      ShowPattern(index_ + 1);
      return;
    }
    const double secs =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count();
    node_->Log("scan " + std::to_string(scan_id_) + ": " +
               std::to_string(sequence_.patterns.size() + 1) + " captures in " +
               std::to_string(secs) + " s");
    node_->Count("scans captured");
    screen_->Show(black_);
    node_->SetState("idle", scan_id_, "scan captured");
    scan_id_ = 0;
  }

  void ShowPattern(int index) {
    index_ = index;
    PatternSpec spec;
    spec.kind = PatternKind::kBlack;
    if (index >= 0) spec = sequence_.patterns[index];
    screen_->Show(index < 0 ? black_ : RenderPattern(spec, sequence_.projector_size));
    std::this_thread::sleep_for(settle_);
    pattern_shown_t m{};
    m.scan_id = scan_id_;
    m.pattern_index = index;
    m.pattern_count = static_cast<int32_t>(sequence_.patterns.size());
    m.projector_width = sequence_.projector_size.width;
    m.projector_height = sequence_.projector_size.height;
    m.pattern = ToMessage(spec);
    node_->Publish(channel::kPatternShown, &m);
    shown_at_ = std::chrono::steady_clock::now();
    node_->SetState("scanning", scan_id_, "showing " + What(index));
  }

  void Fail(const std::string& why) {
    node_->Error("scan " + std::to_string(scan_id_) + " failed: " + why, scan_id_);
    node_->Count("scans failed");
    screen_->Show(black_);
    node_->SetState("idle");
    scan_id_ = 0;
  }

  Node* node_;
  std::string calibration_path_;
  Calibration calibration_;
  PatternSequence sequence_;
  std::chrono::milliseconds settle_{0};
  std::chrono::duration<double> timeout_{5.0};
  std::unique_ptr<Screen> screen_;
  cv::Mat black_;
  int64_t scan_id_ = 0;  // The scan in progress, 0 if none.
  int index_ = -1;       // What is on screen: -1 the texture, k pattern k.
  std::chrono::steady_clock::time_point shown_at_, started_;
};

}  // namespace
}  // namespace vellum::station

int main(int argc, char** argv) {
  using namespace vellum;
  using namespace vellum::station;
  std::vector<Flags::Spec> specs = DaemonFlagSpecs(false);
  const std::vector<Flags::Spec> own = {
      {"calibration", "FILE",
       "station calibration: sets the projector size, published as CALIBRATION per scan", ""},
      {"projector", "WxH", "projector size when no calibration is given", "1024x768"},
      {"display", "N", "SDL display index of the projector", "0"},
      {"fullscreen", "BOOL", "full-screen window on that display", "true"},
      {"flip", "AXIS", "mirror flip: none, horizontal, vertical or both", "none"},
      {"settle-ms", "MS", "wait after vsync before PATTERN_SHOWN", "30"},
      {"capture-timeout", "S", "fail the scan when a CAPTURE takes longer", "5"},
  };
  specs = Join(Join(specs, own), PatternFlagSpecs());
  return DaemonMain(
      argc, argv, "vellum-projector",
      "Shows the structured-light patterns full screen, one per CAPTURE, for each SCAN_REQUEST;\n"
      "publishes CALIBRATION at the start of a scan and PATTERN_SHOWN for each pattern. The\n"
      "images are of the virtual (unmirrored) projector; --flip undoes the mirror.",
      specs, [](const Flags& flags, Node& node) {
        ProjectorNode projector(&node, flags);
        return node.Run([&] { projector.Tick(); }, 5);
      });
}
