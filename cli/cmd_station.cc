// The station from the command line: `scan` (ask for a scan and follow it to the restored
// page), `watch` (follow the bus until scans are restored), `export` and `import` (recorded
// scan log <-> scan directory).
#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <map>
#include <set>

#include "cli/commands.h"
#include "cli/progress.h"
#include "core/common/text.h"
#include "core/outline/outline.h"
#include "core/patterns/display_lag.h"
#include "io/calibration_io.h"
#include "station/chain.h"
#include "station/contact_sheet.h"
#include "station/daemon.h"
#include "station/messages.h"
#include "station/node.h"
#include "station/scan_log.h"
#include "station/scan_store.h"
#include "vellum/latency_probe_t.hpp"
#include "vellum/latency_request_t.hpp"
#include "vellum/latency_seen_t.hpp"
#include "vellum/pattern_shown_t.hpp"
#include "vellum/restored_t.hpp"
#include "vellum/scan_request_t.hpp"
#include "vellum/status_t.hpp"

namespace vellum {
namespace {

using station::Node;
namespace channel = station::channel;

// Follows the bus: progress from PATTERN_SHOWN and the status heartbeats, errors of the
// daemons, and RESTORED. Prints one updating line on a terminal, plain lines otherwise.
class Follower {
 public:
  Follower(Node* node, int64_t scan_id) : node_(node), scan_id_(scan_id) {
    node->Subscribe<pattern_shown_t>(channel::kPatternShown, [this](const pattern_shown_t& m) {
      if (scan_id_ && m.scan_id != scan_id_) return;
      // Capturing is about 70% of a scan's time on the default rig.
      const int captures = m.pattern_count + m.light_count + 1;
      progress_.Update(m.pattern_index < 0 ? std::string("capturing the texture")
                       : m.pattern_index >= m.pattern_count
                           ? "capturing under the light '" + Printable(m.light.name, 40) + "'"
                           : "capturing pattern " + std::to_string(m.pattern_index + 1) + " of " +
                                 std::to_string(m.pattern_count),
                       0.7 * (m.pattern_index + 1) / std::max(1, captures));
    });
    auto on_status = [this](const status_t& m) { OnStatus(m); };
    for (const char* process : station::kGantry) {
      node->Subscribe<status_t>(station::StatusChannel(process), on_status);
    }
    for (const station::ChainLink& link : station::kChain) {
      node->Subscribe<status_t>(station::StatusChannel(link.process), on_status);
    }
    node->Subscribe<restored_t>(channel::kRestored, [this](const restored_t& m) {
      if (scan_id_ && m.scan_id != scan_id_) return;
      EndLine();
      std::printf("scan %lld restored: %dx%d%s -> %s\n", static_cast<long long>(m.scan_id), m.width,
                  m.height,
                  m.view == "orthographic"
                      ? (" at " + std::to_string(static_cast<int>(m.dpi)) + " dpi").c_str()
                      : " (camera view)",
                  m.results.c_str());
      std::printf("scan %lld quality: %s (%s/report.html)\n", static_cast<long long>(m.scan_id),
                  m.qc.c_str(), m.results.c_str());
      for (const std::string& w : m.warnings) {
        std::fprintf(stderr, "scan %lld: warning %s\n", static_cast<long long>(m.scan_id),
                     w.c_str());
      }
      std::fflush(stdout);
      ++restored_;
      warned_ += m.nwarnings > 0 || (!m.qc.empty() && m.qc != "pass");
      results_ = m.results;
    });
  }

  int restored() const { return restored_; }
  // Scans restored doubtful: with warnings, or a verdict other than pass.
  int warned() const { return warned_; }
  const std::string& failure() const { return failure_; }
  const std::string& results() const { return results_; }
  bool Heard(const std::string& process) const { return heard_.count(process) > 0; }

  void EndLine() { progress_.Clear(); }

