#include "display/window.h"

#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "display/sdl_close.h"

namespace vellum::display {

bool ParseFlip(const std::string& text, Flip* flip) {
  if (text == "none") {
    *flip = Flip::kNone;
  } else if (text == "horizontal") {
    *flip = Flip::kHorizontal;
  } else if (text == "vertical") {
    *flip = Flip::kVertical;
  } else if (text == "both") {
    *flip = Flip::kBoth;
  } else {
    return false;
  }
  return true;
}

bool WindowOptions::Check(std::string* why) const {
  if (size.width < 1 || size.height < 1 || display < 0) {
    *why = "window: its size must be at least 1 x 1 and its display >= 0";
    return false;
  }
  return true;
}

Window::Window(const WindowOptions& options) : size_(options.size) {
  if (std::string why; !options.Check(&why)) throw std::invalid_argument(why);
  if (SDL_Init(SDL_INIT_VIDEO) != 0) {
    throw std::runtime_error(std::string("SDL video: ") + SDL_GetError() +
                             " (no display? set SDL_VIDEODRIVER=offscreen to run headless)");
  }
  const int displays = SDL_GetNumVideoDisplays();
  if (options.display < 0 || options.display >= displays) {
    SDL_Quit();
    throw std::invalid_argument("display " + std::to_string(options.display) + ": there are " +
                                std::to_string(displays) + " display(s)");
  }
  const Uint32 flags = options.fullscreen ? SDL_WINDOW_FULLSCREEN_DESKTOP : 0;
  window_ = SDL_CreateWindow(
      options.title.c_str(), SDL_WINDOWPOS_UNDEFINED_DISPLAY(options.display),
      SDL_WINDOWPOS_UNDEFINED_DISPLAY(options.display), size_.width, size_.height, flags);
  if (!window_) {
    const std::string why = SDL_GetError();
    CloseSdl(nullptr, nullptr, nullptr);
    throw std::runtime_error("SDL window: " + why);
  }
  if (options.fullscreen) SDL_ShowCursor(SDL_DISABLE);
  renderer_ = SDL_CreateRenderer(window_, -1, options.vsync ? SDL_RENDERER_PRESENTVSYNC : 0);
  if (!renderer_) renderer_ = SDL_CreateRenderer(window_, -1, SDL_RENDERER_SOFTWARE);
  if (renderer_) {
    SDL_RenderSetLogicalSize(renderer_, size_.width, size_.height);
    texture_ = SDL_CreateTexture(renderer_, SDL_PIXELFORMAT_BGR24, SDL_TEXTUREACCESS_STREAMING,
                                 size_.width, size_.height);
  }
  if (!renderer_ || !texture_) {
    const std::string why = SDL_GetError();
    CloseSdl(texture_, renderer_, window_);
    throw std::runtime_error(std::string(renderer_ ? "SDL texture: " : "SDL renderer: ") + why);
  }
}

Window::~Window() { CloseSdl(texture_, renderer_, window_); }

void Window::Show(const cv::Mat& image, Flip flip) {
  CV_Assert(image.size() == size_ && image.depth() == CV_8U &&
            (image.channels() == 1 || image.channels() == 3));
  if (image.channels() == 1) {
    cv::cvtColor(image, bgr_, cv::COLOR_GRAY2BGR);
  } else {
    image.copyTo(bgr_);
  }
  SDL_UpdateTexture(texture_, nullptr, bgr_.data, static_cast<int>(bgr_.step));
  SDL_RenderClear(renderer_);
  int sdl_flip = SDL_FLIP_NONE;
  if (flip == Flip::kHorizontal || flip == Flip::kBoth) sdl_flip |= SDL_FLIP_HORIZONTAL;
  if (flip == Flip::kVertical || flip == Flip::kBoth) sdl_flip |= SDL_FLIP_VERTICAL;
  SDL_RenderCopyEx(renderer_, texture_, nullptr, nullptr, 0.0, nullptr,
                   static_cast<SDL_RendererFlip>(sdl_flip));
  SDL_RenderPresent(renderer_);
}

double Window::refresh_hz() const {
  SDL_DisplayMode mode{};
  if (SDL_GetWindowDisplayMode(window_, &mode) != 0) return 0;
  return mode.refresh_rate > 0 ? mode.refresh_rate : 0;
}

cv::Mat Window::Screen() const {
  int w = 0, h = 0;
  if (SDL_GetRendererOutputSize(renderer_, &w, &h) != 0 || w <= 0 || h <= 0) return cv::Mat();
  cv::Mat out(h, w, CV_8UC3);
  if (SDL_RenderReadPixels(renderer_, nullptr, SDL_PIXELFORMAT_BGR24, out.data,
                           static_cast<int>(out.step)) != 0) {
    return cv::Mat();
  }
  return out;
}

bool Window::Poll(std::vector<Input>* input) {
  bool open = true;
  SDL_Event e;
  while (SDL_PollEvent(&e)) {
    if (e.type == SDL_QUIT) open = false;
    if (!input) continue;
    if (e.type == SDL_KEYDOWN) input->push_back({e.key.keysym.sym, ""});
    if (e.type == SDL_TEXTINPUT) input->push_back({0, e.text.text});
    // SDL gives the mouse in the logical size's pixels (SDL_RenderSetLogicalSize).
    using Mouse = Input::Mouse;
    if ((e.type == SDL_MOUSEBUTTONDOWN || e.type == SDL_MOUSEBUTTONUP) &&
        e.button.button == SDL_BUTTON_LEFT) {
      input->push_back({0, "", e.type == SDL_MOUSEBUTTONDOWN ? Mouse::kDown : Mouse::kUp,
                        cv::Point(e.button.x, e.button.y)});
    }
    if (e.type == SDL_MOUSEMOTION && (e.motion.state & SDL_BUTTON_LMASK)) {
      input->push_back({0, "", Mouse::kDrag, cv::Point(e.motion.x, e.motion.y)});
    }
  }
  return open;
}

void Window::TextInput(bool on) {
  if (on) {
    SDL_StartTextInput();
  } else {
    SDL_StopTextInput();
  }
}

}  // namespace vellum::display
