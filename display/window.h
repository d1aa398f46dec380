// An SDL2 window that shows OpenCV images: the projector's full-screen output (with the
// mirror's flip) and the operator's viewer. Headless, SDL_VIDEODRIVER=offscreen or dummy
// gives a window no one sees, which is how the tests drive both.
#pragma once

#include <SDL.h>

#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace vellum::display {

// The mirror flip of an image on screen.
enum class Flip { kNone, kHorizontal, kVertical, kBoth };
// "none", "horizontal", "vertical" or "both"; false for anything else.
bool ParseFlip(const std::string& text, Flip* flip);

struct WindowOptions {
  std::string title = "vellum";
  cv::Size size{1280, 720};  // Pixels of the image shown (the logical size).
  int display = 0;           // SDL display index.
  bool fullscreen = false;   // Full screen on that display.
  bool vsync = false;        // Show() returns after the next vertical blank.
  bool Check(std::string* why) const;
};

class Window {
 public:
  // Throws std::runtime_error naming what failed (no display, no renderer), or
  // std::invalid_argument for a display that does not exist.
  explicit Window(const WindowOptions& options);
  ~Window();
  Window(const Window&) = delete;
  Window& operator=(const Window&) = delete;

  cv::Size size() const { return size_; }
  // The refresh rate of the display the window is on (Hz); 0 when SDL does not know it (the
  // offscreen and dummy drivers).
  double refresh_hz() const;
  // Shows an 8-bit gray or BGR image of size(), flipped as asked.
  void Show(const cv::Mat& image, Flip flip = Flip::kNone);
  // What is on screen now, as BGR (read back from the renderer).
  cv::Mat Screen() const;
  // Handles the window's events: what the keyboard and the mouse gave, in order, is appended
  // to `input` (if given): each key pressed, the text typed (UTF-8, while text input is on),
  // and the left mouse button's presses, drags and releases; false once the window was closed.
  struct Input {
    enum class Mouse { kNone, kDown, kDrag, kUp };
    SDL_Keycode key = 0;  // 0 for text and the mouse.
    std::string text;
    Mouse mouse = Mouse::kNone;
    cv::Point at;  // The mouse, in pixels of the image shown (the logical size).
  };
  bool Poll(std::vector<Input>* input = nullptr);
  // Text input (an on-screen or input-method keyboard, and SDL_TEXTINPUT events) on or off.
  void TextInput(bool on);

 private:
  cv::Size size_;
  SDL_Window* window_ = nullptr;
  SDL_Renderer* renderer_ = nullptr;
  SDL_Texture* texture_ = nullptr;
  cv::Mat bgr_;
};

}  // namespace vellum::display
