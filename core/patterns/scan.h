// One structured-light scan as captured: the pattern sequence shown, the texture under studio
// light, and the camera frame taken under each pattern (docs/formats.md's scan directory, in
// memory).
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/object_kind.h"
#include "core/common/view_sides.h"
#include "core/patterns/patterns.h"

namespace vellum {

// What the scanned object is, for the catalogue (docs/formats.md, "Identity"); every field may be
// empty. In scan.yaml as shelfmark, folio, side, operator, note and label.
struct ScanIdentity {
  std::string shelfmark;  // Shelfmark or call number ("MS 12").
  std::string folio;      // Folio or page number ("3").
  std::string side;       // recto, verso, left, right, or empty.
  std::string operator_name;
  std::string note;
  std::string label;  // The operator's own words.

  bool empty() const {
    return shelfmark.empty() && folio.empty() && side.empty() && operator_name.empty() &&
           note.empty() && label.empty();
  }
  bool operator==(const ScanIdentity& o) const {
    return shelfmark == o.shelfmark && folio == o.folio && side == o.side &&
           operator_name == o.operator_name && note == o.note && label == o.label;
  }
};

// Calls f(key, field) for each field of a ScanIdentity (const or not), under its key in
// scan.yaml and in report.json's identity section.
template <class Identity, class F>
void ForEachIdentityField(Identity& id, F&& f) {
  f("shelfmark", id.shelfmark);
  f("folio", id.folio);
  f("side", id.side);
  f("operator", id.operator_name);
  f("note", id.note);
  f("label", id.label);
}

// The most bytes a field of ScanIdentity may hold.
inline constexpr size_t kMaxIdentityField = 200;

// Identity text from anyone (a flag, a message, a file) made safe to keep: control characters
// removed, cut to kMaxIdentityField bytes (at a UTF-8 character boundary), spaces trimmed;
// `side` lower-cased. Sets *why (if given) to what was wrong with the input: an unknown side
// (then dropped), or text that had to be changed; empty when it was clean.
ScanIdentity SanitizedIdentity(const ScanIdentity& identity, std::string* why = nullptr);

// The folio after `identity`'s, for a sequence of scans: recto -> verso of the same folio;
// verso -> recto of the next (the folio's last number plus one: "3" -> "4", "f12" -> "f13");
// without a side (a spread, or pages), the next number. A folio without a number stays.
ScanIdentity NextFolio(const ScanIdentity& identity);

// A spread (an open book, two pages in one scan) names its opening in `folio`, side empty:
// "2v-3r" when the book is foliated (the left page is folio 2 verso, the right folio 3 recto),
// "14-15" when it is paginated. NextFolio turns to the next opening ("3v-4r", "16-17").
// PageIdentity gives one page of it ("left" or "right") its own folio and side ("2", verso;
// "14", left); a folio that is not an opening keeps its text, with the page as its side.
ScanIdentity PageIdentity(const ScanIdentity& spread, const std::string& page);

// The identity as a person reads it: "MS 12, 3 recto" (shelfmark, then folio and side); ""
// when it has none of them.
std::string IdentityTitle(const ScanIdentity& identity);

// The most bytes of IdentitySlug.
inline constexpr size_t kMaxSlug = 64;

// A readable name for a folder, safe on any file system: the shelfmark, folio and side (else
// the label), each with every run of characters other than ASCII letters, digits, '.' and '_'
// made one '-', and no '.' or '-' at either end (so never "..", nor a hidden file); joined by
// '_', at most kMaxSlug bytes; "" when nothing is left ("MS 12", "3", "recto" -> "MS-12_3_recto").
std::string IdentitySlug(const ScanIdentity& identity);

// An extra image of the page in the scan's pose under another light: raking light
// from one side, UV fluorescence, infrared, or the operator's own. Restored through the same
// sheet as the texture, so all register to each other.
struct ScanLight {
  std::string name;  // ValidLightName: its file is light_<name>.png.
  // Unit vector from the page towards a distant light (world); zero when it is not one (UV
  // flood lamps) or not known. Three or more lights with a direction give photometric normals.
  cv::Vec3d direction{0.0, 0.0, 0.0};
  cv::Mat image;  // 8 or 16 bit, gray or BGR, the camera's size.

  bool directed() const { return direction.dot(direction) > 0; }
};

// A light's name: 1 to 32 of a-z, 0-9, '-' and '_', starting with a letter or digit (a file
// name on any system, and a key in report.json).
bool ValidLightName(const std::string& name);
inline constexpr int kMaxLights = 32;  // Extra lights a scan may have.
// A light's direction made a unit vector; false when it is not finite, is zero, or does not point
// up from the table (z > 0).
bool UnitLightDirection(const cv::Vec3d& v, cv::Vec3d* unit);

struct Scan {
  PatternSequence sequence;
  cv::Size camera_size;         // 0x0 when unknown (a pattern set not yet captured).
  cv::Mat texture;              // 8 or 16 bit, gray or BGR.
  std::vector<cv::Mat> frames;  // 8-bit gray, one per pattern.
  ScanIdentity identity;
  std::vector<ScanLight> lights;  // Extra images under other lights, each named once.
  // The operator's hint where the scene is ambiguous: camera pixels inside the leaf (scan.yaml's
  // leaf_hint; drawn in vellum-viewer); empty when none. It outranks the options' hint.
  cv::Rect leaf_hint;
  // What the operator says lies on the table (scan.yaml's `object`): a leaf, an open book, or
  // auto (vellum decides). It outranks the options'.
  ObjectKind object = ObjectKind::kAuto;
  // Where the live view saw the leaf run off the camera's view when the scan was asked (ViewSide
  // bits; scan.yaml's live_off_view): 0 when it saw the leaf in view, or saw none.
  int live_off_view = 0;
};

}  // namespace vellum
