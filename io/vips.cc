#include "io/vips.h"

#include <mutex>
#include <string>
#include <vips/vips8>

namespace vellum {

std::string VipsErrorText(const char* what) {
  std::string text;
  for (const char* c = what; *c != '\0'; ++c) {
    if (*c != '\n') {
      text += *c;
    } else if (c[1] != '\0') {
      text += "; ";
    }
  }
  return text;
}

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

Status CheckVipsLoader(const std::string& path) {
  const Status s = StartVips();
  if (!s.ok()) return Status::Error(path + ": " + s.message());
  // libvips' loaders by class name, and what the error calls each format.
  static const struct {
    const char *loader, *format;
  } kRead[] = {{"VipsForeignLoadPng", "PNG"},
               {"VipsForeignLoadTiff", "TIFF"},
               {"VipsForeignLoadJpeg", "JPEG"},
               {"VipsForeignLoadJp2k", "JPEG 2000"},
               {"VipsForeignLoadWebp", "WebP"}};
  const char* found = vips_foreign_find_load(path.c_str());
  vips_error_clear();
  if (!found) return Status::Error(path + ": not a readable image");
  const std::string loader = found;
  for (const auto& r : kRead) {
    if (loader.rfind(r.loader, 0) == 0) return Status::Ok();
  }
  std::string formats;
  for (const auto& r : kRead) formats += std::string(formats.empty() ? "" : ", ") + r.format;
  std::string name = loader.substr(std::string("VipsForeignLoad").size());
  if (name.size() > 4 && name.compare(name.size() - 4, 4, "File") == 0) {
    name.resize(name.size() - 4);
  }
  return Status::Error(path + ": not a readable image (by its first bytes, one for libvips' " +
                       name + " loader; vellum reads " + formats + ")");
}

}  // namespace vellum
