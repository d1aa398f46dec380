#include "io/manifest.h"

#include <openssl/evp.h>
#include <sys/stat.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <future>
#include <map>
#include <memory>
#include <set>
#include <sstream>

#include "io/json.h"
#include "io/write_whole.h"

namespace vellum {
namespace fs = std::filesystem;
namespace {

// The first folder of a relative path ("" for a file at the top).
std::string TopFolder(const std::string& rel) {
  const size_t slash = rel.find('/');
  return slash == std::string::npos ? "" : rel.substr(0, slash);
}

// Whether `rel` (relative to a folder) is one of its records of hashes, or one being written.
bool IsRecord(const std::string& rel) {
  const std::string name = rel.rfind(".part-", 0) == 0 ? rel.substr(6) : rel;
  const std::string stem = "recorded-sha256", ext = ".txt";
  return name.find('/') == std::string::npos && name.rfind(stem, 0) == 0 &&
         name.size() >= stem.size() + ext.size() &&
         name.compare(name.size() - ext.size(), ext.size(), ext) == 0 &&
         (name.size() == stem.size() + ext.size() || name[stem.size()] == '-');
}

// Every regular file under `dir` but the manifest and the records, as relative paths with '/',
// sorted.
std::vector<std::string> FilesUnder(const std::string& dir) {
  std::vector<std::string> files;
  std::error_code ec;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->is_symlink() || !it->is_regular_file()) continue;  // Links: SymlinksUnder.
    const std::string rel = fs::relative(it->path(), dir).generic_string();
    if (rel == kManifestName || rel == PartName(kManifestName) || IsRecord(rel)) continue;
    files.push_back(rel);
  }
  std::sort(files.begin(), files.end());
  return files;
}

// Every symbolic link under `dir` (relative paths, '/' between folders), whatever it points to
// (a file, a folder, nothing), sorted.
std::vector<std::string> SymlinksUnder(const std::string& dir) {
  std::vector<std::string> links;
  std::error_code ec;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->is_symlink()) {
      // Lexically: fs::relative would follow the link to where it points.
      links.push_back(it->path().lexically_relative(dir).generic_string());
    }
  }
  std::sort(links.begin(), links.end());
  return links;
}

// OpenSSL's SHA-256, fed in pieces.
class Sha256 {
 public:
  Sha256() : ctx_(EVP_MD_CTX_new(), EVP_MD_CTX_free) {
    ok_ = ctx_ && EVP_DigestInit_ex(ctx_.get(), EVP_sha256(), nullptr) == 1;
  }
  bool ok() const { return ok_; }
  void Add(const char* data, size_t size) {
    if (ok_) EVP_DigestUpdate(ctx_.get(), data, size);
  }
  std::string Hex() { return HexOf(ctx_.get()); }
  // The hash of what was added so far, which can still be added to.
  std::string HexSoFar() const {
    std::unique_ptr<EVP_MD_CTX, decltype(&EVP_MD_CTX_free)> copy(EVP_MD_CTX_new(), EVP_MD_CTX_free);
    if (!ok_ || !copy || EVP_MD_CTX_copy_ex(copy.get(), ctx_.get()) != 1) return "";
    return HexOf(copy.get());
  }

 private:
  std::string HexOf(EVP_MD_CTX* ctx) const {
    unsigned char digest[EVP_MAX_MD_SIZE];
    unsigned int length = 0;
    if (ok_) EVP_DigestFinal_ex(ctx, digest, &length);
    std::string hex;
    char two[3];
    for (unsigned int i = 0; i < length; ++i) {
      std::snprintf(two, sizeof(two), "%02x", digest[i]);
      hex += two;
    }
    return hex;
  }

  std::unique_ptr<EVP_MD_CTX, decltype(&EVP_MD_CTX_free)> ctx_;
  bool ok_ = false;
};

