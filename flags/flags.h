// Command-line flags of the vellum tools: --name value or --name=value, --help, and a
// `--config FILE` of `flag: value` lines (YAML, as the station's configs in /etc/vellum are).
//
// Why not CLI11 (Debian's libcli11-dev, 2.1): its config files are TOML or INI; ours are YAML
// and are read through the same guarded OpenCV reader as every other YAML file of the station
// (io/yaml_guard.h, fuzzed). With CLI11 we would still write that YAML reader, as a CLI11
// Config subclass, and restate our exit-status and help contract in its terms; this class is
// 170 lines and does exactly what the tools need.
#pragma once

#include <map>
#include <opencv2/core.hpp>
#include <stdexcept>
#include <string>
#include <vector>

namespace vellum {

// Thrown for bad command lines; main prints its message and exits with status 2.
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

class Flags {
 public:
  struct Spec {
    std::string name, value_name, help, default_value;
  };
  Flags(std::string command, std::string summary, std::vector<Spec> specs);

  // Parses args; returns false when --help was asked (the help is then printed to stdout).
  // When a flag named "config" is given, its file (YAML, flag: value) supplies the flags the
  // command line leaves out; an unknown key or a malformed file throws UsageError.
  bool Parse(const std::vector<std::string>& args);
  std::string Help() const;

  bool Has(const std::string& name) const;
  std::string Get(const std::string& name) const;
  // Typed getters throw UsageError naming the flag when the value does not parse.
  int GetInt(const std::string& name, int min, int max) const;
  double GetDouble(const std::string& name, double min, double max) const;
  bool GetBool(const std::string& name) const;
  cv::Size GetSize(const std::string& name) const;  // WIDTHxHEIGHT
  std::string Require(const std::string& name) const;
  const std::string& command() const { return command_; }

 private:
  void LoadConfig(const std::string& path);
  std::string command_, summary_;
  std::vector<Spec> specs_;
  std::map<std::string, std::string> values_;
};

// Splits a command's arguments into positional ones and flags with their values ("--name
// value" or "--name=value"), for commands that take both (vellum export LOG DIR). `switches`
// are the flags that take no value ("--force").
void SplitPositional(const std::vector<std::string>& args, std::vector<std::string>* positional,
                     std::vector<std::string>* flags,
                     const std::vector<std::string>& switches = {});

}  // namespace vellum
