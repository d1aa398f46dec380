#include "io/manifest.h"

#include <openssl/evp.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <set>
#include <sstream>

namespace vellum {
namespace fs = std::filesystem;
namespace {

// The first folder of a relative path ("" for a file at the top).
std::string TopFolder(const std::string& rel) {
  const size_t slash = rel.find('/');
  return slash == std::string::npos ? "" : rel.substr(0, slash);
}

// Every regular file under `dir` but the manifest, as relative paths with '/', sorted.
std::vector<std::string> FilesUnder(const std::string& dir) {
  std::vector<std::string> files;
  std::error_code ec;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->is_symlink() || !it->is_regular_file()) continue;  // Links: SymlinksUnder.
    const std::string rel = fs::relative(it->path(), dir).generic_string();
    if (rel == kManifestName || rel == std::string(kManifestName) + ".tmp") continue;
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
  std::string Hex() {
    unsigned char digest[EVP_MAX_MD_SIZE];
    unsigned int length = 0;
    if (ok_) EVP_DigestFinal_ex(ctx_.get(), digest, &length);
    std::string hex;
    char two[3];
    for (unsigned int i = 0; i < length; ++i) {
      std::snprintf(two, sizeof(two), "%02x", digest[i]);
      hex += two;
    }
    return hex;
  }

 private:
  std::unique_ptr<EVP_MD_CTX, decltype(&EVP_MD_CTX_free)> ctx_;
  bool ok_ = false;
};

}  // namespace

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
  for (const std::string& rel : paths) {
    std::string hex;
    const Status s = Sha256OfFile((fs::path(dir) / rel).string(), &hex);
    if (!s.ok()) return s;
    text << hex << "  " << rel << "\n";
  }
  const fs::path path = fs::path(dir) / kManifestName;
  const fs::path tmp = path.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out << text.str();
    out.flush();
    if (!out) return Status::Error(tmp.string() + ": cannot write");
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) return Status::Error(path.string() + ": cannot write: " + ec.message());
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
