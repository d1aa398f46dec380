#include "core/patterns/scan.h"

#include <cctype>

namespace vellum {
namespace {

// Control characters out, cut at kMaxIdentityField bytes on a character boundary, trimmed.
std::string Clean(const std::string& text, const char* field, std::string* why) {
  std::string out;
  for (const char ch : text) {
    const unsigned char c = static_cast<unsigned char>(ch);
    if (c < 0x20 || c == 0x7f) continue;
    out += ch;
  }
  if (out.size() > kMaxIdentityField) {
    size_t end = kMaxIdentityField;
    while (end > 0 && (static_cast<unsigned char>(out[end]) & 0xc0) == 0x80) --end;
    out.resize(end);
  }
  const size_t first = out.find_first_not_of(' ');
  out = first == std::string::npos ? "" : out.substr(first, out.find_last_not_of(' ') - first + 1);
  if (why && out != text) {
    if (!why->empty()) *why += "; ";
    *why += std::string(field) + ": control characters removed, cut to " +
            std::to_string(kMaxIdentityField) + " bytes or trimmed";
  }
  return out;
}

}  // namespace

ScanIdentity SanitizedIdentity(const ScanIdentity& in, std::string* why) {
  if (why) why->clear();
  ScanIdentity out;
  out.shelfmark = Clean(in.shelfmark, "shelfmark", why);
  out.folio = Clean(in.folio, "folio", why);
  out.operator_name = Clean(in.operator_name, "operator", why);
  out.note = Clean(in.note, "note", why);
  out.label = Clean(in.label, "label", why);
  std::string side = Clean(in.side, "side", why);
  for (char& c : side) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (side == "recto" || side == "verso" || side == "left" || side == "right" || side.empty()) {
    out.side = side;
  } else if (why) {
    *why += std::string(why->empty() ? "" : "; ") + "side '" + side +
            "' is not recto, verso, left or right: dropped";
  }
  return out;
}

}  // namespace vellum
