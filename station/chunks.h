// A product's chunks made one at a time: a sender encodes each as it is made, into one message
// whose arrays keep their memory from chunk to chunk, and so never holds the product a second
// time in fresh messages (30 MB at 1600 x 1200, faulted in page by page on every scan).
#pragma once

#include <functional>
#include <utility>
#include <vector>

namespace vellum::station {

template <class Msg>
struct ChunkMaker {
  int count = 0;
  // Fills chunk `index` (0 .. count - 1) into `msg`, every field; what it makes from, it holds.
  std::function<void(int index, Msg* msg)> make;

  // Every chunk at once.
  std::vector<Msg> All() const {
    std::vector<Msg> out(static_cast<size_t>(count));
    for (int k = 0; k < count; ++k) make(k, &out[static_cast<size_t>(k)]);
    return out;
  }
};

}  // namespace vellum::station