 private:
  void OnStatus(const status_t& m) {
    heard_.insert(m.process);
    int64_t& seen = errors_[m.process];
    if (!first_seen_.count(m.process)) {
      first_seen_[m.process] = true;
      seen = m.errors;  // Errors from before we started are not ours.
    }
    if (m.errors > seen) {
      seen = m.errors;
      if (!scan_id_ || m.last_error_scan_id == scan_id_ || m.last_error_scan_id == 0) {
        EndLine();
        std::fprintf(stderr, "%s: %s\n", m.process.c_str(), m.last_error.c_str());
        if (!scan_id_ || m.last_error_scan_id == scan_id_)
          failure_ = m.process + ": " + m.last_error;
      }
    }
    if (m.state == "busy" && (!scan_id_ || m.scan_id == scan_id_)) {
      // The processing stages after capture, in order.
      // Capturing is 70% of a scan's time; the chain's daemons share the rest.
      const int link = std::max(0, station::ChainIndex(m.process));
      const double fraction = 0.72 + 0.23 * link / (station::kChainLength - 1);
      progress_.Update(m.process.substr(7) + ": " + m.detail, fraction);
    }
  }

  Node* node_;
  int64_t scan_id_;
  Progress progress_;
  std::string failure_, results_;
  int restored_ = 0, warned_ = 0;
  std::map<std::string, int64_t> errors_;
  std::map<std::string, bool> first_seen_;
  std::set<std::string> heard_;  // Processes whose heartbeat came.
};

// Handles the bus until `done` or the timeout; returns false on timeout.
bool Follow(Node& node, double timeout_s, const std::function<bool()>& done) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (!done()) {
    if (std::chrono::steady_clock::now() > end || node.Stopping()) return false;
    node.lcm().handleTimeout(100);
  }
  return true;
}

std::vector<Flags::Spec> BusSpecs() {
  return {{"url", "URL", "LCM bus", station::kDefaultUrl}, station::StationSpec()};
}

}  // namespace

