// `vellum collection` as a library runs it over a folder of station scans (the virtual gantry's
// leaves of several seeds, and the recorded demo scan exported from its log): the plan says why
// each scan is stale, from provenance; a run processes exactly those, each swapped in whole with
// its manifest; a second run finds nothing left; a failed scan does not stop the others; a run
// killed at any moment leaves every scan wholly old or wholly new.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/file.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "io/xmp.h"
#include "tests/icc_profile.h"
#include "tests/shell.h"

namespace vellum {
namespace {
namespace fs = std::filesystem;

const std::string kBin = VELLUM_BIN;
const std::string kRig = std::string(VELLUM_SOURCE_DIR) + "/config/small_rig.yaml";

ShellResult Vellum(const std::string& args) { return Shell(kBin + " " + args); }

std::string Text(const fs::path& file) {
  std::ifstream in(file);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

nlohmann::json JsonOf(const fs::path& file) { return nlohmann::json::parse(Text(file)); }

// The lines of `text` that start with `prefix`.
std::vector<std::string> LinesStarting(const std::string& text, const std::string& prefix) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    if (line.rfind(prefix, 0) == 0) lines.push_back(line);
  }
  return lines;
}

class CollectionTest : public ::testing::Test {
 protected:
  // Four leaves of the virtual gantry (seeds 1 to 4, each a different curl and page), rendered
  // once as a station records them (scan-<id>/raw with its calibration), and the demo scan
  // exported from its recorded log.
  static void SetUpTestSuite() {
    pristine_ = fs::temp_directory_path() / ("vellum_collection_test_" + std::to_string(getpid()));
    fs::remove_all(pristine_);
    for (int i = 1; i <= 4; ++i) {
      const fs::path raw = pristine_ / ("scan-100" + std::to_string(i)) / "raw";
      const ShellResult r = Vellum("render --out " + raw.string() + " --calibration " + kRig +
                                   " --seed " + std::to_string(i) + " --truth false");
      ASSERT_EQ(r.exit_code, 0) << r.output;
      ASSERT_TRUE(fs::exists(raw / "calibration.yaml"));  // The rig's, pinned with the scan.
    }
    const fs::path demo = pristine_ / "scan-2000-demo" / "raw";
    const ShellResult r = Vellum("export " + std::string(VELLUM_LOG) + " " + demo.string());
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  static void TearDownTestSuite() { fs::remove_all(pristine_); }

  void SetUp() override {
    root_ =
        pristine_.string() + "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name();
    fs::remove_all(root_);
    fs::copy(pristine_, root_, fs::copy_options::recursive);
  }
  void TearDown() override { fs::remove_all(root_); }

  ShellResult Collection(const std::string& what, const std::string& flags = "") {
    return Vellum("collection " + what + " --root " + root_.string() + " " + flags);
  }
  // Every scan folder's manifest checks (raw/ and results/ whole and unchanged).
  void ExpectManifestsCheck() {
    for (const auto& entry : fs::directory_iterator(root_)) {
      const std::string name = entry.path().filename().string();
      if (name.rfind("scan-", 0) != 0 || !fs::exists(entry.path() / "results")) continue;
      const ShellResult r = Vellum("manifest check " + entry.path().string());
      EXPECT_EQ(r.exit_code, 0) << name << ": " << r.output;
    }
  }
  // The ledger's counter of the scan (0 before its first run).
  int Runs(const std::string& folder) {
    const fs::path file = root_ / "vellum-collection" / "scans" / (folder + ".json");
    return fs::exists(file) ? JsonOf(file)["runs"].get<int>() : 0;
  }
  // Each scan's runs as `vellum collection status --all` says them.
  std::map<std::string, int> RunsByStatus() {
    std::map<std::string, int> runs;
    const ShellResult r = Collection("status", "--all");
    for (const std::string& line : LinesStarting(r.output, "scan-")) {
      const size_t space = line.find(' '), at = line.rfind("  runs ");
      if (space == std::string::npos || at == std::string::npos) continue;  // A failure's line.
      runs[line.substr(0, space)] = std::stoi(line.substr(at + 7));
    }
    return runs;
  }
  // Whether any process holds a scan's lock (a worker still at work).
  bool AnyScanLocked() {
    const fs::path locks = root_ / "vellum-collection" / "locks";
    if (!fs::exists(locks)) return false;
    for (const auto& entry : fs::directory_iterator(locks)) {
      const int fd = open(entry.path().c_str(), O_RDONLY | O_CLOEXEC);
      if (fd < 0) continue;
      const bool held = flock(fd, LOCK_EX | LOCK_NB) != 0;
      close(fd);
      if (held) return true;
    }
    return false;
  }

  static fs::path pristine_;
  fs::path root_;
};
fs::path CollectionTest::pristine_;

// The plan names each state and why; a run processes exactly the stale scans (the parked one and
// the one still at the station left alone), each manifest then checks, and a second run finds
// nothing to do: every scan processed once.
TEST_F(CollectionTest, ARunProcessesWhatThePlanSaysOnceAndASecondRunNothing) {
  // One scan made by `vellum process` as the station's results are (no collection provenance),
  // one given up at the station, one still on its way through it.
  const fs::path made = root_ / "scan-1001";
  ShellResult r =
      Vellum("process --scan " + (made / "raw").string() + " --calibration " +
             (made / "raw/calibration.yaml").string() + " --out " + (made / "results").string());
  ASSERT_TRUE(r.exit_code == 0 || r.exit_code == 3) << r.output;
  ASSERT_EQ(Vellum("manifest write " + made.string()).exit_code, 0);
  std::ofstream(root_ / "scan-1003" / "raw" / "failed.txt") << "captures stopped at frame 12\n";
  std::ofstream(root_ / "scan-1004" / "pending") << "decoded\n";

  r = Collection("plan");
  EXPECT_EQ(r.exit_code, 4) << r.output;  // Work left.
  EXPECT_NE(r.output.find("scan-1001: stale: no results/provenance.json"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("scan-1002: stale: never processed"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("scan-2000-demo: stale: never processed"), std::string::npos);
  EXPECT_NE(r.output.find("scan-1003: parked: given up at the station: captures stopped"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("scan-1004: at the station"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("5 scan(s): 0 done, 3 stale, 0 running, 0 failed, 1 parked, 1 at the"),
            std::string::npos)
      << r.output;

  r = Collection("run", "--iiif-base http://127.0.0.1:8080");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("3 scan(s) to process"), std::string::npos) << r.output;
  ExpectManifestsCheck();
  for (const char* folder : {"scan-1001", "scan-1002", "scan-2000-demo"}) {
    EXPECT_EQ(Runs(folder), 1) << folder;
    const nlohmann::json p = JsonOf(root_ / folder / "results" / "provenance.json");
    EXPECT_EQ(p["raw_sha256"].get<std::string>().size(), 64u) << folder;
    EXPECT_EQ(p["options"]["dpi"], "0") << folder;
  }
  EXPECT_FALSE(fs::exists(root_ / "scan-1003" / "results"));
  EXPECT_FALSE(fs::exists(root_ / "scan-1004" / "results"));
  EXPECT_TRUE(fs::exists(root_ / "index.html"));  // The contact sheet, rebuilt.
  const nlohmann::json iiif = JsonOf(root_ / "iiif-manifest.json");
  EXPECT_EQ(iiif["items"].size(), 3u);  // One page each.

  r = Collection("run");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("0 scan(s) to process"), std::string::npos) << r.output;
  r = Collection("status", "--verify --all");  // The captures hashed again: still done.
  EXPECT_NE(r.output.find("3 done, 0 stale"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("3 scan(s) 1 time(s)"), std::string::npos) << r.output;
  for (const char* folder : {"scan-1001", "scan-1002", "scan-2000-demo"})
    EXPECT_EQ(Runs(folder), 1);

  // A capture changed behind the manifest's back: --verify names it; the scan is not processed
  // from it.
  {
    std::fstream frame(root_ / "scan-1002" / "raw" / "frame_004.png",
                       std::ios::in | std::ios::out | std::ios::binary);
    frame.seekp(200);
    frame.put('\x5a');
  }
  r = Collection("plan", "--verify");
  EXPECT_NE(r.output.find("scan-1002: failed: " + (root_ / "scan-1002").string() +
                          "/raw/frame_004.png: does not match the scan's manifest"),
            std::string::npos)
      << r.output;
}

// A refined calibration for half the scans: exactly those are planned stale, for that reason
// alone; new options make every scan stale, naming the option.
TEST_F(CollectionTest, ANewCalibrationMakesExactlyItsScansStaleWithTheReason) {
  ShellResult r = Collection("run");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* folder : {"scan-1001", "scan-1003"}) {
    const fs::path file = root_ / folder / "raw" / "calibration.yaml";
    std::string text = Text(file);
    size_t at = text.find("data: [ 960., 0.,");  // The focal length, refined by 0.1%.
    ASSERT_NE(at, std::string::npos) << text;
    at += 8;
    text.replace(at, 4, "961.");
    std::ofstream(file) << text;
  }
  r = Collection("plan");
  EXPECT_EQ(r.exit_code, 4);
  const std::vector<std::string> stale = LinesStarting(r.output, "scan-");
  ASSERT_EQ(stale.size(), 2u) << r.output;
  EXPECT_EQ(stale[0].rfind("scan-1001: stale: calibration changed: ", 0), 0u) << stale[0];
  EXPECT_EQ(stale[1].rfind("scan-1003: stale: calibration changed: ", 0), 0u) << stale[1];
  for (const std::string& line : stale) EXPECT_EQ(line.find(';'), std::string::npos) << line;

  r = Collection("plan", "--dpi 200");
  EXPECT_EQ(LinesStarting(r.output, "scan-").size(), 5u) << r.output;
  EXPECT_NE(r.output.find("scan-1002: stale: option --dpi changed: 0 -> 200"), std::string::npos)
      << r.output;

  r = Collection("run");  // The two, again.
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("2 scan(s) to process"), std::string::npos) << r.output;
  EXPECT_EQ(Runs("scan-1001"), 2);
  EXPECT_EQ(Runs("scan-1002"), 1);
  ExpectManifestsCheck();
}

// A file a processing flag names is part of what the products were made from: the camera's
// profile (embedded in the masters) refined under the same name makes every scan stale, with the
// reason, and the next run embeds the new one.
TEST_F(CollectionTest, AProfileRefinedUnderTheSameNameMakesEveryScanStale) {
  fs::remove_all(root_ / "scan-2000-demo");  // A colour scan: the gantry's leaves are gray.
  const fs::path icc = root_.string() + "_camera.icc";
  WriteCameraProfile(icc, false, "Gantry camera 7, gray, gamma 2.2");
  const std::string flag = "--camera-icc " + icc.string();
  ShellResult r = Collection("run", flag);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  r = Collection("plan", flag);
  EXPECT_EQ(r.exit_code, 0) << r.output;

  WriteCameraProfile(icc, false, "Gantry camera 7, gray, gamma 2.2, refined");
  r = Collection("plan", flag);
  EXPECT_EQ(r.exit_code, 4) << r.output;
  const std::vector<std::string> stale = LinesStarting(r.output, "scan-");
  EXPECT_EQ(stale.size(), 4u) << r.output;
  for (const std::string& line : stale) {
    EXPECT_NE(line.find(": stale: file of --camera-icc changed: "), std::string::npos) << line;
    EXPECT_EQ(line.find(';'), std::string::npos) << line;  // That reason alone.
  }
  r = Collection("run", flag);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("4 scan(s) to process"), std::string::npos) << r.output;
  std::string embedded;
  ASSERT_TRUE(ReadIccProfile((root_ / "scan-1002/results/restored.tif").string(), &embedded).ok());
  EXPECT_EQ(embedded, Text(icc));
  EXPECT_EQ(Collection("plan", flag).exit_code, 0);
  ExpectManifestsCheck();
  fs::remove(icc);
}

// A scan that cannot be processed is recorded with its message; the others are done; a second
// run leaves it (it would fail the same way) unless asked to try again.
TEST_F(CollectionTest, AFailedScanIsRecordedAndDoesNotStopTheOthers) {
  fs::remove(root_ / "scan-1002" / "raw" / "frame_007.png");
  ShellResult r = Collection("run");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("scan-1002: failed: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("frame_007.png"), std::string::npos) << r.output;
  r = Collection("status");
  EXPECT_EQ(r.exit_code, 4) << r.output;
  EXPECT_NE(r.output.find("4 done, 0 stale, 0 running, 1 failed"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("scan-1002: failed: "), std::string::npos) << r.output;
  r = Collection("run");
  EXPECT_NE(r.output.find("0 scan(s) to process"), std::string::npos) << r.output;
  r = Collection("run", "--retry-failed");
  EXPECT_NE(r.output.find("1 scan(s) to process"), std::string::npos) << r.output;
  const nlohmann::json ledger = JsonOf(root_ / "vellum-collection/scans/scan-1002.json");
  EXPECT_EQ(ledger["failures"], 2);
  EXPECT_EQ(ledger["runs"], 0);
  EXPECT_FALSE(fs::exists(root_ / "scan-1002" / "results"));
}

// SIGKILL to a run, at three moments while it works (each just after one more scan was swapped
// in, so that the next is on its way): every scan is then wholly old or wholly new, its manifest
// checking; the next run finishes exactly what is left.
TEST_F(CollectionTest, AKilledRunLeavesEveryScanWhollyOldOrWhollyNew) {
  ShellResult r = Collection("run");  // Old: made at the default dpi.
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const std::vector<std::string> scans = {"scan-1001", "scan-1002", "scan-1003", "scan-1004",
                                          "scan-2000-demo"};
  auto swapped = [&] {
    int n = 0;
    for (const std::string& s : scans) n += Runs(s) - 1;
    return n;
  };
  for (int kill_at = 1; kill_at <= 3; ++kill_at) {
    const fs::path pid_file = root_.string() + ".pid";
    std::system((kBin + " collection run --jobs 1 --dpi 200 --root " + root_.string() +
                 " > /dev/null 2>&1 & echo $! > " + pid_file.string())
                    .c_str());
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::minutes(3);
    while (swapped() < kill_at && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    ASSERT_GE(swapped(), kill_at) << "the run swapped no scan in three minutes";
    const pid_t pid = std::stoi(Text(pid_file));
    ASSERT_EQ(kill(pid, SIGKILL), 0);
    while (kill(pid, 0) == 0) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    while (AnyScanLocked()) {  // Its worker, killed with it.
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    ExpectManifestsCheck();
    const std::map<std::string, int> runs = RunsByStatus();
    for (const std::string& s : scans) {
      const std::string dpi =
          JsonOf(root_ / s / "results" / "provenance.json")["options"]["dpi"].get<std::string>();
      EXPECT_TRUE(dpi == "0" || dpi == "200") << s << " after kill " << kill_at;
      ASSERT_TRUE(runs.count(s)) << s;
      EXPECT_EQ(dpi == "200", runs.at(s) == 2) << s << " after kill " << kill_at;
    }
  }
  r = Collection("run", "--dpi 200");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("2 scan(s) to process"), std::string::npos) << r.output;
  const std::map<std::string, int> runs = RunsByStatus();
  for (const std::string& s : scans) EXPECT_EQ(runs.at(s), 2) << s;  // None processed twice.
  ExpectManifestsCheck();
  for (const auto& entry : fs::directory_iterator(root_)) {  // No leftovers of the killed runs.
    EXPECT_NE(entry.path().filename().string()[0], '.') << entry.path();
  }
}

}  // namespace
}  // namespace vellum
