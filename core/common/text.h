// Small text helpers shared by messages, logs and reports.
#pragma once

#include <iomanip>
#include <opencv2/core.hpp>
#include <sstream>
#include <string>

namespace vellum {

// "1600x1200".
// `value` with `digits` digits after the point ("0.2").
inline std::string Fixed(double value, int digits) {
  std::ostringstream out;
  out << std::fixed << std::setprecision(digits) << value;
  return out.str();
}

inline std::string SizeText(cv::Size size) {
  return std::to_string(size.width) + "x" + std::to_string(size.height);
}

// Untrusted text (from a message or a file) fit for a log line: control characters and bytes
// outside printable ASCII become '?', and text longer than `max` is cut with "...".
inline std::string Printable(const std::string& text, size_t max = 200) {
  std::string out;
  for (size_t k = 0; k < text.size() && k < max; ++k) {
    const unsigned char c = static_cast<unsigned char>(text[k]);
    out += (c >= 0x20 && c < 0x7f) ? static_cast<char>(c) : '?';
  }
  if (text.size() > max) out += "...";
  return out;
}

// Text for HTML: <, >, & and " as entities.
inline std::string HtmlEscape(const std::string& text) {
  std::string out;
  for (const char c : text) {
    if (c == '<') {
      out += "&lt;";
    } else if (c == '>') {
      out += "&gt;";
    } else if (c == '&') {
      out += "&amp;";
    } else if (c == '"') {
      out += "&quot;";
    } else {
      out += c;
    }
  }
  return out;
}

}  // namespace vellum