int RunScan(const std::vector<std::string>& args) {
  std::vector<Flags::Spec> specs = BusSpecs();
  specs.push_back({"label", "TEXT", "a note for the scan, the operator's own words", ""});
  specs.push_back({"shelfmark", "TEXT", "the object's shelfmark or call number (\"MS 12\")", ""});
  specs.push_back({"folio", "TEXT", "the folio or page number (\"3\")", ""});
  specs.push_back({"side", "SIDE", "recto, verso, left or right", ""});
  specs.push_back({"operator", "NAME", "who scans", ""});
  specs.push_back({"note", "TEXT", "anything else about the scan", ""});
  specs.push_back({"leaf-hint", "X,Y,W,H",
                   "where the leaf lies when it is not at the view's centre: a box inside it, as "
                   "fractions of the camera's view (0..1, x right, y down; as the viewer's drawn "
                   "hint)",
                   ""});
  specs.push_back({"object", "KIND",
                   "what lies on the table: leaf (never split into two pages), book (an open "
                   "book: two pages at a gutter) or auto (split only on strong evidence, else "
                   "flagged)",
                   "auto"});
  specs.push_back({"timeout", "S", "give up after this long", "600"});
  specs.push_back({"wait", "S",
                   "wait this long for every daemon's heartbeat before asking (no projector: "
                   "exit 1; another daemon missing: named, then asked anyway)",
                   "5"});
  specs.push_back({"scan-id", "ID",
                   "the scan's id (0: this clock's microseconds); the station refuses an id it "
                   "has recorded before",
                   "0"});
  Flags flags("vellum scan",
              "Asks the station for one scan (SCAN_REQUEST) once every daemon's heartbeat is\n"
              "heard, shows its progress and prints where the results are once the page is\n"
              "restored. Exit status 1 when the projector is not heard within --wait, a daemon\n"
              "reports the scan failed, or nothing happens before the timeout; 3 when the page\n"
              "was restored with warnings that make it doubtful (printed; the leaf runs off the\n"
              "view, an uncertain outline, high strain, pages missing at a gutter): check its\n"
              "report.html.",
              specs);
  if (!flags.Parse(args)) return 0;
  const double timeout = flags.GetDouble("timeout", 1, 86400);
  Node node("vellum-scan", flags.Get("url"));
  station::SetStationFromFlags(flags, &node);
  scan_request_t request{};
  request.scan_id = static_cast<int64_t>(flags.GetDouble("scan-id", 0, 9.2e18));
  if (request.scan_id <= 0) request.scan_id = station::NowUtime();
  ScanIdentity identity;
  identity.label = flags.Get("label");
  identity.shelfmark = flags.Get("shelfmark");
  identity.folio = flags.Get("folio");
  identity.side = flags.Get("side");
  identity.operator_name = flags.Get("operator");
  identity.note = flags.Get("note");
  std::string changed;
  identity = SanitizedIdentity(identity, &changed);
  if (!flags.Get("side").empty() && identity.side.empty()) {
    throw UsageError("--side must be recto, verso, left or right, got '" + flags.Get("side") + "'");
  }
  if (!changed.empty()) std::fprintf(stderr, "vellum scan: %s\n", changed.c_str());
  request.identity = station::ToMessage(identity);
  const std::string hint = flags.Get("leaf-hint");
  if (!hint.empty()) {
    double x = 0, y = 0, w = 0, h = 0;
    char end = 0;
    if (std::sscanf(hint.c_str(), "%lf,%lf,%lf,%lf%c", &x, &y, &w, &h, &end) != 4 ||
        !(x >= 0 && y >= 0 && w > 0 && h > 0 && x + w <= 1 && y + h <= 1)) {
      throw UsageError(
          "--leaf-hint must be X,Y,W,H as fractions of the camera's view (a box "
          "inside 0..1), got '" +
          hint + "'");
    }
    // The same share of the view a hint in camera pixels may cover (LeafHintFits).
    std::string why;
    if (!LeafHintShareFits(w * h, OutlineOptions().max_view_share, "--leaf-hint '" + hint + "'",
                           &why)) {
      throw UsageError(why);
    }
    station::ToLeafHint(cv::Rect2d(x, y, w, h), request.leaf_hint);
  }
  ObjectKind object = ObjectKind::kAuto;
  if (!ParseObjectKind(flags.Get("object"), &object)) {
    throw UsageError("--object must be leaf, book or auto, got '" + flags.Get("object") + "'");
  }
  request.object = ToString(object);
  Follower follower(&node, request.scan_id);
  // The request goes out once every daemon of the station is heard (a heartbeat a second), or
  // --wait has passed: one sent before the projector listens would be lost. Without the
  // projector nothing can start; without another daemon the scan is asked for anyway, so that
  // the station's own failure says what is missing, and this names it first.
  const double wait = std::min(timeout, flags.GetDouble("wait", 0, 600));
  const auto missing = [&] {
    std::string names;
    for (const char* process : station::kGantry) {
      if (!follower.Heard(process)) names += std::string(names.empty() ? "" : ", ") + process;
    }
    for (const station::ChainLink& link : station::kChain) {
      if (!follower.Heard(link.process))
        names += std::string(names.empty() ? "" : ", ") + link.process;
    }
    return names;
  };
  if (!Follow(node, wait, [&] { return missing().empty(); })) {
    if (!follower.Heard(station::kGantry[0])) {
      std::fprintf(stderr,
                   "vellum scan: no heartbeat within %.0f s from %s (is the station running on "
                   "%s?)\n",
                   wait, missing().c_str(), flags.Get("url").c_str());
      return 1;
    }
    std::fprintf(stderr, "vellum scan: not heard within %.0f s: %s; asking anyway\n", wait,
                 missing().c_str());
  }
  node.Publish(channel::kScanRequest, &request);
  if (isatty(2))
    std::fprintf(stderr, "scan %lld requested\n", static_cast<long long>(request.scan_id));
  const bool finished =
      Follow(node, timeout, [&] { return follower.restored() > 0 || !follower.failure().empty(); });
  follower.EndLine();
  if (!follower.failure().empty()) {
    std::fprintf(stderr, "vellum scan: scan %lld failed: %s\n",
                 static_cast<long long>(request.scan_id), follower.failure().c_str());
    return 1;
  }
  if (!finished) {
    std::fprintf(stderr,
                 "vellum scan: no restored page within %.0f s (are the daemons running on %s?)\n",
                 timeout, flags.Get("url").c_str());
    return 1;
  }
  return follower.warned() > 0 ? kExitDoubtful : 0;
}

