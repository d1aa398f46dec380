// The station's processes (docs/station.md): the gantry that captures a scan, and the processing
// chain that turns it into the restored page, in order, each link taking the product of the
// one before and handing on its own. Tools and the supervisor name the daemons from here.
#pragma once

#include <cstddef>

#include "station/node.h"

namespace vellum::station {

struct ChainLink {
  const char* process;  // The daemon.
  const char* product;  // The channel it hands the scan on with.
};

inline constexpr ChainLink kChain[] = {
    {"vellum-decoder", channel::kCorrespondence},
    {"vellum-triangulator", channel::kPointCloud},
    {"vellum-flattener", channel::kFlatMesh},
    {"vellum-restorer", channel::kRestored},
};
inline constexpr size_t kChainLength = sizeof(kChain) / sizeof(kChain[0]);

// The gantry: the projector conducts a scan, the camera captures it.
inline constexpr const char* kGantry[] = {"vellum-projector", "vellum-camera"};

// The position of `process` in the chain, or -1.
inline int ChainIndex(const std::string& process) {
  for (size_t k = 0; k < kChainLength; ++k) {
    if (process == kChain[k].process) return static_cast<int>(k);
  }
  return -1;
}

}  // namespace vellum::station
