// Shutting SDL down in the daemons that open a window (projector, viewer).
#pragma once

#include <SDL.h>

#if defined(__SANITIZE_ADDRESS__)
#define VELLUM_LEAK_CHECK 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define VELLUM_LEAK_CHECK 1
#endif
#endif
#ifdef VELLUM_LEAK_CHECK
#include <sanitizer/lsan_interface.h>
#endif

namespace vellum::display {

// Destroys a daemon's window with its renderer and texture (any may be null) and shuts SDL
// down. In a sanitizer build LeakSanitizer's check runs once, in place of the one at exit,
// after the texture and renderer are gone and before the window: destroying a window that had
// a GL renderer unloads Mesa's EGL drivers, which leak about 7 KB as they go and are unloaded
// before an at-exit check could name them (so no suppression can). Everything of ours is freed
// by then and SDL's state is still reachable, so the check sees our leaks and not theirs.
inline void CloseSdl(SDL_Texture* texture, SDL_Renderer* renderer, SDL_Window* window) {
  if (texture) SDL_DestroyTexture(texture);
  if (renderer) SDL_DestroyRenderer(renderer);
#ifdef VELLUM_LEAK_CHECK
  __lsan_do_leak_check();
#endif
  if (window) SDL_DestroyWindow(window);
  SDL_Quit();
}

}  // namespace vellum::display