int RunSheet(const std::vector<std::string>& args) {
  Flags flags("vellum sheet",
              "Writes DATA/index.html: a contact sheet of every scan in a station's data folder\n"
              "(newest first, earlier attempts of retaken folios after), each with its restored\n"
              "page, identity, quality verdict or failure, and links to its report and TIFF.\n"
              "The restorer writes it after each scan; this writes it now.",
              {{"data", "DIR", "the station's data folder", "scans"}});
  if (!flags.Parse(args)) return 0;
  const std::string data = flags.Get("data");
  if (!PathExists(data)) throw UsageError("--data " + data + ": no such folder");
  const std::vector<station::SheetEntry> entries = station::ReadSheet(data);
  const Status s = station::WriteContactSheet(data);
  if (!s.ok()) {
    std::fprintf(stderr, "vellum sheet: %s\n", s.message().c_str());
    return 1;
  }
  std::map<std::string, int> states;
  for (const station::SheetEntry& e : entries) ++states[e.retaken ? "retaken" : e.state];
  std::printf("%zu scan(s):", entries.size());
  for (const auto& [state, n] : states) std::printf(" %d %s", n, state.c_str());
  std::printf(" -> %s/index.html\n", data.c_str());
  return 0;
}

int RunWatch(const std::vector<std::string>& args) {
  std::vector<Flags::Spec> specs = BusSpecs();
  specs.push_back({"count", "N", "exit after this many restored scans (0: never)", "1"});
  specs.push_back({"timeout", "S", "give up after this long", "600"});
  specs.push_back({"play", "LOG",
                   "once every processing daemon's heartbeat is heard, play this recorded scan "
                   "log into the bus (lcm-logplayer) and follow it",
                   ""});
  Flags flags("vellum watch",
              "Follows the station's bus: daemon progress and errors, and each restored scan\n"
              "with its results folder. Exit status 1 on a daemon error or a timeout.",
              specs);
  if (!flags.Parse(args)) return 0;
  const int count = flags.GetInt("count", 0, 1 << 30);
  const double timeout = flags.GetDouble("timeout", 1, 1e9);
  Node node("vellum-watch", flags.Get("url"));
  station::SetStationFromFlags(flags, &node);
  Follower follower(&node, 0);
  pid_t player = -1;
  const std::string log = flags.Get("play");
  if (!log.empty()) {
    // The log plays only once the daemons listen (and this watcher does): no capture of it is
    // sent before the decoder is there to record it, however loaded the machine.
    const bool ready = Follow(node, std::min(timeout, 120.0), [&] {
      for (const station::ChainLink& link : station::kChain) {
        if (!follower.Heard(link.process)) return false;
      }
      return true;
    });
    if (!ready) {
      std::fprintf(stderr,
                   "vellum watch: the processing daemons did not answer within %.0f s "
                   "(are they running on %s?)\n",
                   std::min(timeout, 120.0), flags.Get("url").c_str());
      return 1;
    }
    const std::string url_arg = "--lcm-url=" + flags.Get("url");
    std::vector<char*> argv = {const_cast<char*>("lcm-logplayer"),
                               const_cast<char*>(url_arg.c_str()), const_cast<char*>(log.c_str()),
                               nullptr};
    posix_spawn_file_actions_t quiet;  // The player's chatter off this command's stdout.
    posix_spawn_file_actions_init(&quiet);
    posix_spawn_file_actions_addopen(&quiet, 1, "/dev/null", O_WRONLY, 0);
    const int spawned =
        posix_spawnp(&player, "lcm-logplayer", &quiet, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&quiet);
    if (spawned != 0) {
      std::fprintf(stderr, "vellum watch: cannot run lcm-logplayer (liblcm-bin)\n");
      return 1;
    }
  }
  const bool finished = Follow(node, timeout, [&] {
    return (count > 0 && follower.restored() >= count) || !follower.failure().empty();
  });
  follower.EndLine();
  if (player > 0) {
    int status = 0;
    if (waitpid(player, &status, WNOHANG) == 0) kill(player, SIGTERM);
    waitpid(player, &status, 0);
  }
  if (!follower.failure().empty()) return 1;
  if (!finished && count > 0) {
    std::fprintf(stderr, "vellum watch: %d of %d scans restored before the timeout\n",
                 follower.restored(), count);
    return 1;
  }
  return 0;
}

