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

namespace {

std::string SlugPart(const std::string& text) {
  std::string out;
  for (const char ch : text) {
    const unsigned char c = static_cast<unsigned char>(ch);
    if (std::isalnum(c) && c < 0x80) {
      out += ch;
    } else if ((ch == '.' || ch == '_') && !out.empty() && out.back() != '-') {
      out += ch;
    } else if (!out.empty() && out.back() != '-') {
      out += '-';
    }
  }
  while (!out.empty() && (out.back() == '-' || out.back() == '.' || out.back() == '_')) {
    out.pop_back();
  }
  return out;
}

}  // namespace

ScanIdentity NextFolio(const ScanIdentity& identity) {
  ScanIdentity next = identity;
  if (identity.side == "recto") {
    next.side = "verso";
    return next;
  }
  if (identity.side == "verso") next.side = "recto";
  // The last run of digits, plus one.
  std::string& folio = next.folio;
  size_t end = folio.size();
  while (end > 0 && !std::isdigit(static_cast<unsigned char>(folio[end - 1]))) --end;
  size_t begin = end;
  while (begin > 0 && std::isdigit(static_cast<unsigned char>(folio[begin - 1]))) --begin;
  if (begin == end) return next;
  std::string digits = folio.substr(begin, end - begin);
  size_t k = digits.size();
  while (k > 0 && digits[k - 1] == '9') digits[--k] = '0';
  if (k == 0) {
    digits.insert(digits.begin(), '1');
  } else {
    ++digits[k - 1];
  }
  folio.replace(begin, end - begin, digits);
  return next;
}

std::string IdentityTitle(const ScanIdentity& identity) {
  std::string title = identity.shelfmark;
  std::string folio = identity.folio;
  if (!identity.side.empty()) folio += (folio.empty() ? "" : " ") + identity.side;
  if (!folio.empty()) title += (title.empty() ? "" : ", ") + folio;
  return title;
}

std::string IdentitySlug(const ScanIdentity& identity) {
  std::string slug;
  auto add = [&](const std::string& text) {
    const std::string part = SlugPart(text);
    if (part.empty()) return;
    if (!slug.empty()) slug += '_';
    slug += part;
  };
  add(identity.shelfmark);
  add(identity.folio);
  add(identity.side);
  if (slug.empty()) add(identity.label);
  if (slug.size() > kMaxSlug) {
    slug.resize(kMaxSlug);
    while (!slug.empty() && (slug.back() == '-' || slug.back() == '.' || slug.back() == '_')) {
      slug.pop_back();
    }
  }
  return slug;
}

}  // namespace vellum
