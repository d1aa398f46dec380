// What the albedo adds to the restore stage, on a 1600 x 1200 scan (default rig, a
// plain curled leaf under the projector's real fall-off), beside the plain restoration in the
// same run: the baseline restores the texture through the flattened sheet (with the leaf's mask
// and the sampling map, as the pipeline's restore stage does); the albedo adds the normals, the
// albedo of every leaf pixel and two more restorations through the same sheet (the albedo and
// its validity); two extra textures (raking lights) go through the texture's own warp. The
// issue's bar: albedo and two extra textures add at most 50% to the restore stage: measured
// both on the bare warp and on the pipeline's stages (which write their files), as report.json
// times them.
//
//   ./build/bench/albedo_bench
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>

#include "bench/ratio_reporter.h"
#include "core/decode/decode.h"
#include "core/flatten/flatten.h"
#include "core/geometry/triangulate.h"
#include "core/mesh/mesh.h"
#include "core/outline/outline.h"
#include "core/restore/restore.h"
#include "core/shading/albedo.h"
#include "core/sim/evaluate.h"
#include "pipeline/stages.h"

namespace vellum {
namespace {

struct Fixture {
  Fixture() {
    LightOptions light;
    light.projector_falloff = true;
    TextureOptions plain;
    plain.kind = TextureKind::kPlain;
    PageOptions target;
    target.size_mm = {420, 320};
    const SimulatedScan white =
        SimulateScan(DefaultRig(), target, plain, SceneOptions(), 41, light);
    const DecodeResult wd = Decode(white.sequence, white.frames);
    Status s = Status::Ok();
    FlatFieldOptions fo;
    fo.target_albedo = plain.paper_albedo;
    field = MeasureFlatField(wd.amplitude, Triangulator(DefaultRig()).Triangulate(wd).points,
                             DefaultRig(), fo, &s);
    PageOptions page;
    page.shape = PageShape::kCurl;
    const SimulatedScan scan = SimulateScan(DefaultRig(), page, plain, SceneOptions(), 5, light);
    texture = scan.texture;
    for (const ScanLight& l : RenderLights(*scan.gantry, RakingLights(2), 5)) {
      lights.push_back(l.image);
    }
    const DecodeResult decoded = Decode(scan.sequence, scan.frames);
    amplitude = decoded.amplitude;
    points = Triangulator(DefaultRig()).Triangulate(decoded).points;
    const Calibration rig = DefaultRig();
    leaf = FindLeaf(points, texture, OutlineOptions(), &rig).mask;
    const CameraModel& camera = DefaultRig().camera;
    mesh = BuildMesh(points, leaf, MeshOptions(),
                     [&](const cv::Vec3d& x) { return camera.Project(x); });
    flattened = Flatten(mesh, FlattenOptions());
    flat = flattened.flat;
  }
  FlatField field;
  cv::Mat texture, amplitude, points, leaf;
  std::vector<cv::Mat> lights;  // Two raking lights' images.
  Mesh mesh;
  FlattenResult flattened;
  std::vector<cv::Point2d> flat;  // flattened.flat
};

Fixture& Shared() {
  static Fixture f;
  return f;
}

void BM_Baseline_RestoreTexture(benchmark::State& state) {
  const Fixture& f = Shared();
  for (auto _ : state) {
    const RestoreResult r =
        Restore(f.texture, f.mesh, f.flat, DefaultRig().camera, RestoreOptions(), f.leaf);
    if (!r.status.ok()) state.SkipWithError(r.status.message().c_str());
    benchmark::DoNotOptimize(r.image.data);
  }
}

void BM_Vellum_RestoreTextureAndAlbedo(benchmark::State& state) {
  const Fixture& f = Shared();
  const CameraModel& camera = DefaultRig().camera;
  for (auto _ : state) {
    const RestoreResult r = Restore(f.texture, f.mesh, f.flat, camera, RestoreOptions(), f.leaf);
    const AlbedoResult a = EstimateAlbedo(f.amplitude, f.points, f.leaf, DefaultRig(), f.field);
    if (!r.status.ok() || !a.status.ok()) state.SkipWithError("restore or albedo failed");
    // Through the texture's own warp, its marks with it, as the pipeline's albedo stage does it.
    std::vector<cv::Mat> out;
    if (!RestoreMore(r, {MarkedAsNaN(a)}, &out, std::nan("")).ok())
      state.SkipWithError("RestoreMore failed");
    benchmark::DoNotOptimize(out.back().data);
  }
}

// Two extra textures (raking lights) restored with the texture, through one warp.
void BM_Vellum_RestoreTextureAndTwoLights(benchmark::State& state) {
  const Fixture& f = Shared();
  for (auto _ : state) {
    const RestoreResult r =
        Restore(f.texture, f.mesh, f.flat, DefaultRig().camera, RestoreOptions(), f.leaf, f.lights);
    if (!r.status.ok()) state.SkipWithError(r.status.message().c_str());
    benchmark::DoNotOptimize(r.extras.back().data);
  }
}

// The albedo and two extra textures with the texture, as the pipeline does it: the extras
// through the texture's own warp (RestoreMore).
void BM_Vellum_RestoreTextureAlbedoAndTwoLights(benchmark::State& state) {
  const Fixture& f = Shared();
  const CameraModel& camera = DefaultRig().camera;
  for (auto _ : state) {
    const RestoreResult r = Restore(f.texture, f.mesh, f.flat, camera, RestoreOptions(), f.leaf);
    const AlbedoResult a = EstimateAlbedo(f.amplitude, f.points, f.leaf, DefaultRig(), f.field);
    if (!r.status.ok() || !a.status.ok()) state.SkipWithError("restore or albedo failed");
    std::vector<cv::Mat> more = f.lights;
    more.push_back(MarkedAsNaN(a));
    std::vector<cv::Mat> out;
    if (!RestoreMore(r, more, &out).ok()) state.SkipWithError("RestoreMore failed");
    benchmark::DoNotOptimize(out.back().data);
  }
}

// Our bar as the pipeline's report states stage times: the restore stage (the warp, and
// writing the page's masters, pyramid, sampling map and pictures) alone, and with the albedo
// and lights stages for two raking lights (each image restored and written as its TIFF).
std::string BenchDir() {
  return (std::filesystem::temp_directory_path() / ("albedo_bench_" + std::to_string(getpid())))
      .string();
}

// The fixture as the pipeline holds a scan and its one page, with the lights given.
ScanWork FixtureWork(const Fixture& f, const std::string& dir, PageResult* page,
                     const std::vector<ScanLight>& lights = {}) {
  ScanWork work;
  work.scan.texture = f.texture;
  work.scan.lights = lights;
  work.calibration = DefaultRig();
  work.amplitude = f.amplitude;
  work.map.points = f.points;
  work.results = dir;
  page->mask = f.leaf;
  page->mesh = f.mesh;
  page->flat = f.flattened;
  return work;
}

RestoreResult RunRestoreStage(const Fixture& f, const std::string& dir) {
  PageResult page;
  const ScanWork work = FixtureWork(f, dir, &page);
  const StageReport r = RestoreStage(work, PipelineOptions(), &page);
  if (!r.status.ok()) page.restored.status = r.status;
  return page.restored;
}

void BM_Baseline_RestoreStage(benchmark::State& state) {
  const Fixture& f = Shared();
  const std::string dir = BenchDir();
  for (auto _ : state) {
    const RestoreResult restored = RunRestoreStage(f, dir);
    if (!restored.status.ok()) state.SkipWithError(restored.status.message().c_str());
  }
  std::filesystem::remove_all(dir);
}

void BM_Vellum_RestoreStageAlbedoAndTwoLights(benchmark::State& state) {
  const Fixture& f = Shared();
  const std::string dir = BenchDir();
  std::vector<ScanLight> lights(2);
  for (size_t k = 0; k < 2; ++k) {
    lights[k].name = "raking-" + std::to_string(k);
    lights[k].image = f.lights[k];
  }
  double albedo_s = 0, lights_s = 0;
  int runs = 0;
  for (auto _ : state) {
    PageResult page;
    const ScanWork work = FixtureWork(f, dir, &page, lights);
    PipelineOptions options;
    options.flat_field = f.field;
    const StageReport r = RestoreStage(work, options, &page);
    const RestoreResult& restored = page.restored;
    if (!r.status.ok()) state.SkipWithError(r.status.message().c_str());
    const StageReport a = AlbedoStage(work, options, &page);
    const StageReport l = LightsStage(work, options, &page);
    if (!restored.status.ok() || !a.status.ok() || !l.status.ok()) {
      state.SkipWithError("a stage failed");
    }
    albedo_s += a.seconds;
    lights_s += l.seconds;
    ++runs;
  }
  state.counters["albedo_stage_ms"] = 1e3 * albedo_s / std::max(1, runs);
  state.counters["lights_stage_ms"] = 1e3 * lights_s / std::max(1, runs);
  std::filesystem::remove_all(dir);
}

// The albedo of every leaf pixel alone (the normals included), without restoring it.
void BM_Vellum_EstimateAlbedo(benchmark::State& state) {
  const Fixture& f = Shared();
  for (auto _ : state) {
    const AlbedoResult a = EstimateAlbedo(f.amplitude, f.points, f.leaf, DefaultRig(), f.field);
    if (!a.status.ok()) state.SkipWithError(a.status.message().c_str());
    benchmark::DoNotOptimize(a.albedo.data);
  }
}

BENCHMARK(BM_Baseline_RestoreTexture)->Unit(benchmark::kMillisecond)->MinTime(0.5)->Apply(Repeated);
BENCHMARK(BM_Vellum_RestoreTextureAndAlbedo)
    ->Unit(benchmark::kMillisecond)
    ->MinTime(0.5)
    ->Apply(Repeated);
BENCHMARK(BM_Vellum_RestoreTextureAndTwoLights)
    ->Unit(benchmark::kMillisecond)
    ->MinTime(0.5)
    ->Apply(Repeated);
BENCHMARK(BM_Vellum_RestoreTextureAlbedoAndTwoLights)
    ->Unit(benchmark::kMillisecond)
    ->MinTime(0.5)
    ->Apply(Repeated);
BENCHMARK(BM_Baseline_RestoreStage)->Unit(benchmark::kMillisecond)->MinTime(0.5)->Apply(Repeated);
BENCHMARK(BM_Vellum_RestoreStageAlbedoAndTwoLights)
    ->Unit(benchmark::kMillisecond)
    ->MinTime(0.5)
    ->Apply(Repeated);
BENCHMARK(BM_Vellum_EstimateAlbedo)->Unit(benchmark::kMillisecond)->MinTime(0.5)->Apply(Repeated);

}  // namespace
}  // namespace vellum

