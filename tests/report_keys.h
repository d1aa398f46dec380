// report.json as the tests compare two of them (the station's and `vellum process`'s).
#pragma once

#include <nlohmann/json.hpp>
#include <set>
#include <string>

namespace vellum {

// The keys of a JSON object, recursively ("pixels/valid"), into *keys.
inline void JsonKeys(const nlohmann::json& j, const std::string& prefix,
                     std::set<std::string>* keys) {
  if (!j.is_object()) return;
  for (auto it = j.begin(); it != j.end(); ++it) {
    keys->insert(prefix + it.key());
    JsonKeys(it.value(), prefix + it.key() + "/", keys);
  }
}

// The keys two runs of one scan must share: all but what each process measures of itself (a
// stage's peak memory, which a stage reported over the bus by another daemon does not carry).
inline std::set<std::string> ComparableReportKeys(const nlohmann::json& report) {
  std::set<std::string> keys;
  JsonKeys(report, "", &keys);
  for (auto k = keys.begin(); k != keys.end();)
    k = k->rfind("stages_peak_memory_mb", 0) == 0 ? keys.erase(k) : std::next(k);
  return keys;
}

}  // namespace vellum
