// Decode + triangulation of one scan (a curled checkerboard page; the default 1600x1200 rig, or
// any rig file: config/hires_rig.yaml is the 24 MP camera), beside OpenCV's
// cv::structured_light::GrayCodePattern decoding the same page from its own Gray-code frames
// (same virtual gantry, same noise). The ratios are printed at the end of the run.
//
//   ./build/bench/decode_bench [--rig=config/hires_rig.yaml] [--benchmark_min_time=2]
#include <benchmark/benchmark.h>

#include <chrono>
#include <cstdio>
#include <map>
#include <memory>
#include <opencv2/core/utility.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/structured_light.hpp>

#include "bench/ratio_reporter.h"
#include "core/decode/decode.h"
#include "core/geometry/triangulate.h"
#include "core/sim/evaluate.h"
#include "io/calibration_io.h"

namespace vellum {
namespace {

// The rig of --rig=FILE, else the default.
Calibration& BenchRig() {
  static Calibration rig = DefaultRig();
  return rig;
}

// One rendered scan shared by every benchmark.
struct Fixture {
  Fixture() {
    SimulatedScan scan = SimulateScan(BenchRig(), PageShape::kCurl, 21);
    gantry = std::move(scan.gantry);
    sequence = scan.sequence;
    frames = std::move(scan.frames);
    triangulator = std::make_unique<Triangulator>(gantry->rig());
    cv::structured_light::GrayCodePattern::Params params;
    params.width = sequence.projector_size.width;
    params.height = sequence.projector_size.height;
    opencv = cv::structured_light::GrayCodePattern::create(params);
    std::vector<cv::Mat> patterns;
    opencv->generate(patterns);
    cv::Mat black, white;
    opencv->getImagesForShadowMasks(black, white);
    uint64_t seed = 1000;
    for (const cv::Mat& p : patterns) {
      cv::Mat gray = p.channels() == 1 ? p : cv::Mat();
      if (gray.empty()) cv::cvtColor(p, gray, cv::COLOR_BGR2GRAY);
      opencv_frames.push_back(gantry->RenderFrame(gray, ++seed));
    }
    auto to_gray = [](const cv::Mat& m) {
      cv::Mat g = m;
      if (m.channels() != 1) cv::cvtColor(m, g, cv::COLOR_BGR2GRAY);
      return g;
    };
    opencv_white = gantry->RenderFrame(to_gray(white), ++seed);
    opencv_black = gantry->RenderFrame(to_gray(black), ++seed);
  }
  std::unique_ptr<VirtualGantry> gantry;
  PatternSequence sequence;
  std::vector<cv::Mat> frames;
  std::unique_ptr<Triangulator> triangulator;
  cv::Ptr<cv::structured_light::GrayCodePattern> opencv;
  std::vector<cv::Mat> opencv_frames;
  cv::Mat opencv_white, opencv_black;
};

Fixture& Shared() {
  static Fixture f;
  return f;
}

void BM_Vellum_DecodeTriangulate(benchmark::State& state) {
  Fixture& f = Shared();
  // As a daemon runs: one Decoder and one result reused scan after scan. The first scan, which
  // also faults in their buffers (about 60 bytes per camera pixel: 1.5 GB at 24 MP), is timed
  // apart, as `first_scan_ms`: what a fresh `vellum process` pays.
  Decoder decoder;
  DecodeResult d;
  PointMap m;
  const auto first = std::chrono::steady_clock::now();
  decoder.Decode(f.sequence, f.frames, &d);
  f.triangulator->Triangulate(d, TriangulateOptions(), &m);
  state.counters["first_scan_ms"] =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - first).count();
  for (auto _ : state) {
    decoder.Decode(f.sequence, f.frames, &d);
    f.triangulator->Triangulate(d, TriangulateOptions(), &m);
    benchmark::DoNotOptimize(m.points.data);
  }
  state.counters["valid_px"] = m.valid;
  const PointErrorStats s = ComparePoints(f.gantry->truth(), m.points);
  state.counters["median_mm"] = s.median_mm;
  state.counters["rms_mm"] = s.rms_mm;
  state.counters["valid_frac"] = s.valid_fraction;
}

void BM_Vellum_Decode(benchmark::State& state) {
  Fixture& f = Shared();
  DecodeOptions options;
  options.use_phase = state.range(0) != 0;
  Decoder decoder(options);
  DecodeResult d;
  for (auto _ : state) {
    decoder.Decode(f.sequence, f.frames, &d);
    benchmark::DoNotOptimize(d.projector_x.data);
  }
  state.SetLabel(options.use_phase ? "gray+phase" : "gray only");
}

// OpenCV's decoder as its API offers it for a projector-camera pair: a shadow mask from the
// white/black frames, then getProjPixel per camera pixel. Arg = threads: 1 is the API as it
// ships (a serial loop), 2 spreads the loop over both cores with parallel_for_.
void BM_OpenCV_GrayCodeDecode(benchmark::State& state) {
  Fixture& f = Shared();
  const int threads_before = cv::getNumThreads();
  cv::setNumThreads(static_cast<int>(state.range(0)));
  const cv::Size size = f.opencv_white.size();
  cv::Mat proj_x(size, CV_32F), proj_y(size, CV_32F);
  const int black_threshold = 5;  // OpenCV's default shadow threshold.
  for (auto _ : state) {
    cv::parallel_for_(cv::Range(0, size.height), [&](const cv::Range& range) {
      for (int y = range.start; y < range.end; ++y) {
        for (int x = 0; x < size.width; ++x) {
          float px = NAN, py = NAN;
          if (f.opencv_white.at<uint8_t>(y, x) - f.opencv_black.at<uint8_t>(y, x) >
              black_threshold) {
            cv::Point p;
            // getProjPixel returns true on error.
            if (!f.opencv->getProjPixel(f.opencv_frames, x, y, p)) {
              px = static_cast<float>(p.x);
              py = static_cast<float>(p.y);
            }
          }
          proj_x.at<float>(y, x) = px;
          proj_y.at<float>(y, x) = py;
        }
      }
    });
    benchmark::DoNotOptimize(proj_x.data);
  }
  cv::setNumThreads(threads_before);
  // Accuracy of OpenCV's integer decode through our triangulation, for the record.
  DecodeResult d;
  d.status = Status::Ok();
  d.has_columns = d.has_rows = true;
  d.projector_x = proj_x;
  d.projector_y = proj_y;
  d.valid = proj_x == proj_x;
  const PointErrorStats s = ComparePoints(f.gantry->truth(), f.triangulator->Triangulate(d).points);
  state.counters["median_mm"] = s.median_mm;
  state.counters["rms_mm"] = s.rms_mm;
  state.counters["valid_frac"] = s.valid_fraction;
}

BENCHMARK(BM_Vellum_DecodeTriangulate)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.5)
    ->Apply(Repeated);