int main(int argc, char** argv) {
  vellum::InitializeInterleaved(&argc, &argv);
  vellum::RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  const double base = reporter.Time("BM_Baseline_RestoreTexture");
  const double with = reporter.Time("BM_Vellum_RestoreTextureAndAlbedo");
  const double stage = reporter.Time("BM_Baseline_RestoreStage");
  const double stages = reporter.Time("BM_Vellum_RestoreStageAlbedoAndTwoLights");
  if (stage > 0 && stages > 0) {
    std::printf(
        "the restore stage %.1f ms; with the albedo and lights stages (two raking lights) %.1f "
        "ms: +%.0f%% (bar: +50%%)\n",
        stage, stages, 100 * (stages / stage - 1));
  }
  const double lights = reporter.Time("BM_Vellum_RestoreTextureAndTwoLights");
  const double all = reporter.Time("BM_Vellum_RestoreTextureAlbedoAndTwoLights");
  if (base > 0 && with > 0 && lights > 0 && all > 0) {
    std::printf(
        "restore %.1f ms; with the albedo %.1f ms (+%.0f%%); with two extra textures %.1f ms "
        "(+%.0f%%); with both %.1f ms: +%.0f%% (bar: +50%%)\n",
        base, with, 100 * (with / base - 1), lights, 100 * (lights / base - 1), all,
        100 * (all / base - 1));
  }
  benchmark::Shutdown();
  return 0;
}
