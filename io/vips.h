// libvips, started once per process (it keeps its own thread pool and caches).
#pragma once

#include "core/common/status.h"

namespace vellum {

// Starts libvips on first use; an error says why it cannot start.
Status StartVips();

}  // namespace vellum
