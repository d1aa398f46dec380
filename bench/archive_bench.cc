// Recording keeps up with a 24 MP camera. One structured-light frame of 6000 x 4000
// (8-bit gray: fringes over a page, with the virtual gantry's camera noise of 1.5 DN, which is
// what makes real frames hard to compress) written to the scan's archive the ways a recorder
// could: appended raw to the capture log (what the station's LCM log does), as PNG at OpenCV's
// default level and at levels 0 and 1, and as TIFF without compression and with OpenCV's default
// (LZW), and as PNG through libvips (libpng) with row filtering off at deflate levels 0 and 1
// (OpenCV cannot turn filtering off; on noisy frames it costs more than it saves). The baseline
// is the frame interval of a 5 fps camera, 200 ms: a write that takes longer falls behind the
// camera. Files go to the temporary folder (the same disk as /tmp).
#include <benchmark/benchmark.h>
#include <png.h>
#include <unistd.h>
#include <zlib.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>
#include <vips/vips8>

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

// PNG through libvips without row filters, at deflate level `compression`.
void PngUnfiltered(benchmark::State& state, int compression) {
  const cv::Mat& f = Frame();
  const std::string path = TempFile(".vips.png");
  vips::VImage image =
      vips::VImage::new_from_memory(f.data, f.total(), f.cols, f.rows, 1, VIPS_FORMAT_UCHAR);
  for (auto _ : state) {
    image.pngsave(path.c_str(), vips::VImage::option()
                                    ->set("compression", compression)
                                    ->set("filter", VIPS_FOREIGN_PNG_FILTER_NONE));
  }
  state.counters["MB"] = static_cast<double>(fs::file_size(path)) / 1e6;
  // Lossless: read back equal.
  if (cv::norm(cv::imread(path, cv::IMREAD_UNCHANGED), f, cv::NORM_INF) != 0) {
    state.SkipWithError("the PNG does not read back equal");
  }
  fs::remove(path);
}

// PNG through libpng itself: no row filter, deflate with Huffman coding alone (no string
// matching, which noisy frames defeat anyway).
void BM_PngHuffmanOnly(benchmark::State& state) {
  const cv::Mat& f = Frame();
  const std::string path = TempFile(".huff.png");
  for (auto _ : state) {
    FILE* out = std::fopen(path.c_str(), "wb");
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
    png_infop info = png_create_info_struct(png);
    if (setjmp(png_jmpbuf(png))) {
      state.SkipWithError("libpng failed");
      break;
    }
    png_init_io(png, out);
    png_set_IHDR(png, info, f.cols, f.rows, 8, PNG_COLOR_TYPE_GRAY, PNG_INTERLACE_NONE,
                 PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_NONE);
    png_set_compression_level(png, 1);
    png_set_compression_strategy(png, Z_HUFFMAN_ONLY);
    png_write_info(png, info);
    for (int y = 0; y < f.rows; ++y) png_write_row(png, f.ptr<uint8_t>(y));
    png_write_end(png, nullptr);
    png_destroy_write_struct(&png, &info);
    std::fclose(out);
  }
  state.counters["MB"] = static_cast<double>(fs::file_size(path)) / 1e6;
  if (cv::norm(cv::imread(path, cv::IMREAD_UNCHANGED), f, cv::NORM_INF) != 0) {
    state.SkipWithError("the PNG does not read back equal");
  }
  fs::remove(path);
}

void BM_PngDefault(benchmark::State& s) { WriteImage(s, ".png", {}); }
void BM_PngUnfiltered0(benchmark::State& s) { PngUnfiltered(s, 0); }
void BM_PngUnfiltered1(benchmark::State& s) { PngUnfiltered(s, 1); }
void BM_PngLevel0(benchmark::State& s) { WriteImage(s, ".png", {cv::IMWRITE_PNG_COMPRESSION, 0}); }
void BM_PngLevel1(benchmark::State& s) { WriteImage(s, ".png", {cv::IMWRITE_PNG_COMPRESSION, 1}); }
void BM_TiffNone(benchmark::State& s) { WriteImage(s, ".tif", {cv::IMWRITE_TIFF_COMPRESSION, 1}); }
void BM_TiffLzw(benchmark::State& s) { WriteImage(s, ".tif", {}); }

}  // namespace

BENCHMARK(BM_Baseline_FrameInterval5fps)
    ->Unit(benchmark::kMillisecond)
    ->UseManualTime()
    ->Iterations(1)
    ->Apply(vellum::Repeated);
BENCHMARK(BM_LogAppendRaw)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(5)
    ->Apply(vellum::Repeated);
BENCHMARK(BM_PngDefault)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3)
    ->Apply(vellum::Repeated);
BENCHMARK(BM_PngLevel0)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3)
    ->Apply(vellum::Repeated);
BENCHMARK(BM_PngLevel1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3)
    ->Apply(vellum::Repeated);
BENCHMARK(BM_TiffNone)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3)
    ->Apply(vellum::Repeated);
BENCHMARK(BM_TiffLzw)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3)
    ->Apply(vellum::Repeated);
BENCHMARK(BM_PngUnfiltered0)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3)
    ->Apply(vellum::Repeated);
BENCHMARK(BM_PngUnfiltered1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3)
    ->Apply(vellum::Repeated);
BENCHMARK(BM_PngHuffmanOnly)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3)
    ->Apply(vellum::Repeated);

int main(int argc, char** argv) {
  vellum::InitializeInterleaved(&argc, &argv);
  if (VIPS_INIT(argv[0]) != 0) return 1;
  vellum::RatioReporter reporter;
  Frame();  // Made before the clock runs.
  benchmark::RunSpecifiedBenchmarks(&reporter);
  const double interval = reporter.Time("BM_Baseline_FrameInterval5fps");
  for (const char* way :
       {"BM_LogAppendRaw", "BM_PngDefault", "BM_PngLevel0", "BM_PngLevel1", "BM_TiffNone",
        "BM_TiffLzw", "BM_PngUnfiltered0", "BM_PngUnfiltered1", "BM_PngHuffmanOnly"}) {
    const double t = reporter.Time(way);
    if (t > 0 && interval > 0) {
      std::printf("%-16s %7.1f ms = %.2f of the 5 fps frame interval (%s)\n", way + 3, t,
                  t / interval, t < interval ? "keeps up" : "falls behind");
    }
  }
  return 0;
}
