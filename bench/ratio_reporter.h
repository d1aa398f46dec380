// A console reporter that also remembers each run's real time, so a benchmark program can
// print its ratios against the peer after the table.
#pragma once

#include <benchmark/benchmark.h>

#include <map>
#include <string>
#include <vector>

namespace vellum {

class RatioReporter : public benchmark::ConsoleReporter {
 public:
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& r : runs) times_[r.benchmark_name()] = r.GetAdjustedRealTime();
    ConsoleReporter::ReportRuns(runs);
  }
  // Real time (the benchmark's unit) of the first run whose name starts with `prefix`, or 0.
  double Time(const std::string& prefix) const {
    for (const auto& [name, t] : times_) {
      if (name.rfind(prefix, 0) == 0) return t;
    }
    return 0.0;
  }

 private:
  std::map<std::string, double> times_;
};

}  // namespace vellum
