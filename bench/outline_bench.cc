// Finding the leaf and building its sheet on a 1600x1200 scan (default rig, curled checkerboard
// leaf on the dark table), beside the baselines in the same run: the paper's brightness
// segmentation (SegmentPage) with the paper's 45 x 45 sheet, and FindLeaf as it stood before it
// became one cut over every cue (bench/baseline/outline_v1: the height flood, brightness as a
// fallback). The bars: the shape's way and its sheet add at most 50 ms to the paper's; finding
// the leaf by every cue at once takes at most 50 ms more than the height flood did. And the live
// outline on the viewer's preview beside the brightness rule it replaced: at most 50 ms.
//
//   ./build/bench/outline_bench
#include <benchmark/benchmark.h>

#include <cstdio>
#include <vector>

#include "bench/baseline/outline_v1.h"
#include "bench/ratio_reporter.h"
#include "core/decode/decode.h"
#include "core/geometry/triangulate.h"
#include "core/mesh/mesh.h"
#include "core/outline/outline.h"
#include "core/sim/evaluate.h"

namespace vellum {
namespace {

struct Fixture {
  Fixture() {
    const SimulatedScan scan = SimulateScan(DefaultRig(), PageShape::kCurl, 5);
    rig = scan.gantry->rig();
    texture = scan.texture;
    points = Triangulator(rig).Triangulate(Decode(scan.sequence, scan.frames)).points;
  }
  Calibration rig;
  cv::Mat texture, points;
};

Fixture& Shared() {
  static Fixture f;
  return f;
}

Mesh Sheet(const Fixture& f, const cv::Mat& mask, bool auto_grid) {
  auto project = [&](const cv::Vec3d& x) { return f.rig.camera.Project(x); };
  MeshOptions options;
  Mesh mesh = BuildMesh(f.points, mask, options, project);
  if (auto_grid && mesh.status.ok()) {
    // As the pipeline's mesh stage: finer where the warp would stray more than 0.05 px.
    const cv::Size grid = GridForError(mesh, 0.05);
    if (grid != options.grid) {
      options.grid = grid;
      mesh = BuildMesh(f.points, mask, options, project);
    }
  }
  return mesh;
}

void BM_Baseline_SegmentPage(benchmark::State& state) {
  const Fixture& f = Shared();
  for (auto _ : state) benchmark::DoNotOptimize(SegmentPage(f.texture).data);
}

void BM_Baseline_SegmentPage_Sheet45(benchmark::State& state) {
  const Fixture& f = Shared();
  for (auto _ : state) {
    const Mesh mesh = Sheet(f, SegmentPage(f.texture), false);
    if (!mesh.status.ok()) state.SkipWithError(mesh.status.message().c_str());
    benchmark::DoNotOptimize(mesh.point.data());
  }
}

void BM_Baseline_FindLeafV1(benchmark::State& state) {
  const Fixture& f = Shared();
  for (auto _ : state) {
    const baseline::Outline outline = baseline::FindLeaf(f.points, f.texture);
    if (!outline.status.ok()) state.SkipWithError(outline.status.message().c_str());
    benchmark::DoNotOptimize(outline.mask.data);
  }
}

void BM_Vellum_FindLeaf(benchmark::State& state) {
  const Fixture& f = Shared();
  for (auto _ : state) {
    const Outline outline = FindLeaf(f.points, f.texture, OutlineOptions(), &f.rig);
    if (!outline.status.ok()) state.SkipWithError(outline.status.message().c_str());
    benchmark::DoNotOptimize(outline.mask.data);
  }
}

void BM_Vellum_FindLeaf_SheetAuto(benchmark::State& state) {
  const Fixture& f = Shared();
  for (auto _ : state) {
    const Outline outline = FindLeaf(f.points, f.texture, OutlineOptions(), &f.rig);
    // The outline stage's check for a support taken for the leaf (leaf_ambiguous).
    benchmark::DoNotOptimize(HighestRaisedHole(f.points, outline.mask, 0.08).area_px);
    const Mesh mesh = Sheet(f, outline.pages.at(0), true);
    if (!mesh.status.ok()) state.SkipWithError(mesh.status.message().c_str());
    benchmark::DoNotOptimize(mesh.point.data());
  }
}

// The live outline on the preview (640 wide, as vellum-camera sends it): the brightness rule it was
// (SegmentPage), and LeafInPreview (core/outline/live.cc) as the viewer runs it on every preview.
void BM_Baseline_SegmentPage_Preview(benchmark::State& state) {
  const cv::Mat preview = PreviewOf(Shared().texture);
  for (auto _ : state) benchmark::DoNotOptimize(SegmentPage(preview).data);
}

void BM_Vellum_LeafInPreview(benchmark::State& state) {
  const cv::Mat preview = PreviewOf(Shared().texture);
  for (auto _ : state) benchmark::DoNotOptimize(LeafInPreview(preview).mask.data);
}

// Each benchmark is repeated, the repetitions of all interleaved in random order (main), and the
// medians compared: this machine is shared, and its speed drifts over a run.
void Timed(benchmark::internal::Benchmark* b) {
  b->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(0.4)->Apply(Repeated);
}
BENCHMARK(BM_Baseline_SegmentPage)->Apply(Timed);
BENCHMARK(BM_Baseline_SegmentPage_Sheet45)->Apply(Timed);
BENCHMARK(BM_Baseline_FindLeafV1)->Apply(Timed);
BENCHMARK(BM_Vellum_FindLeaf)->Apply(Timed);
BENCHMARK(BM_Vellum_FindLeaf_SheetAuto)->Apply(Timed);
BENCHMARK(BM_Baseline_SegmentPage_Preview)->Apply(Timed);
BENCHMARK(BM_Vellum_LeafInPreview)->Apply(Timed);

}  // namespace
}  // namespace vellum

int main(int argc, char** argv) {
  vellum::InitializeInterleaved(&argc, &argv);
  vellum::RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  const double base = reporter.Time("BM_Baseline_SegmentPage_Sheet45");
  const double ours = reporter.Time("BM_Vellum_FindLeaf_SheetAuto");
  if (base > 0 && ours > 0) {
    std::printf(
        "finding the leaf by its shape and its sheet (medians): %.1f ms against %.1f ms for the "
        "brightness "
        "rule and a 45x45 sheet: %.1f ms added (bar: 50 ms), ratio %.2fx\n",
        ours, base, ours - base, ours / base);
  }
  const double bright = reporter.Time("BM_Baseline_SegmentPage_Preview");
  const double live = reporter.Time("BM_Vellum_LeafInPreview");
  if (bright > 0 && live > 0) {
    std::printf(
        "the live outline on a 640x480 preview (medians): %.2f ms against %.2f ms for the "
        "brightness rule, ratio %.2fx (bar: 50 ms, a tenth of the 2 Hz preview's period)\n",
        live, bright, live / bright);
  }
  const double flood = reporter.Time("BM_Baseline_FindLeafV1");
  const double cut = reporter.Time("BM_Vellum_FindLeaf/");
  if (flood > 0 && cut > 0) {
    std::printf(
        "finding the leaf by every cue at once (medians): %.1f ms against %.1f ms for the height "
        "flood it replaced: %.1f ms added (bar: 50 ms), ratio %.2fx\n",
        cut, flood, cut - flood, cut / flood);
  }
  benchmark::Shutdown();
  return 0;
}
