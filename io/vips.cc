#include "io/vips.h"

#include <mutex>
#include <string>
#include <vips/vips8>

namespace vellum {

Status StartVips() {
  static std::once_flag once;
  static bool ok = false;
  std::call_once(once, [] { ok = VIPS_INIT("vellum") == 0; });
  return ok ? Status::Ok() : Status::Error(std::string("libvips: ") + vips_error_buffer());
}

}  // namespace vellum