int RunCalibrateCapture(const std::vector<std::string>& args) {
  std::vector<Flags::Spec> specs = BusSpecs();
  specs.push_back({"out", "DIR", "where to write the pose's scan directory", ""});
  specs.push_back({"label", "TEXT", "a note for the scan", "calibration board"});
  specs.push_back({"timeout", "S", "give up after this long", "120"});
  Flags flags(
      "vellum calibrate capture",
      "Records one calibration board pose through the station: asks for a scan and\n"
      "writes its captures (texture and pattern frames, from the bus) as a scan\n"
      "directory of docs/formats.md in --out, for `vellum calibrate solve`. Hold the board\n"
      "still in the projector's light; one pose must lie flat on the table.",
      specs);
  if (!flags.Parse(args)) return 0;
  const std::string out = flags.Require("out");
  const double timeout = flags.GetDouble("timeout", 1, 86400);
  Node node("vellum-calibrate", flags.Get("url"));
  station::SetStationFromFlags(flags, &node);
  scan_request_t request{};
  request.scan_id = station::NowUtime();
  request.identity.label = flags.Get("label");
  station::CaptureSet set;
  std::string failure;
  node.Subscribe<capture_t>(station::channel::kCapture, [&](const capture_t& c) {
    if (c.scan_id != request.scan_id || set.Has(c.pattern_index)) return;
    const Status s = set.Add(c);
    if (!s.ok()) failure = s.message();
    if (isatty(2)) std::fprintf(stderr, "\rcapture %d of %d ", set.Received(), set.Expected());
  });
  // Only the gantry's errors fail a capture (the processing daemons may well fail on a board
  // held in the air: it is not a page on the table).
  for (const char* process : station::kGantry) {
    node.Subscribe<status_t>(station::StatusChannel(process), [&](const status_t& m) {
      if (m.last_error_scan_id == request.scan_id && !m.last_error.empty()) {
        failure = m.process + ": " + m.last_error;
      }
    });
  }
  node.Publish(station::channel::kScanRequest, &request);
  const bool complete = Follow(node, timeout, [&] { return set.Complete() || !failure.empty(); });
  if (isatty(2)) std::fputc('\n', stderr);
  if (!failure.empty() || !complete) {
    std::fprintf(stderr, "vellum calibrate capture: %s\n",
                 failure.empty()
                     ? ("incomplete after " + std::to_string(static_cast<int>(timeout)) +
                        " s: " + set.Missing())
                           .c_str()
                     : failure.c_str());
    return 1;
  }
  const Status s = WriteScan(out, set.ToScan());
  if (!s.ok()) {
    std::fprintf(stderr, "vellum calibrate capture: %s\n", s.message().c_str());
    return 1;
  }
  std::printf("pose recorded: %d captures -> %s\n", set.Received(), out.c_str());
  return 0;
}

