#include "collection/slurm.h"

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "io/json.h"

namespace vellum::collection {
namespace fs = std::filesystem;
namespace {

// `text` as one word of a POSIX shell's command line.
std::string Quoted(const std::string& text) {
  std::string q = "'";
  for (const char c : text) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// Runs `argv` (no shell), its stdout and stderr into *out; an error names the program and says
// what it printed when it could not be run or did not exit 0.
Status Capture(const std::vector<std::string>& argv, std::string* out) {
  int fds[2];
  if (pipe(fds) != 0) return Status::Error(argv[0] + ": cannot make a pipe");
  const pid_t pid = fork();
  if (pid < 0) return Status::Error(argv[0] + ": cannot fork");
  if (pid == 0) {
    dup2(fds[1], 1);
    dup2(fds[1], 2);
    close(fds[0]);
    close(fds[1]);
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    execvp(args[0], args.data());
    _exit(127);
  }
  close(fds[1]);
  out->clear();
  char buf[4096];
  for (ssize_t n; (n = read(fds[0], buf, sizeof(buf))) > 0;) out->append(buf, n);
  close(fds[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  if (WIFEXITED(status) && WEXITSTATUS(status) == 127) {
    return Status::Error(argv[0] +
                         ": not found (is Slurm's client installed? apt install "
                         "slurm-client)");
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    std::string said = *out;
    while (!said.empty() && said.back() == '\n') said.pop_back();
    return Status::Error(argv[0] + " failed: " + said);
  }
  return Status::Ok();
}

std::string SlurmFolder(const std::string& root) { return root + "/" + kLedgerFolder + "/slurm"; }

}  // namespace

int64_t ScanMemoryMb(int64_t raw_bytes) {
  return 256 + static_cast<int64_t>(std::ceil(1.25 * raw_bytes / (1 << 20)));
}

int TaskMinutes(int64_t raw_bytes) {
  const double seconds = 3.0 * (2.0 + raw_bytes / 100e6);
  return std::max(5, static_cast<int>(std::ceil(seconds / 60)));
}

SlurmArray MakeArray(const std::vector<PlannedScan>& scans, int chunk) {
  SlurmArray a;
  a.chunk = std::max(1, chunk);
  for (const PlannedScan& s : scans) a.folders.push_back(s.folder);
  a.tasks = static_cast<int>((a.folders.size() + a.chunk - 1) / a.chunk);
  for (int t = 0; t < a.tasks; ++t) {
    int64_t bytes = 0, largest = 0;
    for (size_t i = t * a.chunk; i < std::min(scans.size(), size_t(t + 1) * a.chunk); ++i) {
      bytes += scans[i].raw_bytes;
      largest = std::max(largest, scans[i].raw_bytes);
    }
    a.memory_mb = std::max(a.memory_mb, ScanMemoryMb(largest));
    a.minutes = std::max(a.minutes, TaskMinutes(bytes));
  }
  return a;
}

std::string BatchScript(const std::string& root, const std::string& list_file,
                        const std::string& log_pattern, const SlurmArray& array,
                        const SlurmSettings& slurm, const RunSettings& run) {
  std::ostringstream s;
  s << "#!/bin/sh\n"
    << "# Written by `vellum collection run --slurm` for the collection " << root << ":\n"
    << "# task k processes scans k*" << array.chunk << " to (k+1)*" << array.chunk << "-1 of "
    << list_file << ".\n"
    << "#SBATCH --job-name=vellum-collection\n"
    << "#SBATCH --array=0-" << array.tasks - 1 << "\n"
    << "#SBATCH --ntasks=1\n"
    << "#SBATCH --cpus-per-task=" << slurm.cpus_per_task << "\n"
    << "#SBATCH --mem=" << array.memory_mb << "M\n"
    << "#SBATCH --time=" << array.minutes << "\n"
    << "#SBATCH --output=" << log_pattern << "\n";
  if (!slurm.partition.empty()) s << "#SBATCH --partition=" << slurm.partition << "\n";
  if (!slurm.account.empty()) s << "#SBATCH --account=" << slurm.account << "\n";
  for (const std::string& e : slurm.extra) s << "#SBATCH " << e << "\n";
  s << "exec " << Quoted(slurm.vellum) << " collection task --root " << Quoted(root) << " --list "
    << Quoted(list_file) << " --chunk " << array.chunk
    << " --index \"$SLURM_ARRAY_TASK_ID\" --job \"slurm "
       "${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID}\"";
  if (slurm.steal) s << " --steal-for " << array.minutes * 20;  // A third of its time, in s.
  if (run.retry_failed) s << " --retry-failed";
  for (const auto& [name, value] : run.options) s << " " << Quoted("--" + name + "=" + value);
  s << "\n";
  return s.str();
}

Status Submit(const std::string& script, std::string* job) {
  std::string out;
  const Status s = Capture({"sbatch", "--parsable", script}, &out);
  if (!s.ok()) return s;
  // "1234" or "1234;cluster".
  const size_t end = out.find_first_of(";\n");
  *job = out.substr(0, end);
  if (job->empty() || job->find_first_not_of("0123456789") != std::string::npos) {
    return Status::Error("sbatch said '" + out + "', not a job id");
  }
  return Status::Ok();
}

Status Queued(const std::vector<std::string>& jobs, std::vector<std::string>* tasks) {
  tasks->clear();
  if (jobs.empty()) return Status::Ok();
  std::string ids;
  for (const std::string& j : jobs) ids += (ids.empty() ? "" : ",") + j;
  std::string out;
  // -r: one line per task of an array, pending ones too.
  const Status s = Capture({"squeue", "-h", "-r", "-j", ids, "-o", "%i %T"}, &out);
  if (!s.ok()) {
    // A job the controller has forgotten is no longer queued.
    if (out.find("Invalid job id") != std::string::npos) return Status::Ok();
    return s;
  }
  std::istringstream in(out);
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) tasks->push_back(line);
  }
  return Status::Ok();
}

bool ClaimForArray(const std::string& claims_dir, const std::string& folder) {
  std::error_code ec;
  fs::create_directories(claims_dir, ec);
  const int fd =
      open((claims_dir + "/" + folder).c_str(), O_CREAT | O_EXCL | O_WRONLY | O_CLOEXEC, 0644);
  // Another task's claim; any other failure claims nothing and leaves the scan to its lock.
  if (fd < 0) return errno != EEXIST;
  close(fd);
  return true;
}

Status CancelPending(const std::string& job) {
  std::string out;
  return Capture({"scancel", "--state=PENDING", job}, &out);
}

std::vector<std::string> SubmittedJobs(const std::string& root) {
  std::vector<std::string> jobs;
  std::ifstream in(SlurmFolder(root) + "/jobs");
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) jobs.push_back(line);
  }
  return jobs;
}

Status NoteSubmitted(const std::string& root, const std::string& job) {
  std::error_code ec;
  fs::create_directories(SlurmFolder(root), ec);
  std::ofstream out(SlurmFolder(root) + "/jobs", std::ios::app);
  out << job << "\n";
  out.close();
  if (!out) return Status::Error(SlurmFolder(root) + "/jobs: cannot write");
  return Status::Ok();
}

}  // namespace vellum::collection
