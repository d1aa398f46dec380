// A small JSON writer for reports (report.json): objects, numbers, strings, booleans.
#pragma once

#include <cmath>
#include <sstream>
#include <string>

namespace vellum {

class JsonWriter {
 public:
  JsonWriter& BeginObject(const std::string& key = "") { return Open(key, '{'); }
  JsonWriter& EndObject() { return Close('}'); }
  JsonWriter& BeginArray(const std::string& key = "") { return Open(key, '['); }
  JsonWriter& EndArray() { return Close(']'); }
  JsonWriter& Number(const std::string& key, double value) {
    Key(key);
    if (std::isfinite(value) && value == std::floor(value) && std::fabs(value) < 1e15) {
      out_ << static_cast<long long>(value);
    } else if (std::isfinite(value)) {
      out_.precision(9);
      out_ << value;
    } else {
      out_ << "null";
    }
    return *this;
  }
  JsonWriter& String(const std::string& key, const std::string& value) {
    Key(key);
    out_ << '"' << Escape(value) << '"';
    return *this;
  }
  JsonWriter& Bool(const std::string& key, bool value) {
    Key(key);
    out_ << (value ? "true" : "false");
    return *this;
  }
  std::string str() const { return out_.str() + "\n"; }

 private:
  static std::string Escape(const std::string& s) {
    std::string r;
    for (char c : s) {
      if (c == '"' || c == '\\') {
        r += '\\';
        r += c;
      } else if (c == '\n') {
        r += "\\n";
      } else if (static_cast<unsigned char>(c) < 0x20) {
        r += ' ';
      } else {
        r += c;
      }
    }
    return r;
  }
  void Key(const std::string& key) {
    if (!first_) out_ << ",";
    first_ = false;
    out_ << "\n" << std::string(2 * depth_, ' ');
    if (!key.empty()) out_ << '"' << Escape(key) << "\": ";
  }
  JsonWriter& Open(const std::string& key, char c) {
    if (depth_ > 0 || !first_) Key(key);
    out_ << c;
    ++depth_;
    first_ = true;
    return *this;
  }
  JsonWriter& Close(char c) {
    --depth_;
    out_ << "\n" << std::string(2 * depth_, ' ') << c;
    first_ = false;
    return *this;
  }
  std::ostringstream out_;
  int depth_ = 0;
  bool first_ = true;
};

}  // namespace vellum