int RunCalibrateLatency(const std::vector<std::string>& args) {
  std::vector<Flags::Spec> specs = BusSpecs();
  specs.push_back({"flashes", "N", "flashes, white and black in turn", "12"});
  specs.push_back({"timeout", "S", "give up after this long", "60"});
  Flags flags(
      "vellum calibrate latency",
      "Measures the display's lag: from the projector handing an image to its display (vsync\n"
      "passed) to the camera seeing it on the page. The projector flashes white and black;\n"
      "the camera says when each frame it took started and what it saw. Prints the lag in\n"
      "milliseconds and refreshes, with its spread. The projector waits it from now on\n"
      "(vellum-projector --measure-lag does this at start-up); on a station without a camera\n"
      "at start-up, put it in vellum-projector.yaml as display-lag-ms. Point the camera at\n"
      "the projector's light (the table, a white card) and fix its exposure.",
      specs);
  if (!flags.Parse(args)) return 0;
  const int flashes = flags.GetInt("flashes", 2, 100);
  const double timeout = flags.GetDouble("timeout", 1, 3600);
  Node node("vellum-calibrate", flags.Get("url"));
  station::SetStationFromFlags(flags, &node);
  std::set<std::string> heard;
  for (const char* process : {"vellum-projector", "vellum-camera"}) {
    node.Subscribe<status_t>(station::StatusChannel(process),
                             [&heard](const status_t& m) { heard.insert(m.process); });
  }
  if (!Follow(node, std::min(timeout, 10.0), [&] { return heard.size() == 2; })) {
    std::fprintf(stderr,
                 "vellum calibrate latency: no heartbeat from %s within 10 s: are they running "
                 "and on this bus?\n",
                 heard.count("vellum-projector") ? "vellum-camera" : "vellum-projector");
    return 1;
  }
  latency_request_t request{};
  request.session = station::NewSession();
  request.flashes = flashes;
  std::vector<FlashFrames> seen(static_cast<size_t>(flashes));
  int answered = 0;
  double refresh_hz = 0;
  std::string failure;
  node.Subscribe<latency_probe_t>(station::channel::kLatencyProbe, [&](const latency_probe_t& m) {
    if (m.session != request.session || m.index < 0 || m.index >= flashes) return;
    seen[m.index].handed_us = m.handed_utime;
    seen[m.index].white = m.white;
    refresh_hz = m.refresh_hz;
  });
  node.Subscribe<latency_seen_t>(station::channel::kLatencySeen, [&](const latency_seen_t& m) {
    if (m.session != request.session || m.index < 0 || m.index >= flashes) return;
    if (!m.error.empty()) failure = "the camera: " + m.error;
    FlashFrames& f = seen[m.index];
    f.exposure_us = m.exposure_us;
    f.start_us = m.start_utime;
    f.level.assign(m.level.begin(), m.level.end());
    ++answered;
  });
  node.Subscribe<status_t>(station::StatusChannel("vellum-projector"), [&](const status_t& m) {
    if (m.last_error.find("display lag") != std::string::npos &&
        m.last_error_utime >= request.utime) {
      failure = "vellum-projector: " + m.last_error;
    }
  });
  node.Publish(station::channel::kLatencyRequest, &request);
  if (!Follow(node, timeout, [&] { return answered == flashes || !failure.empty(); })) {
    std::fprintf(stderr, "vellum calibrate latency: %d of %d flashes answered within %d s\n",
                 answered, flashes, static_cast<int>(timeout));
    return 1;
  }
  if (!failure.empty()) {
    std::fprintf(stderr, "vellum calibrate latency: %s\n", failure.c_str());
    return 1;
  }
  const DisplayLag lag = EstimateDisplayLag(seen, refresh_hz);
  if (!lag.status.ok()) {
    std::fprintf(stderr, "vellum calibrate latency: %s\n", lag.status.message().c_str());
    return 1;
  }
  std::printf("%s\n", lag.Describe().c_str());
  std::printf("vellum-projector.yaml: display-lag-ms: %.1f (the projector waits it from now on)\n",
              lag.wait_ms);
  return 0;
}

