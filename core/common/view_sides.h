// Sides of the camera's view, as a set of bits: where the live view saw the leaf run off the view
// when a scan was asked (docs/formats.md, "What the live view saw"). Written as the sides' names
// joined by commas, "left,top", in view order (left, right, top, bottom); "" for none. In scan.yaml
// as a sequence of the names.
#pragma once

#include <algorithm>
#include <string>

namespace vellum {

enum ViewSide : int { kViewLeft = 1, kViewRight = 2, kViewTop = 4, kViewBottom = 8 };
inline constexpr int kViewSideCount = 4;
inline constexpr const char* kViewSideNames[kViewSideCount] = {"left", "right", "top", "bottom"};

// The names of the sides set in `sides`, joined by `separator`; "" for none.
inline std::string ViewSidesText(int sides, const char* separator = ",") {
  std::string text;
  for (int k = 0; k < kViewSideCount; ++k) {
    if (!(sides & (1 << k))) continue;
    if (!text.empty()) text += separator;
    text += kViewSideNames[k];
  }
  return text;
}

// How many sides `sides` holds.
inline int ViewSideCount(int sides) {
  int n = 0;
  for (int k = 0; k < kViewSideCount; ++k) n += (sides >> k) & 1;
  return n;
}

// One side's bit from its name; 0 for anything else.
inline int ViewSideOf(const std::string& name) {
  for (int k = 0; k < kViewSideCount; ++k) {
    if (name == kViewSideNames[k]) return 1 << k;
  }
  return 0;
}

// "left,top" (any order, each side once, no spaces) or "" into *sides; false (and *sides
// unchanged) for anything else.
inline bool ParseViewSides(const std::string& text, int* sides) {
  int read = 0;
  size_t at = 0;
  while (at < text.size()) {
    const size_t end = std::min(text.find(',', at), text.size());
    const int side = ViewSideOf(text.substr(at, end - at));
    if (side == 0 || (read & side)) return false;
    read |= side;
    at = end + 1;
    if (end + 1 == text.size()) return false;  // A trailing comma.
  }
  *sides = read;
  return true;
}

}  // namespace vellum
