#include "core/patterns/scan.h"

#include <algorithm>
#include <cctype>
#include <cmath>

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

// `text` with its last run of digits raised by `by` ("f. 99" + 1 = "f. 100"); unchanged when it
// has none.
std::string AddToLastNumber(const std::string& text, int by) {
  size_t end = text.size();
  while (end > 0 && !std::isdigit(static_cast<unsigned char>(text[end - 1]))) --end;
  size_t begin = end;
  while (begin > 0 && std::isdigit(static_cast<unsigned char>(text[begin - 1]))) --begin;
  if (begin == end) return text;
  std::string digits = text.substr(begin, end - begin);
  for (int step = 0; step < by; ++step) {
    size_t k = digits.size();
    while (k > 0 && digits[k - 1] == '9') digits[--k] = '0';
    if (k == 0) {
      digits.insert(digits.begin(), '1');
    } else {
      ++digits[k - 1];
    }
  }
  return text.substr(0, begin) + digits + text.substr(end);
}

// A spread's opening, "2v-3r" or "14-15": its two pages' folios, and whether they are folios
// (each ending in r or v after its number) rather than pages.
struct Opening {
  std::string left, right;
  bool foliated = false;
};

bool ParseOpening(const std::string& folio, Opening* opening) {
  const size_t dash = folio.find('-');
  if (dash == std::string::npos || folio.find('-', dash + 1) != std::string::npos) return false;
  opening->left = folio.substr(0, dash);
  opening->right = folio.substr(dash + 1);
  auto numbered = [](const std::string& part) {
    return std::any_of(part.begin(), part.end(),
                       [](char c) { return std::isdigit(static_cast<unsigned char>(c)); });
  };
  if (!numbered(opening->left) || !numbered(opening->right)) return false;
  auto side_letter = [](const std::string& part) {
    const char last = static_cast<char>(std::tolower(static_cast<unsigned char>(part.back())));
    return (last == 'r' || last == 'v') && part.size() > 1 &&
           std::isdigit(static_cast<unsigned char>(part[part.size() - 2]));
  };
  opening->foliated = side_letter(opening->left) && side_letter(opening->right);
  return true;
}

}  // namespace

ScanIdentity NextFolio(const ScanIdentity& identity) {
  ScanIdentity next = identity;
  if (identity.side == "recto") {
    next.side = "verso";
    return next;
  }
  if (identity.side == "verso") next.side = "recto";
  Opening opening;
  if (identity.side.empty() && ParseOpening(identity.folio, &opening)) {
    // The next opening: one leaf on when foliated, two pages on when paginated.
    const int by = opening.foliated ? 1 : 2;
    next.folio = AddToLastNumber(opening.left, by) + "-" + AddToLastNumber(opening.right, by);
    return next;
  }
  next.folio = AddToLastNumber(identity.folio, 1);
  return next;
}

ScanIdentity PageIdentity(const ScanIdentity& spread, const std::string& page) {
  ScanIdentity id = spread;
  id.side = page;
  Opening opening;
  if (!ParseOpening(spread.folio, &opening)) return id;
  std::string folio = page == "left" ? opening.left : opening.right;
  if (opening.foliated) {
    const char letter = static_cast<char>(std::tolower(static_cast<unsigned char>(folio.back())));
    id.side = letter == 'r' ? "recto" : "verso";
    folio.pop_back();
  }
  id.folio = folio;
  return id;
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

bool UnitLightDirection(const cv::Vec3d& v, cv::Vec3d* unit) {
  const double norm = cv::norm(v);
  if (!std::isfinite(norm) || norm < 1e-9 || !(v[2] > 0)) return false;
  *unit = v / norm;
  return true;
}

bool ValidLightName(const std::string& name) {
  if (name.empty() || name.size() > 32 || name[0] == '-' || name[0] == '_') return false;
  return std::all_of(name.begin(), name.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' || c == '_';
  });
}

}  // namespace vellum
