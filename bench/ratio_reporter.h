// A console reporter that also remembers each run's real time, so a benchmark program can
// print its ratios against the peer after the table.
#pragma once

#include <benchmark/benchmark.h>

#include <cstdio>
#include <map>
#include <string>
#include <vector>

namespace vellum {

class RatioReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& r : runs) {
      times_[r.benchmark_name()] = r.GetAdjustedRealTime();
      cpu_[r.benchmark_name()] = r.GetAdjustedCPUTime();
    }
    ConsoleReporter::ReportRuns(runs);
  }
  // Real time (the benchmark's unit) of the first run whose name starts with `prefix`, or 0.
  double Time(const std::string& prefix) const { return First(times_, prefix); }
  // CPU time (the benchmark's unit) of the first run whose name starts with `prefix`, or 0:
  // every thread's when the benchmark measures the process's CPU time.
  double CpuTime(const std::string& prefix) const { return First(cpu_, prefix); }
  // The median of a benchmark's repetitions (its "_median" aggregate), else its one run's time.
  double Median(const std::string& prefix) const {
    for (const auto& [name, t] : times_) {
      if (name.rfind(prefix, 0) == 0 && name.size() > 7 &&
          name.compare(name.size() - 7, 7, "_median") == 0) {
        return t;
      }
    }
    return Time(prefix);
  }
  // After the table: "<ours_label> T ms vs <peer_label> T ms: peer / ours = Rx", when both
  // ran (a --benchmark_filter may leave either out). Times in ms (the benchmarks' unit).
  void PrintRatio(const std::string& ours, const std::string& ours_label, const std::string& peer,
                  const std::string& peer_label) const {
    const double a = Time(ours), b = Time(peer);
    if (a <= 0 || b <= 0) return;
    std::printf("%s %.2f ms vs %s %.2f ms: peer / ours = %.1fx\n", ours_label.c_str(), a,
                peer_label.c_str(), b, b / a);
  }

 private:
  static double First(const std::map<std::string, double>& by_name, const std::string& prefix) {
    for (const auto& [name, t] : by_name) {
      if (name.rfind(prefix, 0) == 0) return t;
    }
    return 0.0;
  }

  std::map<std::string, double> times_;
  std::map<std::string, double> cpu_;
};

}  // namespace vellum
