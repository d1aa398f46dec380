// What the operator says lies on the table (docs/formats.md, "What the object is"): a single leaf,
// an open book (two pages meeting at a gutter), or "auto" (vellum decides, and splits a spread only
// on strong evidence). In scan.yaml as `object: leaf | book | auto`.
#pragma once

#include <string>

namespace vellum {

enum class ObjectKind { kAuto, kLeaf, kBook };

inline const char* ToString(ObjectKind kind) {
  switch (kind) {
    case ObjectKind::kLeaf:
      return "leaf";
    case ObjectKind::kBook:
      return "book";
    case ObjectKind::kAuto:
      return "auto";
  }
  return "auto";
}

// "leaf", "book" or "auto"; false (and *kind unchanged) for anything else.
inline bool ParseObjectKind(const std::string& text, ObjectKind* kind) {
  for (ObjectKind k : {ObjectKind::kAuto, ObjectKind::kLeaf, ObjectKind::kBook}) {
    if (text == ToString(k)) {
      *kind = k;
      return true;
    }
  }
  return false;
}

}  // namespace vellum
