// A collection's stale scans as a Slurm job array (Debian's slurm-wlm): the scans in chunks, one
// chunk per task, each task's memory and time estimated from its scans' sizes, the batch script
// written into the ledger folder and submitted with `sbatch --array`, and the array followed with
// `squeue`. Each task runs `vellum collection task`, which processes its chunk's scans one by one
// as `vellum collection one` does (ProcessScan: the same lock, swap and ledger as a local run), so
// the results are the same byte for byte and no scan is processed twice, whatever is cancelled
// when.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "collection/collection.h"
#include "core/common/status.h"

namespace vellum::collection {

// Where a library's cluster wants its jobs, and what each task may use.
struct SlurmSettings {
  std::string partition;  // --partition, "" for the cluster's default
  std::string account;    // --account, "" for the user's default
  int chunk = 10;         // Scans per task.
  int cpus_per_task = 2;  // The pipeline's threads in each task.
  std::string vellum;     // The vellum program the tasks run: the same path on every node.
  // A task done with its chunk takes scans of tasks not yet begun (for a third of its time limit),
  // so that the array ends when its work does, not when its slowest chunk does.
  bool steal = true;
  // Extra sbatch flags, one per entry ("--qos=long"), for what a site asks beyond the above.
  std::vector<std::string> extra;
};

// One array: its tasks' scans (folders, chunk by chunk) and what each task asks for.
struct SlurmArray {
  std::vector<std::string> folders;  // Task k processes folders [k * chunk, (k + 1) * chunk).
  int chunk = 1;
  int tasks = 0;
  int64_t memory_mb = 0;  // Per task: the largest scan of any chunk.
  int minutes = 0;        // Per task: its chunk's estimated time, with room to spare.
};

// Memory for processing one scan whose raw captures take `raw_bytes`: `vellum process` peaks at
// about 220 MB on a 1600 x 1200 scan (113 MB of frames) and 1.9 GB on a 24 MP one (1.4 GB): 256 MB
// and 1.25 times the captures covers both with a margin.
int64_t ScanMemoryMb(int64_t raw_bytes);
// Minutes for processing scans of `raw_bytes` in all: about 1 s per 100 MB of captures on one of
// this project's cores (11 s for the 24 MP scan's 1.4 GB), three times over, and 5 minutes at least
// (a task's start, a slow node, a shared filesystem).
int TaskMinutes(int64_t raw_bytes);

// The array for `scans` (the plan's stale ones, in order).
SlurmArray MakeArray(const std::vector<PlannedScan>& scans, int chunk);

// The batch script of `array` for the collection at `root`: the #SBATCH lines (job name, array,
// memory, time, cpus, partition, account, each task's log beside the script) and one line running
// `vellum collection task` on the task's chunk, the processing `options` passed as flags.
std::string BatchScript(const std::string& root, const std::string& list_file,
                        const std::string& log_pattern, const SlurmArray& array,
                        const SlurmSettings& slurm, const RunSettings& run);

// Runs `sbatch --parsable script`; the job's id in *job. An error carries sbatch's own message.
Status Submit(const std::string& script, std::string* job);
// The tasks of `jobs` still in the queue (pending, running, completing): squeue's lines
// "<job>_<task> <state>". An error when squeue cannot be run or reach the controller.
Status Queued(const std::vector<std::string>& jobs, std::vector<std::string>* tasks);

// A task's claim on a scan of its array: true for the first task of the array to ask, false for
// every later one (an exclusive create of `claims_dir`/`folder`, atomic on NFS too). The tasks of
// an array take their own chunk's scans and steal others' by claim, so that no two start the same
// scan; the scan's lock (ProcessScan) still keeps it from being processed twice across arrays and
// runs. A scan claimed by a task that was cancelled before finishing it stays stale, for the next
// array.
bool ClaimForArray(const std::string& claims_dir, const std::string& folder);

// Cancels the tasks of `job` still pending (none of them begun): `scancel --state=PENDING`.
Status CancelPending(const std::string& job);

// The job ids this collection submitted (vellum-collection/slurm/jobs), the newest last; and one
// more noted.
std::vector<std::string> SubmittedJobs(const std::string& root);
Status NoteSubmitted(const std::string& root, const std::string& job);

}  // namespace vellum::collection