BENCHMARK(BM_Vellum_Decode)
    ->Arg(1)
    ->Arg(0)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.5)
    ->Apply(Repeated);
BENCHMARK(BM_OpenCV_GrayCodeDecode)
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.5)
    ->Apply(Repeated);

}  // namespace
}  // namespace vellum

int main(int argc, char** argv) {
  vellum::InitializeInterleaved(&argc, &argv);
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg.rfind("--rig=", 0) != 0) {
      std::fprintf(stderr, "decode_bench: unknown argument %s (--rig=FILE, --benchmark_*)\n",
                   argv[i]);
      return 2;
    }
    const vellum::Status s = vellum::ReadCalibration(arg.substr(6), &vellum::BenchRig());
    if (!s.ok()) {
      std::fprintf(stderr, "decode_bench: %s\n", s.message().c_str());
      return 2;
    }
  }
  const cv::Size camera = vellum::BenchRig().camera.size;
  std::printf("threads: %d (cv::getNumThreads); camera %dx%d\n", cv::getNumThreads(), camera.width,
              camera.height);
  vellum::RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  for (int threads : {1, 2}) {
    reporter.PrintRatio("BM_Vellum_DecodeTriangulate", "vellum decode+triangulate",
                        "BM_OpenCV_GrayCodeDecode/" + std::to_string(threads) + "/",
                        "OpenCV decode alone on " + std::to_string(threads) +
                            (threads > 1 ? " threads" : " thread"));
  }
  benchmark::Shutdown();
  return 0;
}
