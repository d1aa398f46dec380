// Issue 16: recording keeps up with a 24 MP camera. One structured-light frame of 6000 x 4000
// (8-bit gray: fringes over a page, with the virtual gantry's camera noise of 1.5 DN, which is
// what makes real frames hard to compress) written to the scan's archive the ways a recorder
// could: appended raw to the capture log (what the station's LCM log does), as PNG at OpenCV's
// default level and at levels 0 and 1, and as TIFF without compression and with OpenCV's default
// (LZW). The baseline is the frame interval of a 5 fps camera, 200 ms: a write that takes
// longer falls behind the camera. Files go to the temporary folder (the same disk as /tmp).
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "bench/ratio_reporter.h"

namespace {

namespace fs = std::filesystem;

const cv::Mat& Frame() {
  static const cv::Mat frame = [] {
    cv::Mat f(4000, 6000, CV_8U);
    cv::Mat noise(f.size(), CV_32F);
    cv::RNG rng(7);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, 1.5);
    for (int y = 0; y < f.rows; ++y) {
      uint8_t* row = f.ptr<uint8_t>(y);
      const float* n = noise.ptr<float>(y);
      for (int x = 0; x < f.cols; ++x) {
        // A phase-shift fringe of 64 px over a page of albedo 0.8 on a table of 0.35.
        const bool page = x > 800 && x < 5200 && y > 500 && y < 3500;
        const double albedo = page ? 0.8 : 0.35;
        const double light = 0.08 + 0.92 * (0.5 + 0.5 * std::cos(2 * M_PI * x / 64.0));
        row[x] = cv::saturate_cast<uint8_t>(255 * albedo * light + n[x]);
      }
    }
    return f;
  }();
  return frame;
}

std::string TempFile(const char* name) {
  return (fs::temp_directory_path() / ("vellum_archive_bench_" + std::to_string(getpid()) + name))
      .string();
}

void WriteImage(benchmark::State& state, const char* ext, std::vector<int> params) {
  const cv::Mat& f = Frame();
  const std::string path = TempFile(ext);
  for (auto _ : state) {
    if (!cv::imwrite(path, f, params)) state.SkipWithError("imwrite failed");
  }
  state.counters["MB"] = static_cast<double>(fs::file_size(path)) / 1e6;
  fs::remove(path);
}

void BM_Baseline_FrameInterval5fps(benchmark::State& state) {
  for (auto _ : state) state.SetIterationTime(0.2);
}

void BM_LogAppendRaw(benchmark::State& state) {
  const cv::Mat& f = Frame();
  const std::string path = TempFile(".lcmlog");
  for (auto _ : state) {
    FILE* out = std::fopen(path.c_str(), "ab");
    std::fwrite(f.data, 1, f.total(), out);
    std::fflush(out);
    std::fclose(out);
  }
  state.counters["MB"] = static_cast<double>(f.total()) / 1e6;
  fs::remove(path);
}

void BM_PngDefault(benchmark::State& s) { WriteImage(s, ".png", {}); }
void BM_PngLevel0(benchmark::State& s) { WriteImage(s, ".png", {cv::IMWRITE_PNG_COMPRESSION, 0}); }
void BM_PngLevel1(benchmark::State& s) { WriteImage(s, ".png", {cv::IMWRITE_PNG_COMPRESSION, 1}); }
void BM_TiffNone(benchmark::State& s) { WriteImage(s, ".tif", {cv::IMWRITE_TIFF_COMPRESSION, 1}); }
void BM_TiffLzw(benchmark::State& s) { WriteImage(s, ".tif", {}); }

}  // namespace

BENCHMARK(BM_Baseline_FrameInterval5fps)
    ->Unit(benchmark::kMillisecond)
    ->UseManualTime()
    ->Iterations(1);
BENCHMARK(BM_LogAppendRaw)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(5);
BENCHMARK(BM_PngDefault)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);
BENCHMARK(BM_PngLevel0)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);
BENCHMARK(BM_PngLevel1)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);
BENCHMARK(BM_TiffNone)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);
BENCHMARK(BM_TiffLzw)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  vellum::RatioReporter reporter;
  Frame();  // Made before the clock runs.
  benchmark::RunSpecifiedBenchmarks(&reporter);
  const double interval = reporter.Time("BM_Baseline_FrameInterval5fps");
  for (const char* way : {"BM_LogAppendRaw", "BM_PngDefault", "BM_PngLevel0", "BM_PngLevel1",
                          "BM_TiffNone", "BM_TiffLzw"}) {
    const double t = reporter.Time(way);
    if (t > 0 && interval > 0) {
      std::printf("%-16s %7.1f ms = %.2f of the 5 fps frame interval (%s)\n", way + 3, t,
                  t / interval, t < interval ? "keeps up" : "falls behind");
    }
  }
  return 0;
}
