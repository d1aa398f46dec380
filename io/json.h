// JSON files (report.json, restored.json) through nlohmann-json: objects keep their keys in the
// order they were set, numbers print as a reader expects them ("dpi": 150, not 150.0).
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "core/common/status.h"

namespace vellum {

using Json = nlohmann::ordered_json;

// A whole number as an integer, any other finite number as it is, NaN or infinity as null.
Json JsonNumber(double value);

// Writes `json` indented by two spaces, with a final newline; errors name the file.
Status WriteJsonFile(const std::string& path, const Json& json);
// Writes `text` to `path` (replacing it); errors name the file.
Status WriteTextFile(const std::string& path, const std::string& text);

}  // namespace vellum
