#include "flags/flags.h"

#include <algorithm>
#include <cstdio>
#include <opencv2/core/persistence.hpp>
#include <sstream>

#include "io/yaml_guard.h"

namespace vellum {

Flags::Flags(std::string command, std::string summary, std::vector<Spec> specs)
    : command_(std::move(command)), summary_(std::move(summary)), specs_(std::move(specs)) {}

bool Flags::Parse(const std::vector<std::string>& args) {
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    if (a == "--help" || a == "-h") {
      std::fputs(Help().c_str(), stdout);
      return false;
    }
    if (a.rfind("--", 0) != 0) throw UsageError("unexpected argument '" + a + "' (see --help)");
    std::string name = a.substr(2), value;
    const size_t eq = name.find('=');
    const Spec* spec = nullptr;
    const std::string bare = eq == std::string::npos ? name : name.substr(0, eq);
    for (const Spec& s : specs_) {
      if (s.name == bare) spec = &s;
    }
    if (!spec) throw UsageError("unknown flag --" + bare + " (see " + command_ + " --help)");
    if (eq != std::string::npos) {
      value = name.substr(eq + 1);
    } else if (spec->value_name.empty()) {
      value = "true";
    } else {
      if (i + 1 >= args.size()) throw UsageError("flag --" + bare + " needs a value");
      value = args[++i];
    }
    values_[bare] = value;
  }
  if (Has("config") && !Get("config").empty()) LoadConfig(Get("config"));
  return true;
}

void Flags::LoadConfig(const std::string& path) {
  const std::string problem = YamlTextProblem(path);
  if (!problem.empty()) throw UsageError(path + ": " + problem);
  cv::FileStorage fs;
  try {
    if (!fs.open(path, cv::FileStorage::READ)) throw UsageError(path + ": cannot open config file");
  } catch (const std::exception&) {
    throw UsageError(path + ": not a valid YAML config file");
  }
  const cv::FileNode root = fs.root();
  if (!root.isMap()) throw UsageError(path + ": config must be a map of flag: value");
  for (const cv::FileNode& n : root) {
    const std::string key = n.name();
    const Spec* spec = nullptr;
    for (const Spec& s : specs_) {
      if (s.name == key) spec = &s;
    }
    if (!spec || key == "config") {
      throw UsageError(path + ": unknown key '" + key + "' (keys are the flags of " + command_ +
                       " --help)");
    }
    std::string value;
    if (n.isString()) {
      value = static_cast<std::string>(n);
    } else if (n.isInt()) {
      value = std::to_string(static_cast<int>(n));
    } else if (n.isReal()) {
      char buf[64];
      std::snprintf(buf, sizeof(buf), "%.17g", static_cast<double>(n));
      value = buf;
    } else {
      throw UsageError(path + ": key '" + key + "' must be a single value");
    }
    if (!values_.count(key)) values_[key] = value;  // The command line wins.
  }
}

std::string Flags::Help() const {
  std::ostringstream o;
  o << "usage: " << command_ << " [flags]\n\n" << summary_ << "\n\nflags:\n";
  for (const Spec& s : specs_) {
    std::string left = "  --" + s.name + (s.value_name.empty() ? "" : " " + s.value_name);
    o << left;
    if (left.size() < 28)
      o << std::string(28 - left.size(), ' ');
    else
      o << "\n" << std::string(28, ' ');
    o << s.help;
    if (!s.default_value.empty()) o << " (default: " << s.default_value << ")";
    o << "\n";
  }
  o << "  --help                    print this help\n";
  return o.str();
}

bool Flags::Has(const std::string& name) const { return values_.count(name) > 0; }

std::string Flags::Get(const std::string& name) const {
  auto it = values_.find(name);
  if (it != values_.end()) return it->second;
  for (const Spec& s : specs_) {
    if (s.name == name) return s.default_value;
  }
  return "";
}

std::string Flags::Require(const std::string& name) const {
  const std::string v = Get(name);
  if (v.empty()) throw UsageError("flag --" + name + " is required (see " + command_ + " --help)");
  return v;
}

int Flags::GetInt(const std::string& name, int min, int max) const {
  const std::string v = Get(name);
  try {
    size_t used = 0;
    const long n = std::stol(v, &used);
    if (used == v.size() && n >= min && n <= max) return static_cast<int>(n);
  } catch (const std::exception&) {
  }
  throw UsageError("flag --" + name + " must be an integer in [" + std::to_string(min) + ", " +
                   std::to_string(max) + "], got '" + v + "'");
}

double Flags::GetDouble(const std::string& name, double min, double max) const {
  const std::string v = Get(name);
  try {
    size_t used = 0;
    const double d = std::stod(v, &used);
    if (used == v.size() && d >= min && d <= max) return d;
  } catch (const std::exception&) {
  }
  std::ostringstream o;
  o << "flag --" << name << " must be a number in [" << min << ", " << max << "], got '" << v
    << "'";
  throw UsageError(o.str());
}

bool Flags::GetBool(const std::string& name) const {
  const std::string v = Get(name);
  if (v == "true" || v == "1" || v == "yes") return true;
  if (v == "false" || v == "0" || v == "no" || v.empty()) return false;
  throw UsageError("flag --" + name + " must be true or false, got '" + v + "'");
}

cv::Size Flags::GetSize(const std::string& name) const {
  const std::string v = Get(name);
  int w = 0, h = 0;
  char x = 0, extra = 0;
  if (std::sscanf(v.c_str(), "%d%c%d%c", &w, &x, &h, &extra) == 3 && (x == 'x' || x == 'X') &&
      w > 0 && h > 0 && w <= 65535 && h <= 65535) {
    return {w, h};
  }
  throw UsageError("flag --" + name + " must be WIDTHxHEIGHT, e.g. 1024x768, got '" + v + "'");
}

void SplitPositional(const std::vector<std::string>& args, std::vector<std::string>* positional,
                     std::vector<std::string>* flags, const std::vector<std::string>& switches) {
  for (size_t i = 0; i < args.size(); ++i) {
    if (args[i].rfind("--", 0) == 0) {
      flags->push_back(args[i]);
      const bool takes_value = args[i] != "--help" && std::find(switches.begin(), switches.end(),
                                                                args[i]) == switches.end();
      if (args[i].find('=') == std::string::npos && takes_value && i + 1 < args.size()) {
        flags->push_back(args[++i]);
      }
    } else {
      positional->push_back(args[i]);
    }
  }
}

}  // namespace vellum
