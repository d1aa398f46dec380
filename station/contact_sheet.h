// The session view on disk: <data>/index.html, a contact sheet of every scan in the data folder
// (newest first; retaken attempts after, marked so), each with its thumbnail (the restored page
// from its report), catalogue identity, quality verdict or failure, and links to its report and
// restored TIFF. A library's operator opens it in a browser to see a sequence at a glance; the
// restorer writes it after each scan, `vellum sheet` on demand.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/patterns/scan.h"

namespace vellum::station {

// One scan folder as the sheet shows it.
struct SheetEntry {
  int64_t scan_id = 0;
  std::string folder;     // Relative to the data folder ("scan-..." or "retaken/scan-...").
  ScanIdentity identity;  // From raw/scan.yaml (empty when the scan never completed).
  std::string state;      // "pass", "warn", "fail" (restored), "failed", "pending", "recording"
  std::string detail;     // The failure's reason, or the checks that did not pass.
  std::string thumbnail;  // Relative path of the restored page's picture, "" if none.
  std::string restored;   // Relative path of restored.tif (or the left page's), "" if none.
  bool retaken = false;   // An earlier attempt, set aside.
};

// What the sheet read of each scan folder, kept so that a folder whose files are unchanged since
// (each file the entry is read from, by size and modification time) is not read again: the
// restorer writes the sheet before every RESTORED, and a data folder holds a day's scans and
// more (500 scans took 0.4 s to read, on every scan).
struct SheetCache {
  struct Kept {
    std::string signature;  // The sizes and times of the files the entry was read from.
    SheetEntry entry;
  };
  std::map<std::string, Kept> folders;  // By the folder's path.
  int64_t reads = 0;                    // Folders read, not taken from here.
};

// Every scan folder of `data_dir` (and of its retaken/), newest first, retaken ones last; with
// `cache`, a folder unchanged since the last call is taken from it.
std::vector<SheetEntry> ReadSheet(const std::string& data_dir, SheetCache* cache = nullptr);

// Writes <data_dir>/index.html (whole or not at all); errors name the file.
Status WriteContactSheet(const std::string& data_dir, SheetCache* cache = nullptr);

}  // namespace vellum::station
