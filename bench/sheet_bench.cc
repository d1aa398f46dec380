// The contact sheet the restorer writes before every RESTORED, over a data folder of 500 scans
// (a day at a busy station): read afresh, as `vellum sheet` does, against the restorer's way,
// each folder taken from the sheet's cache unless its files changed (station/contact_sheet.h),
// one scan new since the last sheet, as after each scan. Each scan folder holds what the sheet
// reads: raw/scan.yaml with an identity, results/report.json with a verdict and a check that
// did not pass, and the restored page's files.
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "bench/ratio_reporter.h"
#include "core/patterns/patterns.h"
#include "io/scan_io.h"
#include "station/contact_sheet.h"

namespace {

namespace fs = std::filesystem;

constexpr int kScans = 500;

const fs::path& DataDir() {
  static const fs::path dir = [] {
    const fs::path d =
        fs::temp_directory_path() / ("vellum_sheet_bench_" + std::to_string(getpid()));
    fs::remove_all(d);
    return d;
  }();
  return dir;
}

void AddScan(int id) {
  const fs::path scan = DataDir() / ("scan-" + std::to_string(id) + "-MS-7_" + std::to_string(id));
  fs::create_directories(scan / "raw");
  fs::create_directories(scan / "results" / "report");
  // scan.yaml as the station writes it: the default rig's pattern sequence and an identity.
  static const vellum::Scan header = [] {
    vellum::Scan s;
    s.sequence = vellum::MakePatternSequence(vellum::PatternOptions());
    s.camera_size = cv::Size(1600, 1200);
    s.identity.shelfmark = "MS 7";
    s.identity.side = "recto";
    return s;
  }();
  vellum::Scan s = header;
  s.identity.folio = std::to_string(id);
  if (!vellum::WriteScanYaml((scan / "raw").string(), s).ok()) std::abort();
  std::ofstream(scan / "results" / "report.json")
      << R"({"qc": {"verdict": "warn", "checks": [{"name": "scale", "verdict": "warn",)"
      << R"( "detail": "leaf 190 x 240 mm"}, {"name": "strain", "verdict": "pass"}]},)"
      << R"( "stages": [)" << std::string(4000, ' ') << "]}";
  std::ofstream(scan / "results" / "restored.tif") << "tiff";
  std::ofstream(scan / "results" / "report" / "restored.png") << "png";
}

void MakeFolder() {
  for (int id = 1; id <= kScans; ++id) AddScan(id);
}

void BM_Baseline_SheetAfresh(benchmark::State& state) {
  int next = kScans + 1;
  for (auto _ : state) {
    AddScan(next++);
    if (!vellum::station::WriteContactSheet(DataDir().string()).ok()) {
      state.SkipWithError("cannot write the sheet");
    }
  }
}

void BM_SheetCached(benchmark::State& state) {
  vellum::station::SheetCache cache;
  if (!vellum::station::WriteContactSheet(DataDir().string(), &cache).ok()) {
    state.SkipWithError("cannot write the sheet");
  }
  int next = 100000;
  for (auto _ : state) {
    AddScan(next++);
    if (!vellum::station::WriteContactSheet(DataDir().string(), &cache).ok()) {
      state.SkipWithError("cannot write the sheet");
    }
  }
}

}  // namespace

BENCHMARK(BM_Baseline_SheetAfresh)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(5)
    ->Apply(vellum::Repeated);
BENCHMARK(BM_SheetCached)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(5)
    ->Apply(vellum::Repeated);

int main(int argc, char** argv) {
  vellum::InitializeInterleaved(&argc, &argv);
  MakeFolder();  // Before the clock runs.
  vellum::RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  reporter.PrintRatio("BM_SheetCached", "the sheet with the restorer's cache",
                      "BM_Baseline_SheetAfresh", "read afresh");
  fs::remove_all(DataDir());
  return 0;
}
