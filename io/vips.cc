#include "io/vips.h"

#include <mutex>
#include <string>
#include <vips/vips8>

namespace vellum {

Status StartVips() {
  static std::once_flag once;
  static bool ok = false;
  std::call_once(once, [] {
    ok = VIPS_INIT("vellum") == 0;
    // libvips warns on stderr of what it then reports as an error (a file cut short): the
    // error, with the file's name, is what vellum says.
    g_log_set_handler(
        "VIPS", static_cast<GLogLevelFlags>(G_LOG_LEVEL_WARNING | G_LOG_LEVEL_MESSAGE),
        [](const gchar*, GLogLevelFlags, const gchar*, gpointer) {}, nullptr);
  });
  return ok ? Status::Ok() : Status::Error(std::string("libvips: ") + vips_error_buffer());
}

}  // namespace vellum
