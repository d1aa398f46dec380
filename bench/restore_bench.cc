// Restoring a 24 MP texture to a 400 ppi page. The rig is config/hires_rig.yaml's
// (6000 x 4000 camera, 0.0635 mm per pixel on the table); the page a 190 x 240 mm leaf curled
// (the virtual gantry's curl), its sheet 90 x 90 nodes placed on the true surface and its flat
// positions the true page coordinates, so the benchmark times the restoration alone. The peer is
// OpenCV's cv::remap of an output of the same size from maps computed beforehand (bilinear): the
// least work any warp of that output must do; vellum's restoration also works out its maps (one
// affine map per triangle), supersamples where the warp shrinks, restores the leaf's mask and
// the true sampling map.
#include <benchmark/benchmark.h>

#include <opencv2/imgproc.hpp>

#include "bench/ratio_reporter.h"
#include "core/restore/restore.h"
#include "core/sim/page.h"
#include "io/calibration_io.h"

namespace {

using namespace vellum;

struct Setup {
  Calibration rig;
  cv::Mat texture, leaf;
  Mesh mesh;
  std::vector<cv::Point2d> flat;
  RestoreOptions options;
  cv::Mat map_x, map_y;  // The peer's maps, for the same output as Restore's.
};

const Setup& Get() {
  static const Setup setup = [] {
    Setup s;
    if (!ReadCalibration(std::string(VELLUM_SOURCE_DIR) + "/config/hires_rig.yaml", &s.rig).ok())
      std::abort();
    PageOptions po;
    po.shape = PageShape::kCurl;
    const Page page(po);
    const cv::Size2d size = po.size_mm;
    Mesh& m = s.mesh;
    m.cols = m.rows = 90;
    for (int j = 0; j < m.rows; ++j) {
      for (int i = 0; i < m.cols; ++i) {
        const double u = size.width * i / (m.cols - 1), v = size.height * j / (m.rows - 1);
        const cv::Vec3d x = page.Point(u, v);
        m.kind.push_back(NodeKind::kMeasured);
        m.point.push_back(x);
        m.pixel.push_back(s.rig.camera.Project(x));
        s.flat.emplace_back(u, v);
      }
    }
    for (int j = 0; j + 1 < m.rows; ++j) {
      for (int i = 0; i + 1 < m.cols; ++i) {
        m.quads.emplace_back(m.Index(i, j), m.Index(i + 1, j), m.Index(i + 1, j + 1),
                             m.Index(i, j + 1));
      }
    }
    m.measured = m.cols * m.rows;
    m.status = Status::Ok();
    s.texture.create(s.rig.camera.size, CV_8UC3);
    cv::randu(s.texture, cv::Scalar::all(0), cv::Scalar::all(255));
    s.leaf = cv::Mat(s.rig.camera.size, CV_8U, cv::Scalar(255));
    s.options.dpi = 400;
    s.options.deskew = true;
    s.options.crop_to_leaf = true;
    // The peer's maps, for an output of Restore's size: a plain scaling onto the camera image,
    // which reads the texture as locally as the page's warp does.
    const RestoreResult probe = Restore(s.texture, s.mesh, s.flat, s.rig.camera, s.options);
    s.map_x.create(probe.image.size(), CV_32F);
    s.map_y.create(probe.image.size(), CV_32F);
    for (int y = 0; y < s.map_x.rows; ++y) {
      for (int x = 0; x < s.map_x.cols; ++x) {
        s.map_x.at<float>(y, x) = static_cast<float>(x) * s.rig.camera.size.width / s.map_x.cols;
        s.map_y.at<float>(y, x) = static_cast<float>(y) * s.rig.camera.size.height / s.map_x.rows;
      }
    }
    return s;
  }();
  return setup;
}

void BM_Peer_OpenCvRemap(benchmark::State& state) {
  const Setup& s = Get();
  cv::Mat out;
  for (auto _ : state) cv::remap(s.texture, out, s.map_x, s.map_y, cv::INTER_LINEAR);
  state.counters["out_MP"] = out.total() / 1e6;
}

void BM_Vellum_Restore24MpAt400Ppi(benchmark::State& state) {
  const Setup& s = Get();
  RestoreResult r;
  for (auto _ : state) r = Restore(s.texture, s.mesh, s.flat, s.rig.camera, s.options, s.leaf);
  state.counters["out_MP"] = r.image.total() / 1e6;
  state.counters["true_ppi_p95"] = r.finest_ppi;
}

}  // namespace

BENCHMARK(BM_Peer_OpenCvRemap)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.5)
    ->Apply(vellum::Repeated);
BENCHMARK(BM_Vellum_Restore24MpAt400Ppi)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.5)
    ->Apply(vellum::Repeated);

int main(int argc, char** argv) {
  vellum::InitializeInterleaved(&argc, &argv);
  vellum::RatioReporter reporter;
  Get();  // Set up before the clock runs.
  benchmark::RunSpecifiedBenchmarks(&reporter);
  const double t = reporter.Time("BM_Vellum_Restore24MpAt400Ppi");
  const double peer = reporter.Time("BM_Peer_OpenCvRemap");
  if (t > 0 && peer > 0) {
    std::printf(
        "restore 24 MP at 400 ppi: %.0f ms (our bar: under 1000 ms), %.1f times "
        "cv::remap's %.0f ms for an output of the same size\n",
        t, t / peer, peer);
  }
  return 0;
}
