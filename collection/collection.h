// A collection: a folder of scan folders as the station writes them (scan-<id>[-<slug>]/ with
// raw/ and its pinned calibration, results/ and manifest-sha256.txt), reprocessed whenever
// vellum, the calibration or the options change. What vellum keeps about it lives in one folder
// at its root, vellum-collection/ (the ledger: one small JSON file per scan), which may be
// deleted without losing a scan: what is up to date is read from each scan's results, not from
// the ledger or file times (docs/collection.md).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "flags/flags.h"
#include "io/json.h"
#include "pipeline/stages.h"

namespace vellum::collection {

// The ledger's folder, at the collection's root.
inline constexpr char kLedgerFolder[] = "vellum-collection";
// What a scan's products were made from, in its results folder.
inline constexpr char kProvenanceName[] = "provenance.json";

// What a scan's products were made from: the same five, and the scan is up to date.
struct Provenance {
  std::string vellum_version;                  // io/version.h
  std::string raw_sha256;                      // RawDigest: the raw captures' checksums, as one.
  std::string calibration_sha256;              // Of the calibration's values (CalibrationSha256).
  std::map<std::string, std::string> options;  // Every processing flag and its value.
  // The SHA-256 of each file a processing flag names (--camera-icc, --flatfield, --studio-field),
  // by flag: a file changed under the same name makes the scan stale too.
  std::map<std::string, std::string> files;
  // The how-manyth time the scan was processed (1 the first): the ledger's counter, kept with the
  // products too, so that a run killed between the swap and the ledger's note miscounts nothing.
  // Not compared by StaleReasons.
  int run = 0;
};
Json ProvenanceJson(const Provenance& p);
// Reads results/provenance.json; an error names the file and what is wrong.
Status ReadProvenance(const std::string& file, Provenance* p);
// Why products made from `made` are not what `want` would make, one line per difference
// ("calibration changed: 3f2a... -> 9b1c..."); empty when they agree. `want.raw_sha256` and
// `want.calibration_sha256` are the scan's own.
std::vector<std::string> StaleReasons(const Provenance& made, const Provenance& want);

// The raw captures' checksum: the SHA-256 of the lines "<sha256>  <path>" of every file under
// raw/ but the calibration (planned apart), recorded-sha256.txt and failed.txt, sorted by path.
// From the scan's manifest-sha256.txt when it lists them; with `verify`, or without a manifest,
// from the files themselves (a file that no longer matches its manifest line is an error naming
// it: the scan is damaged, `vellum manifest check` tells more).
Status RawDigest(const std::string& scan_dir, bool verify, std::string* digest);

// Every processing flag (`vellum process`'s, PipelineFlagSpecs) with the value `flags` give it,
// or its default; `flags` holds those specs among its own.
std::map<std::string, std::string> OptionsOf(const Flags& flags);
// The pipeline's options from such a map (a bad value throws UsageError naming the flag).
PipelineOptions PipelineOptionsOf(const std::map<std::string, std::string>& options);

enum class State { kDone, kStale, kRunning, kFailed, kParked, kAtStation };
const char* StateName(State s);

// One scan of the plan.
struct PlannedScan {
  std::string folder;  // Its name under the root ("scan-1764...-MS-12_3_recto").
  State state = State::kStale;
  std::vector<std::string> reasons;  // Why it is stale, failed, parked or at the station.
  int runs = 0;  // Times it was processed and swapped in (the ledger, or its provenance's run).
  int64_t raw_bytes = 0;  // Its raw captures' size (for a task's memory and time).
};

// The plan of the collection at `root` for processing with `options` (OptionsOf): every scan
// folder's state, in the order of their names (the scans' ids: the order they were taken).
// With `verify`, each stale or done scan's raw captures are hashed again (RawDigest).
Status Plan(const std::string& root, const std::map<std::string, std::string>& options, bool verify,
            std::vector<PlannedScan>* plan);

// One scan folder's state, as Plan gives it.
PlannedScan PlanScan(const std::string& root, const std::string& folder,
                     const std::map<std::string, std::string>& options, bool verify);

// What one scan's processing needs besides the root and the folder.
struct RunSettings {
  std::map<std::string, std::string> options;  // OptionsOf: every processing flag.
  bool retry_failed = false;  // Process a scan whose last run failed with the same inputs.
  std::string job;            // Who runs it, for the ledger ("local", "slurm 1234_5").
};

// Processes the scan `folder` of `root` if it is still stale (or failed, with retry_failed): its
// products are made into a new folder beside it (.vellum-new-<folder>: the raw files hard-linked,
// results/ made by RunPipeline with its provenance.json, the manifest written over both), which
// then takes the scan folder's place in one step (ReplaceFolder), so that a run killed at any
// instant leaves the scan wholly old or wholly new, its manifest checking. A per-scan lock in the
// ledger keeps two runs (local or Slurm tasks) from processing one scan at once. The ledger
// records the run (its counter, or the failure and its message). `*what` says what was done
// ("processed", "done", "running elsewhere", "failed: ..."). Returns an error only when the scan
// failed.
Status ProcessScan(const std::string& root, const std::string& folder, const RunSettings& run,
                   std::string* what);

// Records in the ledger that processing the scan failed with `message`: what a worker that
// died (a crash, the out-of-memory killer) could not record itself.
Status RecordFailure(const std::string& root, const std::string& folder, const RunSettings& run,
                     const std::string& message);

// The ledger's entry of one scan (vellum-collection/scans/<folder>.json).
struct LedgerEntry {
  int runs = 0;         // Times processed and swapped in.
  int failures = 0;     // Times it failed.
  std::string state;    // "done", "failed", "" (never run)
  std::string message;  // The last failure's.
  std::string want;     // The provenance it was last run for (a digest), to tell a failure stale.
  std::string job, host, finished;
};
Status ReadLedger(const std::string& root, const std::string& folder, LedgerEntry* entry);
// The UTC time now as the ledger writes `finished` ("2026-12-07T06:36:44Z"): strings in this form
// compare as the times do.
std::string LedgerTime();
// Whether the ledger notes a run of the scan (done or failed) that finished at or after `since`
// (a LedgerTime); `*entry` gets the ledger's entry whenever it can be read.
bool NotedSince(const std::string& root, const std::string& folder, const std::string& since,
                LedgerEntry* entry);

// Leftovers of killed runs (.vellum-new-* and .old-* folders at the root, whose scans' locks no
// one holds) removed; a scan folder a fallback swap left missing gets its old one back.
void CleanUp(const std::string& root);

}  // namespace vellum::collection
