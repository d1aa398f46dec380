// A SHA-256 manifest of every file under a folder, as BagIt writes it (RFC 8493,
// manifest-sha256.txt: one line per file, "<64 hex digits>  <path relative to the folder>",
// '/' between folders, sorted by path), so that an archive can prove a scan is whole and
// unchanged years later. Hashed with OpenSSL's libcrypto.
#pragma once

#include <string>
#include <vector>

#include "core/common/status.h"

namespace vellum {

inline constexpr const char* kManifestName = "manifest-sha256.txt";

// The SHA-256 of a file, as 64 lower-case hex digits.
Status Sha256OfFile(const std::string& path, std::string* hex);
// The SHA-256 of bytes in memory, as 64 lower-case hex digits.
std::string Sha256OfBytes(const std::string& bytes);

// Writes <dir>/manifest-sha256.txt over every regular file under `dir` but itself, or only
// under its subfolders `parts` when given (a station's scan: raw and results, not the
// supervisor's ledger beside them); written whole to a temporary name, then renamed. `files`
// (optional) gets how many it lists.
Status WriteManifest(const std::string& dir, const std::vector<std::string>& parts = {},
                     int* files = nullptr);

// Checks <dir>/manifest-sha256.txt against the files: `problems` gets one line per file that is
// missing or changed, or that is not listed but lies where the manifest lists files (its
// subfolders, or `dir` itself), and one per symbolic link anywhere under `dir`. An error when
// the manifest cannot be read, is malformed, or lists no file (empty or blank).
Status CheckManifest(const std::string& dir, std::vector<std::string>* problems);

}  // namespace vellum
