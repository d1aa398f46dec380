// A SHA-256 manifest of every file under a folder, as BagIt writes it (RFC 8493,
// manifest-sha256.txt: one line per file, "<64 hex digits>  <path relative to the folder>",
// '/' between folders, sorted by path), so that an archive can prove a scan is whole and
// unchanged years later. Hashed with OpenSSL's libcrypto.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "core/common/status.h"

namespace vellum {

inline constexpr const char* kManifestName = "manifest-sha256.txt";

// The SHA-256 of a file, as 64 lower-case hex digits.
Status Sha256OfFile(const std::string& path, std::string* hex);
// The SHA-256 of bytes in memory, as 64 lower-case hex digits.
std::string Sha256OfBytes(const std::string& bytes);

// The SHA-256s of a folder's files taken as they were written (a scan's raw captures, hashed
// by the decoder while the next frames arrive), so that the manifest written at the end need
// not read them again: <dir>/recorded-sha256.txt, one line per file, "<64 hex digits>  <size in
// bytes>  <modification time, ns since the epoch>  <path relative to dir>". A file is hashed
// from disk, what the manifest vouches for; one that grows (an appended log) in pieces as it
// grows. WriteManifest takes a recorded hash only while the file's size and modification time
// are still those recorded, and hashes the file again otherwise.
// A station's daemons that write results keep records of their own beside it, in the same form:
// <dir>/recorded-sha256-<name>.txt (RecordedHashesName), each written by one process only.
inline constexpr const char* kRecordedHashesName = "recorded-sha256.txt";
std::string RecordedHashesName(const std::string& name);

class HashRecord {
 public:
  // `file`: the record's name in `dir`.
  explicit HashRecord(std::string dir = "", std::string file = kRecordedHashesName)
      : dir_(std::move(dir)), file_(std::move(file)) {}
  // Hashes what the file `rel` (relative to the folder) holds now: one written whole.
  Status Add(const std::string& rel);
  // Hashes what was appended to `rel` since the last call (all of it the first time, or when
  // it is shorter than what was hashed: cut and written again).
  Status Grow(const std::string& rel);
  // Writes the record (to a temporary name, then renamed): the files as they are now; one that
  // changed since it was hashed is left out (WriteManifest hashes it).
  Status Save() const;

 private:
  struct Growing;
  struct Entry {
    std::string hex;
    int64_t size = 0, mtime_ns = 0;
  };
  std::string dir_, file_;
  std::map<std::string, Entry> done_;
  std::map<std::string, std::shared_ptr<Growing>> growing_;
};

// Writes <dir>/manifest-sha256.txt over every regular file under `dir` but itself (and
// recorded-sha256.txt), or only under its subfolders `parts` when given (a station's scan: raw
// and results, not the supervisor's ledger beside them); written whole to a temporary name,
// then renamed. Files whose hashes a record in <dir> holds (recorded-sha256.txt or
// recorded-sha256-<name>.txt), unchanged since, are not read again. `files` (optional) gets how
// many it lists.
Status WriteManifest(const std::string& dir, const std::vector<std::string>& parts = {},
                     int* files = nullptr);

// Checks <dir>/manifest-sha256.txt against the files: `problems` gets one line per file that is
// missing or changed, or that is not listed but lies where the manifest lists files (its
// subfolders, or `dir` itself), and one per symbolic link anywhere under `dir`. An error when
// the manifest cannot be read, is malformed, or lists no file (empty or blank).
Status CheckManifest(const std::string& dir, std::vector<std::string>* problems);

}  // namespace vellum
