// The session view on disk: <data>/index.html, a contact sheet of every scan in the data folder
// (newest first; retaken attempts after, marked so), each with its thumbnail (the restored page
// from its report), catalogue identity, quality verdict or failure, and links to its report and
// restored TIFF. A library's operator opens it in a browser to see a sequence at a glance; the
// restorer writes it after each scan, `vellum sheet` on demand.
#pragma once

#include <cstdint>
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

// Every scan folder of `data_dir` (and of its retaken/), newest first, retaken ones last.
std::vector<SheetEntry> ReadSheet(const std::string& data_dir);

// Writes <data_dir>/index.html (whole or not at all); errors name the file.
Status WriteContactSheet(const std::string& data_dir);

}  // namespace vellum::station
