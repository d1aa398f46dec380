// Flattening and restoration of one measured page (default rig, curled checkerboard page,
// 45 x 45 sheet), beside CGAL's ARAP parameterisation of the same sheet (the peer) in one run.
//
//   ./build/bench/flatten_bench
#include <benchmark/benchmark.h>

#include <Eigen/CholmodSupport>
#include <Eigen/SparseCholesky>
#include <cstdio>
#include <map>
#include <memory>

#include "bench/ratio_reporter.h"
#include "core/decode/decode.h"
#include "core/flatten/flatten.h"
#include "core/flatten/frontal_cholesky.h"
#include "core/geometry/triangulate.h"
#include "core/restore/restore.h"
#include "core/sim/evaluate.h"

#ifdef VELLUM_WITH_CGAL
#include <CGAL/Polygon_mesh_processing/measure.h>
#include <CGAL/Simple_cartesian.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_parameterization/ARAP_parameterizer_3.h>
#include <CGAL/Surface_mesh_parameterization/parameterize.h>
#endif

namespace vellum {
namespace {

struct Fixture {
  Fixture() {
    SimulatedScan scan = SimulateScan(DefaultRig(), PageShape::kCurl, 5);
    gantry = std::move(scan.gantry);
    texture = scan.texture;
    const Triangulator tri(gantry->rig());
    const PointMap map = tri.Triangulate(Decode(scan.sequence, scan.frames));
    const cv::Mat page_mask = SegmentPage(texture);
    auto project = [&](const cv::Vec3d& x) { return gantry->rig().camera.Project(x); };
    mesh = BuildMesh(map.points, page_mask, MeshOptions(), project);
    MeshOptions fine;
    fine.grid = {200, 150};
    fine_mesh = BuildMesh(map.points, page_mask, fine, project);
    fine.grid = {300, 300};
    finest_mesh = BuildMesh(map.points, page_mask, fine, project);
    flat = Flatten(mesh);
  }
  std::unique_ptr<VirtualGantry> gantry;
  cv::Mat texture;
  Mesh mesh, fine_mesh, finest_mesh;
  FlattenResult flat;
};

Fixture& Shared() {
  static Fixture f;
  return f;
}

void Record(benchmark::State& state, const std::vector<cv::Point2d>& flat) {
  const FlatErrorStats s = CompareFlat(Shared().gantry->truth(), Shared().mesh, flat);
  state.counters["rms_mm"] = s.rms_mm;
  state.counters["edge_err_pct"] = 100 * s.mean_edge_error;
}

void BM_Vellum_GaussNewton_45x45(benchmark::State& state) {
  Fixture& f = Shared();
  FlattenResult r;
  for (auto _ : state) r = Flatten(f.mesh);
  Record(state, r.flat);
  state.counters["iterations"] = r.iterations;
}

void BM_Vellum_GaussNewton_200x150(benchmark::State& state) {
  Fixture& f = Shared();
  FlattenResult r;
  for (auto _ : state) r = Flatten(f.fine_mesh);
  const FlatErrorStats s = CompareFlat(f.gantry->truth(), f.fine_mesh, r.flat);
  state.counters["rms_mm"] = s.rms_mm;
  state.counters["iterations"] = r.iterations;
  state.counters["folds"] = r.folded_quads;
}

// The factorisation alone: the Gauss-Newton normal equations J^T J + 1e-6 I of the 200 x 150
// sheet (springs' directions from the measured points), by our multifrontal Cholesky over the
// grid's nested dissection, and by Eigen's SimplicialLDLT (its AMD ordering) as the baseline.
struct NormalEquations {
  explicit NormalEquations(const Mesh& mesh) {
    std::vector<int> order;
    fronts = DissectGrid(
        mesh.cols, mesh.rows, 1, [&](int k) { return mesh.Active(k); }, &order);
    std::vector<int> var(mesh.kind.size(), -1);
    for (size_t v = 0; v < order.size(); ++v) var[order[v]] = static_cast<int>(v);
    const int n = static_cast<int>(order.size());
    std::vector<Eigen::Triplet<double>> graph_t, full_t;
    for (const Spring& s : mesh.springs) {
      const int a = var[s.a], b = var[s.b];
      cv::Vec2d u(mesh.point[s.a][0] - mesh.point[s.b][0], mesh.point[s.a][1] - mesh.point[s.b][1]);
      u /= cv::norm(u);
      graph_t.emplace_back(std::max(a, b), std::min(a, b), 1.0);
      for (int p = 0; p < 2; ++p) {
        for (int q = 0; q < 2; ++q) {
          const double uu = u[p] * u[q];
          full_t.emplace_back(2 * a + p, 2 * a + q, uu);
          full_t.emplace_back(2 * b + p, 2 * b + q, uu);
          full_t.emplace_back(2 * a + p, 2 * b + q, -uu);
          full_t.emplace_back(2 * b + p, 2 * a + q, -uu);
        }
      }
    }
    for (int v = 0; v < n; ++v) graph_t.emplace_back(v, v, 1.0);
    for (int k = 0; k < 2 * n; ++k) full_t.emplace_back(k, k, 1e-6);
    graph.resize(n, n);
    graph.setFromTriplets(graph_t.begin(), graph_t.end());
    graph.makeCompressed();
    full.resize(2 * n, 2 * n);
    full.setFromTriplets(full_t.begin(), full_t.end());
    for (int c = 0; c < n; ++c) {
      for (Eigen::SparseMatrix<double>::InnerIterator it(graph, c); it; ++it) {
        for (int q = 0; q < 4; ++q)
          blocks.push_back(full.coeff(2 * it.row() + q % 2, 2 * c + q / 2));
      }
    }
    rhs = Eigen::VectorXd::Random(2 * n);
  }
  std::vector<Front> fronts;
  Eigen::SparseMatrix<double> graph, full;
  std::vector<double> blocks;
  Eigen::VectorXd rhs;
};

NormalEquations& FineSystem() {
  static NormalEquations system(Shared().fine_mesh);
  return system;
}

// The sheets of the factorisation comparison: 45 x 45 (the paper's), 200 x 150, 300 x 300.
NormalEquations& System(int k) {
  static NormalEquations coarse(Shared().mesh), finest(Shared().finest_mesh);
  return k == 0 ? coarse : k == 1 ? FineSystem() : finest;
}
const char* const kSheets[] = {"45x45", "200x150", "300x300"};

// Our multifrontal Cholesky of the normal equations (symbolic analysis once, as the solver does).
void BM_Factor_Frontal(benchmark::State& state) {
  NormalEquations& sys = System(static_cast<int>(state.range(0)));
  FrontalCholesky chol;
  if (!chol.Analyze(sys.graph, sys.fronts, 2).ok()) state.SkipWithError("analysis failed");
  for (auto _ : state) {
    if (!chol.Factorize(sys.blocks)) state.SkipWithError("not positive definite");
  }
  Eigen::MatrixXd x = sys.rhs;
  chol.Solve(&x);
  state.counters["residual"] = (sys.full * x - sys.rhs).norm() / sys.rhs.norm();
  state.counters["unknowns"] = static_cast<double>(sys.rhs.size());
  state.SetLabel(kSheets[state.range(0)]);
}

// CHOLMOD's supernodal Cholesky (SuiteSparse, through Eigen's CholmodSupport) of the same
// matrices, in its own fill-reducing order; symbolic analysis once, as for ours.
void BM_Factor_CholmodSupernodal(benchmark::State& state) {
  NormalEquations& sys = System(static_cast<int>(state.range(0)));
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> llt;
  llt.analyzePattern(sys.full);
  for (auto _ : state) {
    llt.factorize(sys.full);
    if (llt.info() != Eigen::Success) state.SkipWithError("CHOLMOD failed");
  }
  const Eigen::VectorXd x = llt.solve(sys.rhs);
  state.counters["residual"] = (sys.full * x - sys.rhs).norm() / sys.rhs.norm();
  state.counters["unknowns"] = static_cast<double>(sys.rhs.size());
  state.SetLabel(kSheets[state.range(0)]);
}

void BM_Factor_Frontal_200x150(benchmark::State& state) {
  NormalEquations& sys = FineSystem();
  FrontalCholesky chol;
  if (!chol.Analyze(sys.graph, sys.fronts, 2).ok()) state.SkipWithError("analysis failed");
  for (auto _ : state) {
    if (!chol.Factorize(sys.blocks)) state.SkipWithError("not positive definite");
  }
  Eigen::MatrixXd x = sys.rhs;
  chol.Solve(&x);
  state.counters["residual"] = (sys.full * x - sys.rhs).norm() / sys.rhs.norm();
}

void BM_Factor_EigenSimplicialLDLT_200x150(benchmark::State& state) {
  NormalEquations& sys = FineSystem();
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt;
  ldlt.analyzePattern(sys.full);
  for (auto _ : state) ldlt.factorize(sys.full);
  const Eigen::VectorXd x = ldlt.solve(sys.rhs);
  state.counters["residual"] = (sys.full * x - sys.rhs).norm() / sys.rhs.norm();
}

void BM_Vellum_Simulator_45x45(benchmark::State& state) {
  Fixture& f = Shared();
  FlattenOptions o;
  o.solver = state.range(0) == 0 ? FlattenSolver::kEuler : FlattenSolver::kRungeKutta4;
  FlattenResult r;
  for (auto _ : state) r = Flatten(f.mesh, o);
  Record(state, r.flat);
  state.counters["steps"] = r.iterations;
  state.SetLabel(ToString(o.solver));
}

void BM_Vellum_Restore_200dpi(benchmark::State& state) {
  Fixture& f = Shared();
  RestoreOptions o;
  o.dpi = 200;
  RestoreResult r;
  for (auto _ : state) r = Restore(f.texture, f.mesh, f.flat.flat, f.gantry->rig().camera, o);
  state.counters["megapixels"] = r.image.total() / 1e6;
}

#ifdef VELLUM_WITH_CGAL
// CGAL's ARAP parameterisation of the same sheet (its quads split into triangles), the
// texture-mapping peer: time, and the same accuracy measures on its (u, v) as flat mm.
void BM_CGAL_ARAP_45x45(benchmark::State& state) {
  using K = CGAL::Simple_cartesian<double>;
  using SM = CGAL::Surface_mesh<K::Point_3>;
  namespace SMP = CGAL::Surface_mesh_parameterization;
  Fixture& f = Shared();
  SM sm;
  std::vector<SM::Vertex_index> vid(f.mesh.kind.size());
  for (size_t k = 0; k < f.mesh.kind.size(); ++k) {
    if (!f.mesh.Active(static_cast<int>(k))) continue;
    const cv::Vec3d& p = f.mesh.point[k];
    vid[k] = sm.add_vertex(K::Point_3(p[0], p[1], p[2]));
  }
  for (const cv::Vec4i& q : f.mesh.quads) {
    // Counter-clockwise seen from above (image order is clockwise from above).
    sm.add_face(vid[q[0]], vid[q[3]], vid[q[2]]);
    sm.add_face(vid[q[0]], vid[q[2]], vid[q[1]]);
  }
  const auto border = CGAL::Polygon_mesh_processing::longest_border(sm).first;
  std::vector<cv::Point2d> flat(f.mesh.kind.size(), cv::Point2d(0, 0));
  for (auto _ : state) {
    auto uv = sm.add_property_map<SM::Vertex_index, K::Point_2>("h:uv").first;
    const SMP::Error_code err = SMP::parameterize(sm, SMP::ARAP_parameterizer_3<SM>(), border, uv);
    if (err != SMP::OK) state.SkipWithError("CGAL parameterisation failed");
    for (size_t k = 0; k < f.mesh.kind.size(); ++k) {
      if (f.mesh.Active(static_cast<int>(k))) flat[k] = cv::Point2d(uv[vid[k]].x(), uv[vid[k]].y());
    }
    sm.remove_property_map(uv);
  }
  Record(state, flat);
}
BENCHMARK(BM_CGAL_ARAP_45x45)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.5)
    ->Apply(Repeated);
#endif

BENCHMARK(BM_Vellum_GaussNewton_45x45)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.5)
    ->Apply(Repeated);
