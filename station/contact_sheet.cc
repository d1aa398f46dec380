#include "station/contact_sheet.h"

#include <sys/stat.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/common/text.h"
#include "io/json.h"
#include "io/scan_io.h"
#include "station/scan_log.h"
#include "station/scan_store.h"

namespace vellum::station {
namespace fs = std::filesystem;
namespace {

// The entry of one scan folder (`dir`, named `name`).
SheetEntry ReadEntry(const fs::path& dir, const std::string& relative, int64_t id) {
  SheetEntry e;
  e.scan_id = id;
  e.folder = relative;
  const fs::path raw = dir / "raw", results = dir / "results";
  std::error_code ec;
  if (fs::exists(raw / "scan.yaml", ec)) {
    Scan header;
    const Status ignored = ReadScanYaml(raw.string(), &header);
    (void)ignored;  // An unreadable scan.yaml: the entry shows what was read before the fault.
    e.identity = header.identity;
  } else {
    // A scan that never completed has no scan.yaml: its log's SCAN_STARTED names it.
    (void)ReadLoggedIdentity((raw / "captures.lcmlog").string(), &e.identity);
  }
  for (const char* page : {"report/restored.png", "report/restored-left.png"}) {
    if (fs::exists(results / page, ec)) {
      e.thumbnail = relative + "/results/" + page;
      break;
    }
  }
  for (const char* tif : {"restored.tif", "pages/left/restored.tif"}) {
    if (fs::exists(results / tif, ec)) {
      e.restored = relative + "/results/" + tif;
      break;
    }
  }
  // A restored scan's report decides, even while its folder is still marked pending (the
  // restorer writes the sheet before the decoder hears RESTORED and clears the mark).
  if (ReadGivenUp(raw.string(), &e.detail)) {
    e.state = "failed";
  } else if (!fs::exists(results / "report.json", ec) && fs::exists(dir / "pending", ec)) {
    e.state = "pending";
  } else if (fs::exists(results / "report.json", ec)) {
    std::ifstream in(results / "report.json");
    const nlohmann::json report = nlohmann::json::parse(in, nullptr, false);
    e.state = "restored";
    if (report.is_object() && report.contains("qc") && report["qc"].is_object()) {
      const nlohmann::json& qc = report["qc"];
      if (qc.contains("verdict") && qc["verdict"].is_string()) e.state = qc["verdict"];
      if (qc.contains("checks") && qc["checks"].is_array()) {
        for (const nlohmann::json& c : qc["checks"]) {
          if (!c.is_object() || !c.contains("verdict") || c["verdict"] == "pass") continue;
          e.detail += (e.detail.empty() ? "" : "; ") + c.value("name", std::string()) + ": " +
                      c.value("detail", std::string());
        }
      }
    }
  } else {
    e.state = "recording";
  }
  return e;
}

// Every file ReadEntry looks at, by size and modification time ("-" for one not there).
std::string Signature(const fs::path& dir) {
  static const char* const kRead[] = {"raw/scan.yaml",
                                      "raw/captures.lcmlog",
                                      "raw/failed.txt",
                                      "pending",
                                      "results/report.json",
                                      "results/report/restored.png",
                                      "results/restored.tif",
                                      "results/report/restored-left.png",
                                      "results/pages/left/restored.tif"};
  std::string signature;
  for (const char* rel : kRead) {
    struct stat st;
    if (::stat((dir / rel).c_str(), &st) != 0) {
      signature += "-;";
      continue;
    }
    signature += std::to_string(st.st_size) + ":" + std::to_string(st.st_mtim.tv_sec) + "." +
                 std::to_string(st.st_mtim.tv_nsec) + ";";
  }
  return signature;
}

void Collect(const fs::path& dir, const std::string& prefix, bool retaken, SheetCache* cache,
             std::map<std::string, SheetCache::Kept>* kept, std::vector<SheetEntry>* out) {
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    const int64_t id = ScanFolderId(name);
    if (id == 0 || !it->is_directory(ec)) continue;
    if (!cache) {
      out->push_back(ReadEntry(it->path(), prefix + name, id));
      out->back().retaken = retaken;
      continue;
    }
    const std::string path = it->path().string();
    const std::string signature = Signature(it->path());
    auto was = cache->folders.find(path);
    if (was == cache->folders.end() || was->second.signature != signature) {
      ++cache->reads;
      SheetEntry e = ReadEntry(it->path(), prefix + name, id);
      e.retaken = retaken;
      (*kept)[path] = {signature, std::move(e)};
    } else {
      (*kept)[path] = std::move(was->second);
    }
    out->push_back((*kept)[path].entry);
  }
}

}  // namespace