int RunExport(const std::vector<std::string>& args) {
  std::vector<Flags::Spec> specs = {
      {"scan-id", "ID", "the scan to export when the log holds several", "0"}};
  Flags flags("vellum export LOG DIR",
              "Writes the scan recorded in an LCM log (CAPTURE, CALIBRATION) as a scan directory\n"
              "(scan.yaml, texture.png, frame_NNN.png, and calibration.yaml when the log has one).",
              specs);
  std::vector<std::string> positional, rest;
  SplitPositional(args, &positional, &rest);
  if (!flags.Parse(rest)) return 0;
  if (positional.size() != 2) throw UsageError("expected LOG DIR (see vellum export --help)");
  Scan scan;
  bool has_calibration = false;
  calibration_t calibration;
  int64_t id = 0;
  Status s = station::ReadScanLog(positional[0],
                                  static_cast<int64_t>(flags.GetDouble("scan-id", 0, 9.2e18)),
                                  &scan, &has_calibration, &calibration, &id);
  if (s.ok()) s = WriteScan(positional[1], scan);
  if (s.ok() && has_calibration) {
    Calibration c;
    s = station::FromMessage(calibration, &c);
    if (s.ok()) {
      s = WriteCalibration((std::filesystem::path(positional[1]) / "calibration.yaml").string(), c);
    }
  }
  if (!s.ok()) {
    std::fprintf(stderr, "vellum export: %s\n", s.message().c_str());
    return 1;
  }
  const std::string lights =
      scan.lights.empty() ? "" : ", " + std::to_string(scan.lights.size()) + " extra lights";
  std::printf("scan %lld: %zu frames%s%s -> %s\n", static_cast<long long>(id), scan.frames.size(),
              lights.c_str(), has_calibration ? " and calibration.yaml" : "",
              positional[1].c_str());
  return 0;
}

int RunImport(const std::vector<std::string>& args) {
  std::vector<Flags::Spec> specs = {
      {"scan-id", "ID", "scan id of the log's messages (0: the current time)", "0"},
      station::StationSpec(),
      {"calibration", "FILE", "calibration to include (default: DIR/calibration.yaml if any)", ""}};
  Flags flags("vellum import DIR LOG",
              "Writes a scan directory as an LCM log as station --station records it:\n"
              "SCAN_STARTED, CALIBRATION, then the texture, every frame and the image under\n"
              "each extra light on CAPTURE.\n"
              "lcm-logplayer of it drives the station's decoder and processing daemons (a scan id\n"
              "the station has recorded before is refused: give each playback its own).",
              specs);
  std::vector<std::string> positional, rest;
  SplitPositional(args, &positional, &rest);
  if (!flags.Parse(rest)) return 0;
  if (positional.size() != 2) throw UsageError("expected DIR LOG (see vellum import --help)");
  Scan scan;
  Status s = ReadScan(positional[0], &scan);
  calibration_t calibration{};
  bool has_calibration = false;
  std::string calib_path = flags.Get("calibration");
  const std::string beside = (std::filesystem::path(positional[0]) / "calibration.yaml").string();
  if (calib_path.empty() && std::filesystem::exists(beside)) calib_path = beside;
  if (s.ok() && !calib_path.empty()) {
    Calibration c;
    s = ReadCalibration(calib_path, &c);
    station::ToMessage(c, &calibration);
    calibration.source = calib_path;
    has_calibration = true;
  }
  int64_t id = static_cast<int64_t>(flags.GetDouble("scan-id", 0, 9.2e18));
  if (id <= 0) id = station::NowUtime();
  const std::string station_id = flags.Get("station");
  const std::string bad_station = station::CheckStationId(station_id);
  if (!bad_station.empty()) throw UsageError("--station: " + bad_station);
  if (s.ok()) {
    s = station::WriteScanLog(positional[1], scan, id, station_id,
                              has_calibration ? &calibration : nullptr);
  }
  if (!s.ok()) {
    std::fprintf(stderr, "vellum import: %s\n", s.message().c_str());
    return 1;
  }
  std::printf("scan %lld: %zu frames%s -> %s\n", static_cast<long long>(id), scan.frames.size(),
              has_calibration ? " and the calibration" : "", positional[1].c_str());
  return 0;
}

}  // namespace vellum