// A regular file's size and modification time (ns since the epoch); false when it is none.
bool Stat(const std::string& path, int64_t* size, int64_t* mtime_ns) {
  struct stat st;
  if (::stat(path.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) return false;
  *size = static_cast<int64_t>(st.st_size);
  *mtime_ns = static_cast<int64_t>(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec;
  return true;
}

// Adds bytes [from, to) of `path` to `sha`.
Status HashRange(const std::string& path, int64_t from, int64_t to, Sha256* sha) {
  std::ifstream in(path, std::ios::binary);
  if (!in || !in.seekg(from)) return Status::Error(path + ": cannot read");
  std::vector<char> buffer(1 << 20);
  for (int64_t left = to - from; left > 0;) {
    const int64_t want = std::min<int64_t>(left, static_cast<int64_t>(buffer.size()));
    in.read(buffer.data(), static_cast<std::streamsize>(want));
    if (in.gcount() != want) return Status::Error(path + ": read error");
    sha->Add(buffer.data(), static_cast<size_t>(want));
    left -= want;
  }
  return Status::Ok();
}

// The records in `dir` (recorded-sha256.txt, recorded-sha256-<name>.txt), by relative path:
// {hex, size, mtime}; empty when there are none (or they cannot be read: the files are hashed
// instead).
std::map<std::string, std::array<std::string, 3>> ReadRecorded(const std::string& dir) {
  std::vector<std::string> records;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (IsRecord(name) && name.rfind(".part-", 0) != 0) records.push_back(name);
  }
  std::sort(records.begin(), records.end());
  std::map<std::string, std::array<std::string, 3>> recorded;
  for (const std::string& record : records) {
    std::ifstream in(fs::path(dir) / record);
    std::string line;
    while (std::getline(in, line)) {
      std::istringstream fields(line);
      std::string hex, size, mtime, rel;
      if (!(fields >> hex >> size >> mtime) || hex.size() != 64) continue;
      std::getline(fields >> std::ws, rel);
      if (!rel.empty()) recorded[rel] = {hex, size, mtime};
    }
  }
  return recorded;
}

}  // namespace

std::string RecordedHashesName(const std::string& name) {
  return "recorded-sha256-" + name + ".txt";
}

struct HashRecord::Growing {
  Sha256 sha;
  int64_t hashed = 0;  // Bytes added to sha.
};

Status HashRecord::Add(const std::string& rel) {
  const std::string path = (fs::path(dir_) / rel).string();
  Entry e;
  int64_t size = 0, mtime = 0;
  if (!Stat(path, &e.size, &e.mtime_ns)) return Status::Error(path + ": cannot read");
  const Status s = Sha256OfFile(path, &e.hex);
  if (!s.ok()) return s;
  // Changed while it was read: left to the manifest.
  if (!Stat(path, &size, &mtime) || size != e.size || mtime != e.mtime_ns) return Status::Ok();
  done_[rel] = e;
  return Status::Ok();
}

Status HashRecord::Grow(const std::string& rel) {
  const std::string path = (fs::path(dir_) / rel).string();
  int64_t size = 0, mtime = 0;
  if (!Stat(path, &size, &mtime)) return Status::Error(path + ": cannot read");
  std::shared_ptr<Growing>& g = growing_[rel];
  if (!g || size < g->hashed) g = std::make_shared<Growing>();  // New, or cut.
  if (!g->sha.ok()) return Status::Error(path + ": SHA-256 not available");
  // Only up to the size seen: what is appended meanwhile is for the next call.
  const Status s = HashRange(path, g->hashed, size, &g->sha);
  if (!s.ok()) {
    growing_.erase(rel);
    return s;
  }
  g->hashed = size;
  done_[rel] = {g->sha.HexSoFar(), size, mtime};
  return Status::Ok();
}

Status HashRecord::Save() const {
  std::ostringstream text;
  for (const auto& [rel, e] : done_) {
    int64_t size = 0, mtime = 0;
    if (!Stat((fs::path(dir_) / rel).string(), &size, &mtime) || size != e.size ||
        mtime != e.mtime_ns) {
      continue;
    }
    text << e.hex << "  " << e.size << "  " << e.mtime_ns << "  " << rel << "\n";
  }
  return WriteTextFile((fs::path(dir_) / file_).string(), text.str());
}

Status Sha256OfFile(const std::string& path, std::string* hex) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error(path + ": cannot read");
  Sha256 sha;
  if (!sha.ok()) return Status::Error(path + ": SHA-256 not available");
  std::vector<char> buffer(1 << 20);
  while (in) {
    in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    if (in.gcount() > 0) sha.Add(buffer.data(), static_cast<size_t>(in.gcount()));
  }
  if (in.bad()) return Status::Error(path + ": read error");
  *hex = sha.Hex();
  return Status::Ok();
}

std::string Sha256OfBytes(const std::string& bytes) {
  Sha256 sha;
  sha.Add(bytes.data(), bytes.size());
  return sha.Hex();
}

