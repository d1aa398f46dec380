// libvips, started once per process (it keeps its own thread pool and caches).
#pragma once

#include <string>

#include "core/common/status.h"

namespace vellum {

// Starts libvips on first use; an error says why it cannot start.
Status StartVips();

// A libvips error (VError::what(): one line per failing call, as "file: write error\nunix
// error: No space left on device\n") as one line, its parts joined by "; ".
std::string VipsErrorText(const char* what);

// Ok when `path` is an image in a format vellum reads through libvips: PNG, TIFF, JPEG, JPEG 2000
// or WebP. Other formats libvips knows (OpenEXR, FITS, PDF, SVG, ImageMagick's, ...) are refused
// naming the loader: no page a station keeps comes in them, and their loaders are not hardened
// against hostile files as these are (a malformed EXR leaked memory inside libvips 8.14's
// loader: fuzz/fuzz_files). An error names the file and says which.
Status CheckVipsLoader(const std::string& path);

}  // namespace vellum
