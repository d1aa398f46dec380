// How every benchmark here runs and reports, so that its figures hold run to run on a shared,
// noisy machine: each case is repeated (Repeated), the repetitions of all cases interleaved in
// random order (InitializeInterleaved), and each case reported by its median and its spread (the
// slowest repetition over the fastest). RatioReporter remembers the figures so a benchmark
// program can print its ratios against the peer after the table.
#pragma once

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

namespace vellum {

// Repetitions of every case: enough for a median that one slow repetition cannot move.
inline constexpr int kBenchRepetitions = 5;

// `b` repeated, reported by its aggregates only (mean, median, stddev, cv, and min and max, from
// which the spread).
inline void Repeated(benchmark::internal::Benchmark* b) {
  b->Repetitions(kBenchRepetitions)->ReportAggregatesOnly(true);
  b->ComputeStatistics("min", [](const std::vector<double>& v) {
    return v.empty() ? 0.0 : *std::min_element(v.begin(), v.end());
  });
  b->ComputeStatistics("max", [](const std::vector<double>& v) {
    return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end());
  });
}

// benchmark::Initialize with the repetitions of all cases interleaved in random order (the
// machine's speed drifts over a run; interleaved, the drift falls on every case alike). A flag
// given on the command line still wins.
inline void InitializeInterleaved(int* argc, char*** argv) {
  static std::vector<char*> args;
  static char interleave[] = "--benchmark_enable_random_interleaving=true";
  args.assign(*argv, *argv + *argc);
  args.insert(args.begin() + 1, interleave);
  args.push_back(nullptr);
  *argc = static_cast<int>(args.size()) - 1;
  *argv = args.data();
  benchmark::Initialize(argc, *argv);
}

class RatioReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& r : runs) {
      times_[r.benchmark_name()] = r.GetAdjustedRealTime();
      cpu_[r.benchmark_name()] = r.GetAdjustedCPUTime();
    }
    ConsoleReporter::ReportRuns(runs);
  }
  // Real time (the benchmark's unit) of the first case whose name starts with `prefix`: its
  // median over the repetitions, or its one run's time; 0 when it did not run.
  double Time(const std::string& prefix) const { return Figure(times_, prefix, "median"); }
  // Likewise its CPU time: every thread's when the benchmark measures the process's CPU time.
  double CpuTime(const std::string& prefix) const { return Figure(cpu_, prefix, "median"); }
  // The spread of its real time: the slowest repetition over the fastest (1 for one run).
  double Spread(const std::string& prefix) const {
    const double lo = Figure(times_, prefix, "min"), hi = Figure(times_, prefix, "max");
    return lo > 0 && hi > 0 ? hi / lo : 1.0;
  }
  // After the table: "<ours_label> T ms (spread S) vs <peer_label> T ms (spread S): peer / ours =
  // Rx (medians), at worst Wx (the peer's fastest repetition over our slowest)", when both ran
  // (a --benchmark_filter may leave either out). Times in ms (the benchmarks' unit).
  void PrintRatio(const std::string& ours, const std::string& ours_label, const std::string& peer,
                  const std::string& peer_label) const {
    const double a = Time(ours), b = Time(peer);
    if (a <= 0 || b <= 0) return;
    std::printf("%s %.2f ms (spread %.2fx) vs %s %.2f ms (spread %.2fx): peer / ours = %.1fx",
                ours_label.c_str(), a, Spread(ours), peer_label.c_str(), b, Spread(peer), b / a);
    const double fastest_peer = Figure(times_, peer, "min"), slowest = Figure(times_, ours, "max");
    if (fastest_peer > 0 && slowest > 0) {
      std::printf(" (medians), at worst %.1fx", fastest_peer / slowest);
    }
    std::printf("\n");
  }

 private:
  // The aggregate `aggregate` ("median", "min", "max") of the first case named `prefix...`, else
  // (a case run once) that case's own figure for "median", else 0.
  static double Figure(const std::map<std::string, double>& by_name, const std::string& prefix,
                       const std::string& aggregate) {
    const std::string suffix = "_" + aggregate;
    for (const auto& [name, t] : by_name) {
      if (name.rfind(prefix, 0) == 0 && name.size() > suffix.size() &&
          name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0) {
        return t;
      }
    }
    if (aggregate != "median") return 0.0;
    for (const auto& [name, t] : by_name) {
      if (name.rfind(prefix, 0) == 0) return t;
    }
    return 0.0;
  }

  std::map<std::string, double> times_;
  std::map<std::string, double> cpu_;
};

}  // namespace vellum