std::vector<SheetEntry> ReadSheet(const std::string& data_dir, SheetCache* cache) {
  std::vector<SheetEntry> entries;
  std::map<std::string, SheetCache::Kept> kept;  // The folders there now (gone ones dropped).
  Collect(data_dir, "", false, cache, &kept, &entries);
  Collect(fs::path(data_dir) / "retaken", "retaken/", true, cache, &kept, &entries);
  if (cache) cache->folders.swap(kept);
  std::sort(entries.begin(), entries.end(), [](const SheetEntry& a, const SheetEntry& b) {
    if (a.retaken != b.retaken) return !a.retaken;
    return a.scan_id > b.scan_id;
  });
  return entries;
}

Status WriteContactSheet(const std::string& data_dir, SheetCache* cache) {
  const std::vector<SheetEntry> entries = ReadSheet(data_dir, cache);
  std::ostringstream h;
  h << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n"
    << "<title>vellum: scans in " << HtmlEscape(data_dir) << "</title>\n<style>\n"
    << "body{font-family:sans-serif;margin:1.5em;color:#222}\n"
    << ".sheet{display:flex;flex-wrap:wrap;gap:14px}\n"
    << ".scan{width:230px;border:4px solid #999;padding:6px;background:#fafafa}\n"
    << ".scan img{width:100%;height:260px;object-fit:contain;background:#333}\n"
    << ".none{height:260px;display:flex;align-items:center;justify-content:center;"
       "background:#333;color:#ddd}\n"
    << ".pass{border-color:#2a2}.warn{border-color:#d90}.fail,.failed{border-color:#c22}"
       ".pending,.recording{border-color:#48c}.retaken{opacity:0.6}\n"
    << ".state{font-weight:bold;text-transform:uppercase}.detail{font-size:0.8em;color:#555}\n"
    << "</style></head><body>\n<h1>vellum: " << entries.size() << " scan(s) in "
    << HtmlEscape(data_dir) << "</h1>\n";
  bool retaken_heading = false;
  h << "<div class=sheet>\n";
  for (const SheetEntry& e : entries) {
    if (e.retaken && !retaken_heading) {
      h << "</div>\n<h2>Earlier attempts, retaken (kept in retaken/)</h2>\n<div class=sheet>\n";
      retaken_heading = true;
    }
    std::string title = IdentityTitle(e.identity);
    if (title.empty()) title = e.identity.label.empty() ? "(no identity)" : e.identity.label;
    h << "<div class=\"scan " << HtmlEscape(e.state) << (e.retaken ? " retaken" : "") << "\">";
    if (!e.thumbnail.empty()) {
      h << "<a href=\"" << HtmlEscape(e.folder) << "/results/report.html\"><img src=\""
        << HtmlEscape(e.thumbnail) << "\" alt=\"" << HtmlEscape(title) << "\"></a>";
    } else {
      h << "<div class=none>" << HtmlEscape(e.state) << "</div>";
    }
    h << "<div><b>" << HtmlEscape(title) << "</b></div>";
    h << "<div class=state>" << HtmlEscape(e.state) << "</div>";
    if (!e.detail.empty()) h << "<div class=detail>" << HtmlEscape(e.detail) << "</div>";
    h << "<div class=detail>" << HtmlEscape(e.folder);
    if (!e.restored.empty()) {
      h << " &middot; <a href=\"" << HtmlEscape(e.restored) << "\">TIFF</a>";
    }
    h << "</div></div>\n";
  }
  h << "</div>\n</body></html>\n";
  const std::string path = (fs::path(data_dir) / "index.html").string();
  const std::string tmp = path + ".tmp";
  Status s = WriteTextFile(tmp, h.str());
  if (!s.ok()) return s;
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) return Status::Error("cannot write " + path + ": " + ec.message());
  return Status::Ok();
}

}  // namespace vellum::station