BENCHMARK(BM_Vellum_GaussNewton_200x150)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3)
    ->Apply(Repeated);
BENCHMARK(BM_Factor_Frontal_200x150)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.3)
    ->Apply(Repeated);
BENCHMARK(BM_Factor_EigenSimplicialLDLT_200x150)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.3)
    ->Apply(Repeated);
BENCHMARK(BM_Factor_Frontal)
    ->DenseRange(0, 2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.3)
    ->Apply(Repeated);
BENCHMARK(BM_Factor_CholmodSupernodal)
    ->DenseRange(0, 2)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.3)
    ->Apply(Repeated);
BENCHMARK(BM_Vellum_Simulator_45x45)
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3)
    ->Apply(Repeated);
BENCHMARK(BM_Vellum_Restore_200dpi)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.5)
    ->Apply(Repeated);

}  // namespace
}  // namespace vellum

int main(int argc, char** argv) {
  vellum::InitializeInterleaved(&argc, &argv);
  vellum::RatioReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  reporter.PrintRatio("BM_Vellum_GaussNewton_45x45", "vellum gauss-newton 45x45",
                      "BM_CGAL_ARAP_45x45", "CGAL ARAP");
  reporter.PrintRatio("BM_Factor_Frontal_200x150", "vellum frontal factor 200x150",
                      "BM_Factor_EigenSimplicialLDLT_200x150", "Eigen SimplicialLDLT");
  for (int k = 0; k < 3; ++k) {
    const std::string arg = "/" + std::to_string(k) + "/";
    reporter.PrintRatio("BM_Factor_Frontal" + arg,
                        std::string("vellum frontal factor ") + vellum::kSheets[k],
                        "BM_Factor_CholmodSupernodal" + arg, "CHOLMOD supernodal");
  }
  benchmark::Shutdown();
  return 0;
}
