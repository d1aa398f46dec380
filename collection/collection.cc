#include "collection/collection.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>

#include "flags/options.h"
#include "io/calibration_io.h"
#include "io/manifest.h"
#include "io/scan_io.h"
#include "io/version.h"
#include "io/write_whole.h"
#include "pipeline/process.h"

namespace vellum::collection {
namespace fs = std::filesystem;
namespace {

constexpr char kNewPrefix[] = ".vellum-new-";

// The raw files that are not captures: the calibration (planned on its own), the station's
// recorded hashes and the reason a scan was given up.
bool IsCapture(const std::string& rel) {
  return rel.rfind("raw/", 0) == 0 && rel != "raw/calibration.yaml" &&
         rel != std::string("raw/") + kRecordedHashesName &&
         rel != std::string("raw/") + kGivenUpName;
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// The manifest's lines by path ("<hex>" for "raw/frame_000.png"); empty without one.
std::map<std::string, std::string> ManifestLines(const std::string& scan_dir) {
  std::map<std::string, std::string> lines;
  std::ifstream in(scan_dir + "/" + kManifestName);
  std::string line;
  while (std::getline(in, line)) {
    if (line.size() > 66 && line[64] == ' ' && line[65] == ' ') {
      lines[line.substr(66)] = line.substr(0, 64);
    }
  }
  return lines;
}

std::string LedgerFile(const std::string& root, const std::string& folder) {
  return root + "/" + kLedgerFolder + "/scans/" + folder + ".json";
}

std::string HostName() {
  char buf[256] = {};
  gethostname(buf, sizeof(buf) - 1);
  return buf;
}

Status WriteLedger(const std::string& root, const std::string& folder, const LedgerEntry& e) {
  std::error_code ec;
  fs::create_directories(fs::path(LedgerFile(root, folder)).parent_path(), ec);
  Json j;
  j["folder"] = folder;
  j["runs"] = e.runs;
  j["failures"] = e.failures;
  j["state"] = e.state;
  j["message"] = e.message;
  j["want"] = e.want;
  j["job"] = e.job;
  j["host"] = e.host;
  j["finished"] = e.finished;
  return WriteJsonFile(LedgerFile(root, folder), j);
}

// Notes a scan's run in the ledger: `outcome` ok (processed and swapped in as its `runs`th time:
// its counter goes up) or its failure.
Status Record(const std::string& root, const std::string& folder, const RunSettings& run,
              const std::string& want, const Status& outcome, int runs = 0) {
  LedgerEntry ledger;
  static_cast<void>(ReadLedger(root, folder, &ledger));  // None yet: a new entry.
  ledger.job = run.job;
  ledger.host = HostName();
  ledger.want = want;
  ledger.finished = LedgerTime();
  if (outcome.ok()) {
    ledger.runs = std::max(ledger.runs + 1, runs);
    ledger.state = "done";
    ledger.message.clear();
  } else {
    ++ledger.failures;
    ledger.state = "failed";
    ledger.message = outcome.message();
  }
  return WriteLedger(root, folder, ledger);
}

// A scan's lock (flock on vellum-collection/locks/<folder>.lock): held while it is processed,
// by whichever process (a local worker, a Slurm task); the kernel lets it go when the holder
// dies, so a killed run never blocks the next.
class ScanLock {
 public:
  ScanLock(const std::string& root, const std::string& folder) {
    const fs::path dir = fs::path(root) / kLedgerFolder / "locks";
    std::error_code ec;
    fs::create_directories(dir, ec);
    fd_ = open((dir / (folder + ".lock")).c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd_ >= 0 && flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      close(fd_);
      fd_ = -1;
    }
  }
  ~ScanLock() {
    if (fd_ >= 0) close(fd_);  // Closing lets the lock go.
  }
  ScanLock(const ScanLock&) = delete;
  ScanLock& operator=(const ScanLock&) = delete;
  bool held() const { return fd_ >= 0; }

 private:
  int fd_ = -1;
};

// Whether some process holds the scan's lock now.
bool Locked(const std::string& root, const std::string& folder) {
  const fs::path file = fs::path(root) / kLedgerFolder / "locks" / (folder + ".lock");
  const int fd = open(file.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  const bool locked = flock(fd, LOCK_EX | LOCK_NB) != 0 && errno == EWOULDBLOCK;
  close(fd);
  return locked;
}

// The SHA-256 of each file the processing flags name (their value name is FILE), by flag. Read
// once a process for each file as it is now (its size and time): a plan of thousands of scans
// hashes a flat field once.
Status FilesOf(const std::map<std::string, std::string>& options,
               std::map<std::string, std::string>* files) {
  static std::mutex mutex;
  static std::map<std::string, std::pair<std::string, std::string>> hashed;  // path: (stamp, hex)
  files->clear();
  for (const Flags::Spec& spec : PipelineFlagSpecs()) {
    const auto it = options.find(spec.name);
    if (spec.value_name != "FILE" || it == options.end() || it->second.empty()) continue;
    const std::string& path = it->second;
    std::error_code ec;
    const auto size = fs::file_size(path, ec);
    const auto time = ec ? fs::file_time_type() : fs::last_write_time(path, ec);
    if (ec) {
      return Status::Error("--" + spec.name + " " + path + ": cannot read (" + ec.message() + ")");
    }
    const std::string stamp =
        std::to_string(size) + "@" + std::to_string(time.time_since_epoch().count());
    std::lock_guard<std::mutex> lock(mutex);
    auto& [was, hex] = hashed[path];
    if (was != stamp || hex.empty()) {
      const Status s = Sha256OfFile(path, &hex);
      if (!s.ok()) return Status::Error("--" + spec.name + ": " + s.message());
      was = stamp;
    }
    (*files)[spec.name] = hex;
  }
  return Status::Ok();
}

// The want of one scan: what processing it now would make its products from.
Status Want(const std::string& scan_dir, const std::map<std::string, std::string>& options,
            bool verify, Provenance* want) {
  want->vellum_version = VellumVersion();
  want->options = options;
  Status s = FilesOf(options, &want->files);
  if (!s.ok()) return s;
  Calibration calibration;
  s = ReadCalibration(scan_dir + "/raw/calibration.yaml", &calibration);
  if (!s.ok()) return s;
  want->calibration_sha256 = CalibrationSha256(calibration);
  return RawDigest(scan_dir, verify, &want->raw_sha256);
}

std::string WantDigest(const Provenance& want) {
  return Sha256OfBytes(ProvenanceJson(want).dump());
}

int64_t RawBytes(const fs::path& raw) {
  int64_t bytes = 0;
  std::error_code ec;
  for (fs::recursive_directory_iterator it(raw, ec), end; !ec && it != end; it.increment(ec)) {
    if (it->is_regular_file(ec)) bytes += static_cast<int64_t>(it->file_size(ec));
  }
  return bytes;
}

// One scan folder's state against `options`.
// `locked_here`: this process holds the scan's lock (it is not running elsewhere).
PlannedScan PlanFolder(const std::string& root, const std::string& folder,
                       const std::map<std::string, std::string>& options, bool verify,
                       bool locked_here = false) {
  PlannedScan p;
  p.folder = folder;
  const fs::path dir = fs::path(root) / folder;
  std::error_code ec;
  LedgerEntry ledger;
  if (ReadLedger(root, folder, &ledger).ok()) p.runs = ledger.runs;
  p.raw_bytes = RawBytes(dir / "raw");
  if (std::string why; ReadGivenUp((dir / "raw").string(), &why)) {
    p.state = State::kParked;
    p.reasons.push_back("given up at the station: " + why);
    return p;
  }
  if (fs::exists(dir / "pending", ec) || !fs::exists(dir / "raw" / "scan.yaml", ec)) {
    p.state = State::kAtStation;
    p.reasons.push_back(fs::exists(dir / "pending", ec) ? "still on its way through the station"
                                                        : "not recorded whole (no raw/scan.yaml)");
    return p;
  }
  if (!locked_here && Locked(root, folder)) {
    p.state = State::kRunning;
    return p;
  }
  Provenance want;
  const Status s = Want(dir.string(), options, verify, &want);
  if (!s.ok()) {
    p.state = State::kFailed;
    p.reasons.push_back(s.message());
    return p;
  }
  if (ledger.state == "failed" && ledger.want == WantDigest(want)) {
    p.state = State::kFailed;
    p.reasons.push_back(ledger.message);
    return p;
  }
  const fs::path made_file = dir / "results" / kProvenanceName;
  if (!fs::exists(dir / "results" / "report.json", ec)) {
    p.reasons.push_back("never processed (no results/report.json)");
  } else if (!fs::exists(made_file, ec)) {
    p.reasons.push_back("no results/provenance.json: made at the station or by `vellum process`");
  } else {
    Provenance made;
    const Status read = ReadProvenance(made_file.string(), &made);
    if (!read.ok()) {
      p.reasons.push_back(read.message());
    } else {
      p.reasons = StaleReasons(made, want);
      p.runs = std::max(p.runs, made.run);
    }
  }
  p.state = p.reasons.empty() ? State::kDone : State::kStale;
  return p;
}

// Makes `to` hold what `from` holds but results/ and the manifest: folders made again, files
// hard-linked (copied where the filesystem cannot link).
Status LinkScan(const fs::path& from, const fs::path& to) {
  std::error_code ec;
  fs::create_directories(to, ec);
  if (ec) return Status::Error(to.string() + ": cannot make (" + ec.message() + ")");
  for (fs::recursive_directory_iterator it(from, ec), end; !ec && it != end; it.increment(ec)) {
    const fs::path rel = fs::relative(it->path(), from);
    const std::string top = rel.begin()->string();
    if (top == "results" || rel == kManifestName) {
      if (it->is_directory(ec)) it.disable_recursion_pending();
      continue;
    }
    const fs::path target = to / rel;
    if (it->is_directory(ec)) {
      fs::create_directories(target, ec);
    } else if (it->is_regular_file(ec)) {
      fs::create_hard_link(it->path(), target, ec);
      if (ec) {
        ec.clear();
        fs::copy_file(it->path(), target, ec);
      }
    }
    if (ec) return Status::Error(target.string() + ": " + ec.message());
  }
  if (ec) return Status::Error(from.string() + ": cannot read (" + ec.message() + ")");
  return Status::Ok();
}

// Makes the scan's new folder at `fresh`: its raw files, results made from them, the
// provenance and the manifest.
Status MakeNew(const fs::path& dir, const fs::path& fresh, const RunSettings& run,
               const Provenance& want) {
  Status s = LinkScan(dir, fresh);
  if (!s.ok()) return s;
  // Read from the scan's own raw/ (the same files): the report names the scan's folder.
  ProcessInput input;
  const std::string raw = (dir / "raw").string();
  s = ReadProcessInput(raw, raw + "/calibration.yaml", &input);
  if (!s.ok()) return s;
  const PipelineOptions options = PipelineOptionsOf(run.options);
  const ProcessResult result = RunPipeline(input, options, (fresh / "results").string());
  if (!result.status.ok()) return result.status;
  s = WriteJsonFile((fresh / "results" / kProvenanceName).string(), ProvenanceJson(want));
  if (!s.ok()) return s;
  return WriteManifest(fresh.string(), {"raw", "results"});
}

}  // namespace

Json ProvenanceJson(const Provenance& p) {
  Json j;
  j["vellum_version"] = p.vellum_version;
  j["raw_sha256"] = p.raw_sha256;
  j["calibration_sha256"] = p.calibration_sha256;
  Json options = Json::object();
  for (const auto& [name, value] : p.options) options[name] = value;
  j["options"] = options;
  Json files = Json::object();
  for (const auto& [name, hex] : p.files) files[name] = hex;
  j["files"] = files;
  if (p.run > 0) j["run"] = p.run;
  return j;
}

Status ReadProvenance(const std::string& file, Provenance* p) {
  try {
    const Json j = Json::parse(ReadText(file));
    p->vellum_version = j.at("vellum_version").get<std::string>();
    p->raw_sha256 = j.at("raw_sha256").get<std::string>();
    p->calibration_sha256 = j.at("calibration_sha256").get<std::string>();
    p->options.clear();
    for (const auto& [name, value] : j.at("options").items()) {
      p->options[name] = value.get<std::string>();
    }
    p->files.clear();
    if (j.contains("files")) {
      for (const auto& [name, hex] : j.at("files").items()) p->files[name] = hex.get<std::string>();
    }
    p->run = j.value("run", 0);
  } catch (const std::exception& e) {
    return Status::Error(file + ": not a provenance file (" + e.what() + ")");
  }
  return Status::Ok();
}

std::vector<std::string> StaleReasons(const Provenance& made, const Provenance& want) {
  std::vector<std::string> why;
  if (made.raw_sha256 != want.raw_sha256) why.push_back("raw captures changed");
  if (made.calibration_sha256 != want.calibration_sha256) {
    why.push_back("calibration changed: " + made.calibration_sha256.substr(0, 12) + " -> " +
                  want.calibration_sha256.substr(0, 12));
  }
  if (made.vellum_version != want.vellum_version) {
    why.push_back("vellum changed: " + made.vellum_version + " -> " + want.vellum_version);
  }
  std::map<std::string, std::string> names = made.options;
  names.insert(want.options.begin(), want.options.end());
  for (const auto& [name, ignored] : names) {
    const auto was = made.options.find(name), now = want.options.find(name);
    const std::string a = was == made.options.end() ? "(none)" : was->second;
    const std::string b = now == want.options.end() ? "(none)" : now->second;
    if (a != b) why.push_back("option --" + name + " changed: " + a + " -> " + b);
  }
  // A file changed under the same name (a new name is an option's change, said above).
  for (const auto& [name, hex] : want.files) {
    const auto was = made.files.find(name);
    const auto named = made.options.find(name), naming = want.options.find(name);
    const bool same_name = named != made.options.end() && naming != want.options.end() &&
                           named->second == naming->second;
    if (same_name && (was == made.files.end() || was->second != hex)) {
      const std::string a = was == made.files.end() ? "(none)" : was->second.substr(0, 12);
      why.push_back("file of --" + name + " changed: " + a + " -> " + hex.substr(0, 12));
    }
  }
  return why;
}

Status RawDigest(const std::string& scan_dir, bool verify, std::string* digest) {
  const std::map<std::string, std::string> listed = ManifestLines(scan_dir);
  std::map<std::string, std::string> hashes;
  bool from_manifest = !verify;
  if (from_manifest) {
    for (const auto& [rel, hex] : listed) {
      if (IsCapture(rel)) hashes[rel] = hex;
    }
    from_manifest = !hashes.empty();
  }
  if (!from_manifest) {
    hashes.clear();
    const fs::path dir(scan_dir);
    std::error_code ec;
    for (fs::recursive_directory_iterator it(dir / "raw", ec), end; !ec && it != end;
         it.increment(ec)) {
      if (!it->is_regular_file(ec)) continue;
      const std::string rel = fs::relative(it->path(), dir).generic_string();
      if (!IsCapture(rel)) continue;
      std::string hex;
      const Status s = Sha256OfFile(it->path().string(), &hex);
      if (!s.ok()) return s;
      const auto line = listed.find(rel);
      if (line != listed.end() && line->second != hex) {
        return Status::Error(scan_dir + "/" + rel +
                             ": does not match the scan's manifest (changed or damaged since; "
                             "`vellum manifest check` names every such file)");
      }
      hashes[rel] = hex;
    }
    if (ec) return Status::Error(scan_dir + "/raw: cannot read (" + ec.message() + ")");
  }
  if (hashes.empty()) return Status::Error(scan_dir + "/raw: holds no captures");
  std::string lines;
  for (const auto& [rel, hex] : hashes) lines += hex + "  " + rel + "\n";
  *digest = Sha256OfBytes(lines);
  return Status::Ok();
}

std::map<std::string, std::string> OptionsOf(const Flags& flags) {
  std::map<std::string, std::string> options;
  for (const Flags::Spec& spec : PipelineFlagSpecs()) {
    if (spec.name != "config") options[spec.name] = flags.Get(spec.name);
  }
  return options;
}

PipelineOptions PipelineOptionsOf(const std::map<std::string, std::string>& options) {
  std::vector<std::string> args;
  for (const auto& [name, value] : options) args.push_back("--" + name + "=" + value);
  Flags flags("vellum collection", "", PipelineFlagSpecs());
  flags.Parse(args);
  return PipelineOptionsFromFlags(flags);
}

const char* StateName(State s) {
  switch (s) {
    case State::kDone:
      return "done";
    case State::kStale:
      return "stale";
    case State::kRunning:
      return "running";
    case State::kFailed:
      return "failed";
    case State::kParked:
      return "parked";
    case State::kAtStation:
      return "at the station";
  }
  return "?";
}

Status Plan(const std::string& root, const std::map<std::string, std::string>& options, bool verify,
            std::vector<PlannedScan>* plan) {
  std::error_code ec;
  if (!fs::is_directory(root, ec)) return Status::Error(root + ": not a folder");
  std::vector<std::string> folders;
  for (fs::directory_iterator it(root, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.rfind("scan-", 0) == 0 && it->is_directory(ec)) folders.push_back(name);
  }
  if (ec) return Status::Error(root + ": cannot read (" + ec.message() + ")");
  std::sort(folders.begin(), folders.end());
  plan->clear();
  for (const std::string& folder : folders) {
    plan->push_back(PlanFolder(root, folder, options, verify));
  }
  return Status::Ok();
}

PlannedScan PlanScan(const std::string& root, const std::string& folder,
                     const std::map<std::string, std::string>& options, bool verify) {
  return PlanFolder(root, folder, options, verify);
}

Status ReadLedger(const std::string& root, const std::string& folder, LedgerEntry* e) {
  const std::string file = LedgerFile(root, folder);
  std::error_code ec;
  if (!fs::exists(file, ec)) return Status::Error(file + ": no entry");
  try {
    const Json j = Json::parse(ReadText(file));
    e->runs = j.value("runs", 0);
    e->failures = j.value("failures", 0);
    e->state = j.value("state", "");
    e->message = j.value("message", "");
    e->want = j.value("want", "");
    e->job = j.value("job", "");
    e->host = j.value("host", "");
    e->finished = j.value("finished", "");
  } catch (const std::exception& ex) {
    return Status::Error(file + ": unreadable (" + ex.what() + ")");
  }
  return Status::Ok();
}

std::string LedgerTime() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof(buf), "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

bool NotedSince(const std::string& root, const std::string& folder, const std::string& since,
                LedgerEntry* entry) {
  return ReadLedger(root, folder, entry).ok() && !entry->state.empty() && entry->finished >= since;
}

Status ProcessScan(const std::string& root, const std::string& folder, const RunSettings& run,
                   std::string* what) {
  const ScanLock lock(root, folder);
  if (!lock.held()) {
    *what = "running elsewhere";
    return Status::Ok();
  }
  const std::map<std::string, std::string>& options = run.options;
  // Planned again under the lock: another run may have processed it since this one planned.
  const PlannedScan planned = PlanFolder(root, folder, options, false, /*locked_here=*/true);
  const bool retry = planned.state == State::kFailed && run.retry_failed;
  if (planned.state != State::kStale && !retry) {
    *what = StateName(planned.state);
    return Status::Ok();
  }
  const fs::path dir = fs::path(root) / folder;
  const fs::path fresh = fs::path(root) / (kNewPrefix + folder);
  std::error_code ec;
  fs::remove_all(fresh, ec);  // A killed run's.
  // What the plan compares a failure with (the captures' checksums from the manifest), and what
  // the products are made from (the captures hashed again: what is processed).
  Provenance planned_want, want;
  static_cast<void>(Want(dir.string(), options, false, &planned_want));
  const std::string want_digest = WantDigest(planned_want);
  Status s = Want(dir.string(), options, true, &want);
  want.run = planned.runs + 1;
  if (s.ok()) s = MakeNew(dir, fresh, run, want);
  if (s.ok()) s = ReplaceFolder(fresh.string(), dir.string());
  fs::remove_all(fresh, ec);
  *what = s.ok() ? "processed" : "failed: " + s.message();
  const Status noted = Record(root, folder, run, want_digest, s, want.run);
  if (!s.ok()) return s;
  return noted;
}

Status RecordFailure(const std::string& root, const std::string& folder, const RunSettings& run,
                     const std::string& message) {
  Provenance want;
  static_cast<void>(Want((fs::path(root) / folder).string(), run.options, false, &want));
  return Record(root, folder, run, WantDigest(want), Status::Error(message));
}

void CleanUp(const std::string& root) {
  std::error_code ec;
  std::vector<fs::path> leftovers;
  for (fs::directory_iterator it(root, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    for (const std::string& prefix : {std::string(kNewPrefix), std::string(".old-")}) {
      if (name.rfind(prefix, 0) == 0 && name.size() > prefix.size()) {
        const std::string folder = name.substr(prefix.size());
        if (folder.rfind("scan-", 0) == 0 && !Locked(root, folder)) leftovers.push_back(it->path());
      }
    }
  }
  for (const fs::path& p : leftovers) {
    const std::string name = p.filename().string();
    if (name.rfind(".old-", 0) == 0) {
      const fs::path scan = p.parent_path() / name.substr(5);
      // A fallback swap killed between its two renames: the old scan goes back whole.
      if (!fs::exists(scan, ec)) {
        fs::rename(p, scan, ec);
        continue;
      }
    }
    fs::remove_all(p, ec);
  }
}

}  // namespace vellum::collection
