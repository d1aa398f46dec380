// The Slurm array as written, before any cluster sees it: each task's memory and time from its
// scans' sizes, and a batch script whose command line reaches `vellum collection task` word for
// word, whatever the paths and options hold.
#include "collection/slurm.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace vellum::collection {
namespace {
namespace fs = std::filesystem;

PlannedScan Scan(const std::string& folder, int64_t raw_bytes) {
  PlannedScan p;
  p.folder = folder;
  p.raw_bytes = raw_bytes;
  return p;
}

// `vellum process` peaked at 219 to 227 MB on the 1600 x 1200 scan (113 MB of frames) and at
// 1877 MB on the 24 MP rig's (1.4 GB of frames; docs/measurements.md): a task asks for more than
// each, and the 24 MP scan's task for less than the 2.5 GB bar of its peak.
TEST(SlurmArray, EachTaskAsksForTheMemoryOfItsLargestScan) {
  EXPECT_GT(ScanMemoryMb(113'000'000), 227);
  EXPECT_GT(ScanMemoryMb(1'400'000'000), 1877);
  EXPECT_LT(ScanMemoryMb(1'400'000'000), 2560);

  std::vector<PlannedScan> scans;
  for (int i = 0; i < 23; ++i) scans.push_back(Scan("scan-" + std::to_string(i), 113'000'000));
  scans[17].raw_bytes = 1'400'000'000;  // One 24 MP scan among them.
  const SlurmArray a = MakeArray(scans, 10);
  EXPECT_EQ(a.tasks, 3);
  EXPECT_EQ(a.chunk, 10);
  EXPECT_EQ(a.folders.size(), 23u);
  EXPECT_EQ(a.memory_mb, ScanMemoryMb(1'400'000'000));
  EXPECT_GE(a.minutes, 5);
  EXPECT_GE(a.minutes, TaskMinutes(9 * 113'000'000LL + 1'400'000'000));
}

// The script's command line, run by sh with the task's variables set, gives the task its root,
// list, chunk, index, job and every option as one word each, quotes and spaces included.
TEST(SlurmArray, TheBatchScriptPassesEveryWordIntact) {
  const fs::path dir =
      fs::temp_directory_path() / ("vellum_slurm_test_" + std::to_string(getpid()));
  fs::create_directories(dir);
  const fs::path echo = dir / "args";
  std::ofstream(echo) << "#!/bin/sh\nfor a in \"$@\"; do printf '%s\\n' \"$a\"; done\n";
  fs::permissions(echo, fs::perms::owner_all);

  SlurmArray array = MakeArray({Scan("scan-1", 1 << 20), Scan("scan-2", 1 << 20)}, 1);
  SlurmSettings slurm;
  slurm.partition = "batch";
  slurm.account = "library";
  slurm.extra = {"--qos=long"};
  slurm.vellum = echo.string();
  RunSettings run;
  run.options = {{"dpi", "300"}, {"leaf-size", "it's 150x200"}};
  const std::string root = "/data/the library's scans";
  const std::string script =
      BatchScript(root, root + "/list.txt", root + "/task-%a.log", array, slurm, run);
  for (const std::string line :
       {"#SBATCH --array=0-1\n", "#SBATCH --partition=batch\n", "#SBATCH --account=library\n",
        "#SBATCH --qos=long\n", "#SBATCH --cpus-per-task=2\n"}) {
    EXPECT_NE(script.find(line), std::string::npos) << line << " not in\n" << script;
  }
  EXPECT_NE(script.find("#SBATCH --mem=" + std::to_string(ScanMemoryMb(1 << 20)) + "M\n"),
            std::string::npos);
  std::ofstream(dir / "job.sh") << script;

  FILE* p = popen(
      ("SLURM_ARRAY_TASK_ID=1 SLURM_ARRAY_JOB_ID=77 sh " + (dir / "job.sh").string()).c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::vector<std::string> words;
  char buf[512];
  while (fgets(buf, sizeof(buf), p)) {
    std::string w(buf);
    if (!w.empty() && w.back() == '\n') w.pop_back();
    words.push_back(w);
  }
  ASSERT_EQ(pclose(p), 0);
  const std::vector<std::string> expected = {"collection",  "task",
                                             "--root",      root,
                                             "--list",      root + "/list.txt",
                                             "--chunk",     "1",
                                             "--index",     "1",
                                             "--job",       "slurm 77_1",
                                             "--steal-for", std::to_string(array.minutes * 20),
                                             "--dpi=300",   "--leaf-size=it's 150x200"};
  EXPECT_EQ(words, expected);
  fs::remove_all(dir);
}

// The tasks of one array claim each scan once; a later array (the scans of a cancelled task, sent
// again) claims afresh in its own folder.
TEST(SlurmArray, EachScanIsClaimedOnceAnArray) {
  const fs::path dir = fs::temp_directory_path() / ("vellum_claims_" + std::to_string(getpid()));
  fs::remove_all(dir);
  EXPECT_TRUE(ClaimForArray((dir / "array-1/claims").string(), "scan-1001"));
  EXPECT_FALSE(ClaimForArray((dir / "array-1/claims").string(), "scan-1001"));
  EXPECT_TRUE(ClaimForArray((dir / "array-1/claims").string(), "scan-1002"));
  EXPECT_TRUE(ClaimForArray((dir / "array-2/claims").string(), "scan-1001"));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace vellum::collection
