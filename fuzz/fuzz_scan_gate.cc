// libFuzzer: the decoder's capture bookkeeping (station/scan_gate.h) under any sequence of
// SCAN_STARTED, CAPTURE, CALIBRATION and give-up events for a few scan ids, sessions and
// pattern indices. Each 6 bytes of input are one event. Beyond "no crash", it checks the gate's
// promises against a model kept here: a capture is recorded only for the scan started last
// (with its session, through CheckCapture), each pattern at most once, never after the scan
// was whole or given up; a second capture of a recorded pattern is always reported as such.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <set>
#include <string>
#include <utility>

#include "station/scan_gate.h"
#include "station/scan_store.h"

namespace {

[[noreturn]] void Broken(const char* what) {
  std::fprintf(stderr, "scan gate broke its promise: %s\n", what);
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace vellum;
  using namespace vellum::station;
  namespace fs = std::filesystem;
  // An empty data folder: no scan on disk to take up, none to refuse for its folder.
  static const std::string dir =
      (fs::temp_directory_path() / ("vellum_fuzz_gate_" + std::to_string(getpid()))).string();
  ScanGate gate(dir);
  // The model: the open scan, its session and count, the patterns recorded, the scans over.
  int64_t open = 0, session = 0;
  int count = 0;
  std::set<int> recorded;
  std::set<int64_t> over;
  for (size_t at = 0; at + 6 <= size; at += 6) {
    const uint8_t* e = data + at;
    const int64_t id = e[1] % 6;           // 0 is never a scan.
    const int64_t sess = e[2] % 3;         // 0 is never a session.
    const int index = int(e[3] % 12) - 2;  // -2 .. 9: the texture, patterns, out of range.
    const int patterns = e[4] % 9;         // 0 .. 8.
    switch (e[0] % 4) {
      case 0: {
        scan_started_t m{};
        m.scan_id = id;
        m.session = sess;
        m.pattern_count = patterns;
        m.projector_width = 64;
        m.projector_height = 48;
        const ScanGate::Decision d = gate.Start(m);
        if (d.verdict == ScanGate::Verdict::kRecord) {
          if (id <= 0 || sess <= 0 || patterns <= 0 || over.count(id)) {
            Broken("a scan started that is not valid, or is over");
          }
          if (open != 0 && open != id) over.insert(open);  // Superseded: never reopened.
          open = id;
          session = sess;
          count = patterns;
          recorded.clear();
        }
        break;
      }
      case 1: {
        capture_t c{};
        c.scan_id = id;
        c.session = sess;
        c.pattern_index = index;
        c.pattern_count = e[5] % 2 ? patterns : count;
        c.projector_width = 64;
        c.projector_height = 48;
        if (!CheckCapture(c).ok()) break;  // The decoder refuses these before the gate.
        const ScanGate::Decision d = gate.Admit(c);
        const bool ours = open != 0 && id == open && sess == session && c.pattern_count == count;
        if (d.verdict == ScanGate::Verdict::kRecord) {
          if (!ours) Broken("a capture of another scan, session or count was recorded");
          if (!recorded.insert(index).second) Broken("a pattern was recorded twice");
          if (static_cast<int>(recorded.size()) == count + 1) {  // Whole: over.
            over.insert(open);
            open = 0;
          }
        } else if (d.verdict == ScanGate::Verdict::kDuplicate) {
          if (!ours || !recorded.count(index)) Broken("a duplicate that was not one");
        } else if (ours && !recorded.count(index)) {
          Broken("a capture of the open scan was refused");
        }
        break;
      }
      case 2: {
        calibration_t m{};
        m.scan_id = id;
        m.session = sess;
        const ScanGate::Decision d = gate.AdmitCalibration(m);
        if (d.verdict == ScanGate::Verdict::kRecord &&
            (id != open || sess != session || !recorded.empty())) {
          Broken("a calibration was recorded for a scan not open, or under way");
        }
        break;
      }
      case 3:
        gate.Close(id);
        over.insert(id);
        if (id == open) open = 0;
        break;
    }
  }
  return 0;
}