Status WriteManifest(const std::string& dir, const std::vector<std::string>& parts, int* files) {
  std::ostringstream text;
  std::vector<std::string> paths;
  for (const std::string& rel : FilesUnder(dir)) {
    if (parts.empty() || std::count(parts.begin(), parts.end(), TopFolder(rel))) {
      paths.push_back(rel);
    }
  }
  const auto recorded = ReadRecorded(dir);
  std::vector<std::string> hexes(paths.size());
  std::vector<size_t> to_hash;  // The files not hashed as they were written, largest first.
  std::vector<int64_t> sizes(paths.size(), 0);
  for (size_t k = 0; k < paths.size(); ++k) {
    const auto known = recorded.find(paths[k]);
    int64_t mtime = 0;
    const bool stat = Stat((fs::path(dir) / paths[k]).string(), &sizes[k], &mtime);
    if (known != recorded.end() && stat && known->second[1] == std::to_string(sizes[k]) &&
        known->second[2] == std::to_string(mtime)) {
      hexes[k] = known->second[0];  // Hashed as it was written, unchanged since.
    } else {
      to_hash.push_back(k);
    }
  }
  std::stable_sort(to_hash.begin(), to_hash.end(),
                   [&](size_t a, size_t b) { return sizes[a] > sizes[b]; });
  // Hashed on two threads, each taking the largest file left: mostly the reading and the
  // hashing of one large file (a point map) beside all the others.
  std::vector<Status> hashed(paths.size(), Status::Ok());
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t n = next++; n < to_hash.size(); n = next++) {
      const size_t k = to_hash[n];
      hashed[k] = Sha256OfFile((fs::path(dir) / paths[k]).string(), &hexes[k]);
    }
  };
  std::future<void> second;
  // With no thread to be had, all on this one (the deferred second finds nothing left).
  if (to_hash.size() > 1) second = std::async(std::launch::async | std::launch::deferred, work);
  work();
  if (second.valid()) second.get();
  for (size_t k = 0; k < paths.size(); ++k) {
    if (!hashed[k].ok()) return hashed[k];  // The first by path.
    text << hexes[k] << "  " << paths[k] << "\n";
  }
  const Status s = WriteTextFile((fs::path(dir) / kManifestName).string(), text.str());
  if (!s.ok()) return s;
  if (files) *files = static_cast<int>(paths.size());
  return Status::Ok();
}

Status CheckManifest(const std::string& dir, std::vector<std::string>* problems) {
  problems->clear();
  const std::string path = (fs::path(dir) / kManifestName).string();
  std::ifstream in(path);
  if (!in) return Status::Error(path + ": cannot read");
  std::map<std::string, std::string> listed;  // path -> hash
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;  // Blank.
    if (line.size() < 67 || line.compare(64, 2, "  ") != 0 ||
        line.find_first_not_of("0123456789abcdef") < 64) {
      return Status::Error(path + ": line " + std::to_string(number) +
                           " is not '<sha-256 in hex>  <path>'");
    }
    listed[line.substr(66)] = line.substr(0, 64);
  }
  // A manifest that lists nothing proves nothing (a truncated or emptied one looks like that).
  if (listed.empty()) return Status::Error(path + ": lists no file (empty or blank)");
  for (const auto& [rel, want] : listed) {
    const std::string file = (fs::path(dir) / rel).string();
    std::error_code ec;
    if (!fs::is_regular_file(file, ec)) {
      problems->push_back(rel + ": missing");
      continue;
    }
    std::string got;
    const Status s = Sha256OfFile(file, &got);
    if (!s.ok()) {
      problems->push_back(rel + ": " + s.message());
    } else if (got != want) {
      problems->push_back(rel + ": changed (SHA-256 " + got + ", the manifest says " + want + ")");
    }
  }
  std::set<std::string> scope;  // Where the manifest lists files.
  for (const auto& entry : listed) scope.insert(TopFolder(entry.first));
  for (const std::string& rel : FilesUnder(dir)) {
    if (!listed.count(rel) && scope.count(TopFolder(rel))) {
      problems->push_back(rel + ": not in the manifest");
    }
  }
  // A link is reported wherever it lies: what it points to can change without the manifest
  // noticing (a scan's folders hold files, never links).
  for (const std::string& rel : SymlinksUnder(dir)) {
    std::error_code ec;
    const fs::path target = fs::read_symlink(fs::path(dir) / rel, ec);
    problems->push_back(rel + ": a symbolic link" +
                        (ec ? std::string() : " to " + target.string()) +
                        ", which the manifest cannot vouch for");
  }
  return Status::Ok();
}

}  // namespace vellum
