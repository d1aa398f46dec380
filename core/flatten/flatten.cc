#include "core/flatten/flatten.h"

#include <Eigen/SparseCore>
#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>

#include "core/common/check.h"
#include "core/flatten/frontal_cholesky.h"
#include "core/geometry/rigid2d.h"

namespace vellum {
namespace {

// Active nodes get consecutive variable indices, in nested-dissection order over the grid;
// `fronts` is the elimination tree of that order for the solvers' factorisations.
struct Indexing {
  explicit Indexing(const Mesh& mesh) : var(mesh.kind.size(), -1) {
    int span = 1;
    for (const Spring& s : mesh.springs) {
      span = std::max({span, std::abs(s.a % mesh.cols - s.b % mesh.cols),
                       std::abs(s.a / mesh.cols - s.b / mesh.cols)});
    }
    fronts = DissectGrid(
        mesh.cols, mesh.rows, span, [&](int k) { return mesh.Active(k); }, &node);
    for (size_t v = 0; v < node.size(); ++v) var[node[v]] = static_cast<int>(v);
  }
  std::vector<int> var;   // Node -> variable (-1: inactive).
  std::vector<int> node;  // Variable -> node.
  std::vector<Front> fronts;
};

// Rotates and translates flat positions onto the nodes' original (x, y) (least squares,
// no reflection, no scale), so the flat page lies where the page was and is never mirrored.
void AlignToOriginal(const Mesh& mesh, const Indexing& idx, std::vector<cv::Point2d>* flat) {
  std::vector<cv::Point2d> from, to;
  for (int k : idx.node) {
    from.push_back((*flat)[k]);
    to.emplace_back(mesh.point[k][0], mesh.point[k][1]);
  }
  const Rigid2D r = FitRigid2D(from, to);
  for (int k : idx.node) (*flat)[k] = r.Apply((*flat)[k]);
}

// The springs' energy at positions y (x, y of each variable): the sum of squared length errors.
double SpringEnergy(const Mesh& mesh, const Indexing& idx, const Eigen::VectorXd& y) {
  double e = 0;
  for (const Spring& s : mesh.springs) {
    const int a = idx.var[s.a], b = idx.var[s.b];
    const double dx = y[2 * a] - y[2 * b], dy = y[2 * a + 1] - y[2 * b + 1];
    const double r = std::sqrt(dx * dx + dy * dy) - s.rest_mm;
    e += r * r;
  }
  return e;
}

constexpr double kProximal = 1e-6;  // Proximal term: fixes the rigid-motion gauge without bias.

// The sheet's graph as a lower-triangular matrix: the pattern of both systems of GaussNewton,
// with the Laplacian's values (and the proximal term on the diagonal). The storage slot of each
// spring's off-diagonal entry and of each node's diagonal entry.
struct SheetGraph {
  Eigen::SparseMatrix<double> matrix;
  std::vector<int> off_diagonal, diagonal;
};
SheetGraph GraphOf(const Mesh& mesh, const Indexing& idx) {
  const int n = static_cast<int>(idx.node.size());
  SheetGraph out;
  Eigen::SparseMatrix<double>& graph = out.matrix;
  graph.resize(n, n);
  out.off_diagonal.resize(mesh.springs.size());
  out.diagonal.resize(n);
  std::vector<Eigen::Triplet<double>> lt;
  lt.reserve(3 * mesh.springs.size() + n);
  for (const Spring& s : mesh.springs) {
    const int a = idx.var[s.a], b = idx.var[s.b];
    lt.emplace_back(a, a, 1.0);
    lt.emplace_back(b, b, 1.0);
    lt.emplace_back(std::max(a, b), std::min(a, b), -1.0);
  }
  for (int v = 0; v < n; ++v) lt.emplace_back(v, v, kProximal);
  graph.setFromTriplets(lt.begin(), lt.end());
  graph.makeCompressed();
  auto slot = [&](int r, int c) {
    return static_cast<int>(&graph.coeffRef(r, c) - graph.valuePtr());
  };
  for (size_t k = 0; k < mesh.springs.size(); ++k) {
    const int a = idx.var[mesh.springs[k].a], b = idx.var[mesh.springs[k].b];
    out.off_diagonal[k] = slot(std::max(a, b), std::min(a, b));
  }
  for (int v = 0; v < n; ++v) out.diagonal[v] = slot(v, v);
  return out;
}

// Local/global iterations (Liu et al. 2013) from x: each projects every spring onto its rest
// length (local) and solves one fixed, pre-factored Laplacian system (global). The energy
// falls monotonically, which carries the compressed height map out of the basins where a
// bare Gauss-Newton from the same start can stall; Gauss-Newton then converges fast.
Status LocalGlobal(const Mesh& mesh, const Indexing& idx, const SheetGraph& sheet,
                   const FlattenOptions& options, Eigen::VectorXd* x_inout) {
  const int n = static_cast<int>(idx.node.size());
  const Eigen::SparseMatrix<double>& graph = sheet.matrix;
  Eigen::VectorXd& x = *x_inout;
  const double prox = kProximal;
  FrontalCholesky lap_solver;
  const Status analysed = lap_solver.Analyze(graph, idx.fronts, 1);
  if (!analysed.ok()) return analysed;
  if (!lap_solver.Factorize(
          std::vector<double>(graph.valuePtr(), graph.valuePtr() + graph.nonZeros()))) {
    return Status::Error("flattening: the sheet's Laplacian is singular");
  }
  // Both coordinates share the Laplacian: one two-column solve per iteration.
  Eigen::MatrixXd pos(n, 2);
  for (int v = 0; v < n; ++v) {
    pos(v, 0) = x[2 * v];
    pos(v, 1) = x[2 * v + 1];
  }
  double e_prev = std::numeric_limits<double>::infinity();
  Eigen::MatrixXd rhs(n, 2);
  for (int k = 0; k < options.local_global_iterations; ++k) {
    rhs = prox * pos;
    for (const Spring& s : mesh.springs) {
      const int a = idx.var[s.a], b = idx.var[s.b];
      const double dx = pos(a, 0) - pos(b, 0), dy = pos(a, 1) - pos(b, 1);
      const double len = std::max(std::sqrt(dx * dx + dy * dy), 1e-12);
      const double fx = s.rest_mm * dx / len, fy = s.rest_mm * dy / len;
      rhs(a, 0) += fx;
      rhs(b, 0) -= fx;
      rhs(a, 1) += fy;
      rhs(b, 1) -= fy;
    }
    lap_solver.Solve(&rhs);
    pos.swap(rhs);
    for (int v = 0; v < n; ++v) {
      x[2 * v] = pos(v, 0);
      x[2 * v + 1] = pos(v, 1);
    }
    const double e_now = SpringEnergy(mesh, idx, x);
    if (e_prev - e_now < 1e-3 * e_now) break;  // Slowing down: hand over to Gauss-Newton.
    e_prev = e_now;
  }
  return Status::Ok();
}

// The gradient g of the springs' energy at x and, when `refactor`, J^T J into `blocks` (2 x 2
// blocks in the sheet graph's slots): u u^T of each spring on both diagonal blocks, -u u^T
// between them.
void Linearize(const Mesh& mesh, const Indexing& idx, const SheetGraph& sheet,
               const Eigen::VectorXd& x, bool refactor, Eigen::MatrixXd* g_out,
               std::vector<double>* blocks_out) {
  Eigen::MatrixXd& g = *g_out;
  std::vector<double>& blocks = *blocks_out;
  const std::vector<int>& off_diagonal = sheet.off_diagonal;
  const std::vector<int>& diagonal = sheet.diagonal;
  g.setZero();
  if (refactor) std::fill(blocks.begin(), blocks.end(), 0.0);
  for (size_t k = 0; k < mesh.springs.size(); ++k) {
    const Spring& s = mesh.springs[k];
    const int a = idx.var[s.a], b = idx.var[s.b];
    const double dx = x[2 * a] - x[2 * b], dy = x[2 * a + 1] - x[2 * b + 1];
    const double len = std::max(std::sqrt(dx * dx + dy * dy), 1e-12);
    const double ux = dx / len, uy = dy / len, r = len - s.rest_mm;
    g(2 * a, 0) += ux * r;
    g(2 * a + 1, 0) += uy * r;
    g(2 * b, 0) -= ux * r;
    g(2 * b + 1, 0) -= uy * r;
    if (!refactor) continue;
    // The spring's J^T J: u u^T on both diagonal blocks, -u u^T between them.
    const double uu[4] = {ux * ux, ux * uy, ux * uy, uy * uy};
    double* off = &blocks[4 * static_cast<size_t>(off_diagonal[k])];
    double* da = &blocks[4 * static_cast<size_t>(diagonal[a])];
    double* db = &blocks[4 * static_cast<size_t>(diagonal[b])];
    for (int q = 0; q < 4; ++q) {
      off[q] -= uu[q];
      da[q] += uu[q];
      db[q] += uu[q];
    }
  }
}

FlattenResult GaussNewton(const Mesh& mesh, const FlattenOptions& options) {
  FlattenResult result;
  const Indexing idx(mesh);
  const int n = static_cast<int>(idx.node.size());
  // Fold-free start: the height map dropped onto the plane.
  Eigen::VectorXd x(2 * n);
  for (int v = 0; v < n; ++v) {
    x[2 * v] = mesh.point[idx.node[v]][0];
    x[2 * v + 1] = mesh.point[idx.node[v]][1];
  }
  auto energy = [&](const Eigen::VectorXd& y) { return SpringEnergy(mesh, idx, y); };
  const SheetGraph sheet = GraphOf(mesh, idx);
  const Eigen::SparseMatrix<double>& graph = sheet.matrix;
  const std::vector<int>& diagonal = sheet.diagonal;
  result.status = LocalGlobal(mesh, idx, sheet, options, &x);
  if (!result.status.ok()) return result;
  // J^T J has the graph's pattern with a 2 x 2 block per entry: each refactorisation refills
  // the blocks through the slots. A tiny diagonal (Levenberg) term removes the
  // rigid-motion null space without moving the minimum.
  FrontalCholesky solver;
  {
    const Status analysed = solver.Analyze(graph, idx.fronts, 2);
    if (!analysed.ok()) {
      result.status = analysed;
      return result;
    }
  }
  std::vector<double> blocks(4 * static_cast<size_t>(graph.nonZeros()));
  // Gauss-Newton with the factorisation reused while it keeps converging fast (a chord
  // method): near the solution J barely changes, a refactorisation costs 10-20 solves.
  double lambda = 1e-6;
  double e = energy(x);
  int it = 0;
  bool refactor = true, fresh = false;
  double last_step = std::numeric_limits<double>::infinity();
  Eigen::MatrixXd g(2 * n, 1);
  for (; it < options.max_iterations; ++it) {
    Linearize(mesh, idx, sheet, x, refactor, &g, &blocks);
    if (refactor) {
      for (int v = 0; v < n; ++v) {
        const size_t d = 4 * static_cast<size_t>(diagonal[v]);
        blocks[d] += lambda;
        blocks[d + 3] += lambda;
      }
      if (!solver.Factorize(blocks)) {
        result.status = Status::Error("flattening: the sheet's normal equations are singular");
        return result;
      }
      refactor = false;
      fresh = true;
    }
    Eigen::MatrixXd step = g;
    solver.Solve(&step);
    Eigen::VectorXd delta = -step.col(0);
    Eigen::VectorXd next = x + delta;
    double e_next = energy(next);
    // A step that overshoots along a soft mode (a flap turning about a hinge, where the
    // linearised rotation moves nodes off their arc) is halved before the damping is raised.
    for (int half = 0; half < 3 && !(e_next <= e) && e > 1e-24; ++half) {
      delta *= 0.5;
      next = x + delta;
      e_next = energy(next);
    }
    if (!(e_next <= e) && e > 1e-24) {
      // No descent: refactor at the current point, more damped if the factor was fresh.
      // With a fresh factor and the last step already below the tolerance, this is
      // round-off at the minimum, not a slope: done.
      if (fresh && last_step < options.tolerance_mm) break;
      if (fresh) lambda *= 10;
      if (lambda > 1e6) break;
      refactor = true;
      continue;
    }
    x = next;
    e = e_next;
    double largest = 0;
    for (int v = 0; v < n; ++v) {
      largest =
          std::max(largest, delta[2 * v] * delta[2 * v] + delta[2 * v + 1] * delta[2 * v + 1]);
    }
    largest = std::sqrt(largest);
    if (largest < options.tolerance_mm) {
      ++it;
      break;
    }
    // Slow contraction: the factor is stale; refactor (and relax the damping).
    if (largest > 0.5 * last_step) {
      refactor = true;
      lambda = std::max(1e-9, lambda * 0.1);
    }
    fresh = false;
    last_step = largest;
  }
  result.flat.assign(mesh.kind.size(), cv::Point2d(0, 0));
  for (int v = 0; v < n; ++v) result.flat[idx.node[v]] = cv::Point2d(x[2 * v], x[2 * v + 1]);
  AlignToOriginal(mesh, idx, &result.flat);
  result.iterations = it;
  result.status = Status::Ok();
  return result;
}

// The paper's particle system. State per active particle: position and velocity (3D).
class Simulator {
 public:
  Simulator(const Mesh& mesh, const FlattenOptions& options)
      : mesh_(mesh), o_(options), idx_(mesh), n_(static_cast<int>(idx_.node.size())) {
    x_.resize(n_);
    v_.assign(n_, cv::Vec3d(0, 0, 0));
    for (int p = 0; p < n_; ++p) x_[p] = mesh.point[idx_.node[p]];
    // Shift so the lowest particle touches the plane: "the page lies on the table".
    double zmin = x_.empty() ? 0 : x_[0][2];
    for (const cv::Vec3d& p : x_) zmin = std::min(zmin, p[2]);
    for (cv::Vec3d& p : x_) p[2] -= zmin;
    for (const Spring& s : mesh.springs)
      springs_.push_back({idx_.var[s.a], idx_.var[s.b], s.rest_mm});
  }

  FlattenResult Run() {
    FlattenResult result;
    double dt = o_.time_step;
    double last_force = -1;
    int step = 0, good_steps = 0, stalled_steps = 0;
    std::vector<cv::Vec3d> x0, v0;
    for (; step < o_.max_steps; ++step) {
      if (o_.record_every > 0 && step % o_.record_every == 0) Record(&result);
      x0 = x_;
      v0 = v_;
      double internal = 0;
      for (;;) {
        internal = o_.solver == FlattenSolver::kEuler ? EulerStep(dt) : RungeKuttaStep(dt);
        // Penetration: restore the previous state and halve the time step (paper, 3.7.2).
        bool penetrated = false;
        for (const cv::Vec3d& p : x_) penetrated |= p[2] < -o_.plane_epsilon_mm;
        if (!penetrated) break;
        x_ = x0;
        v_ = v0;
        dt *= 0.5;
        good_steps = 0;
        if (dt < 1e-9 * o_.time_step) {
          result.status = Status::Error("flattening simulator: time step underflow");
          return result;
        }
      }
      // Once stable again, let the step grow back towards the initial one.
      if (++good_steps > 10 && dt < o_.time_step) {
        dt = std::min(o_.time_step, dt * 2);
        good_steps = 0;
      }
      bool on_plane = true;
      double moved = 0;
      for (int p = 0; p < n_; ++p) {
        on_plane &= x_[p][2] < o_.plane_epsilon_mm;
        // In-plane motion: contact chatter in z (restitution bounces) is not "moving".
        const double mx = x_[p][0] - x0[p][0], my = x_[p][1] - x0[p][1];
        moved = std::max(moved, mx * mx + my * my);  // Squared; root taken once below.
      }
      moved = std::sqrt(moved);
      const double mean_force = internal / std::max(1, n_);
      const bool steady = last_force >= 0 &&
                          std::fabs(mean_force - last_force) < o_.force_tolerance &&
                          moved < o_.settle_tolerance_mm;
      last_force = mean_force;
      // At rest but not flat: part of the sheet is held up (it folded while falling).
      stalled_steps = (!on_plane && moved < o_.settle_tolerance_mm) ? stalled_steps + 1 : 0;
      if (stalled_steps > 2000) {
        double zmax = 0;
        int up = 0;
        for (int p = 0; p < n_; ++p) {
          zmax = std::max(zmax, x_[p][2]);
          up += x_[p][2] >= o_.plane_epsilon_mm;
        }
        result.status = Status::Error(
            "flattening simulator: came to rest with " + std::to_string(up) + " particles up to " +
            std::to_string(zmax) +
            " mm above the plane (the sheet folded while falling); the gauss-newton solver "
            "does not fold");
        return result;
      }
      if (on_plane && steady) {
        ++step;
        break;
      }
    }
    if (o_.record_every > 0) Record(&result);
    result.flat.assign(mesh_.kind.size(), cv::Point2d(0, 0));
    for (int p = 0; p < n_; ++p) result.flat[idx_.node[p]] = cv::Point2d(x_[p][0], x_[p][1]);
    AlignToOriginal(mesh_, idx_, &result.flat);
    result.iterations = step;
    result.status = step >= o_.max_steps
                        ? Status::Error("flattening simulator: no steady state after " +
                                        std::to_string(o_.max_steps) + " steps")
                        : Status::Ok();
    return result;
  }

 private:
  struct S {
    int a, b;
    double rest;
  };

  // Accelerations (unit mass) at a state; returns sum |F_int| over particles.
  double Forces(const std::vector<cv::Vec3d>& x, const std::vector<cv::Vec3d>& v,
                std::vector<cv::Vec3d>* acc) {
    acc->assign(n_, cv::Vec3d(0, 0, 0));
    // The hot loop of the simulator: plain doubles, one square root per spring.
    const double ks = o_.stiffness, kd = o_.spring_damping;
    const double* xp = x[0].val;
    const double* vp = v[0].val;
    double* ap = (*acc)[0].val;
    for (const S& s : springs_) {
      const int a = 3 * s.a, b = 3 * s.b;
      const double dx = xp[a] - xp[b], dy = xp[a + 1] - xp[b + 1], dz = xp[a + 2] - xp[b + 2];
      const double len = std::max(std::sqrt(dx * dx + dy * dy + dz * dz), 1e-12);
      const double inv = 1.0 / len;
      const double ux = dx * inv, uy = dy * inv, uz = dz * inv;
      const double closing =
          (vp[a] - vp[b]) * ux + (vp[a + 1] - vp[b + 1]) * uy + (vp[a + 2] - vp[b + 2]) * uz;
      const double mag = ks * (len - s.rest) + kd * closing;
      // A stretched spring pulls the pair together.
      ap[a] -= mag * ux;
      ap[a + 1] -= mag * uy;
      ap[a + 2] -= mag * uz;
      ap[b] += mag * ux;
      ap[b + 1] += mag * uy;
      ap[b + 2] += mag * uz;
    }
    double internal = 0;
    for (int p = 0; p < n_; ++p) {
      internal += cv::norm((*acc)[p]);
      cv::Vec3d& a = (*acc)[p];
      a[2] -= o_.gravity;
      a -= o_.drag * v[p];
      // In contact the plane carries any downward force (no penetration by pushing). Contact
      // is decided once per step, so every Runge-Kutta stage sees the same constraint.
      if (contact_[p] && a[2] < 0) a[2] = 0;
    }
    return internal;
  }

  // Collision with the plane (x3 < epsilon): v_new = v_t - k_r v_n for particles moving into
  // it; records which particles are in contact for this step.
  // A bounce slower than gravity gives in one step is a resting contact: the particle stays
  // on the plane (no endless micro-bounces).
  void Collide(std::vector<cv::Vec3d>* v, std::vector<cv::Vec3d>* x, double dt) {
    contact_.assign(n_, 0);
    for (int p = 0; p < n_; ++p) {
      if ((*x)[p][2] >= o_.plane_epsilon_mm) continue;
      contact_[p] = 1;
      double& vz = (*v)[p][2];
      if (vz < 0) vz *= -o_.restitution;
      if (vz < o_.gravity * dt) {
        vz = 0;
        (*x)[p][2] = 0;
      }
    }
  }

  double EulerStep(double dt) {
    Collide(&v_, &x_, dt);
    const double internal = Forces(x_, v_, &a1_);
    for (int p = 0; p < n_; ++p) {
      v_[p] += dt * a1_[p];  // Velocity first, then position from the new velocity.
      x_[p] += dt * v_[p];
    }
    return internal;
  }

  double RungeKuttaStep(double dt) {
    Collide(&v_, &x_, dt);
    const std::vector<cv::Vec3d> x = x_, v = v_;
    std::vector<cv::Vec3d> xs(n_), vs(n_);
    const double internal = Forces(x, v, &a1_);
    for (int p = 0; p < n_; ++p) {
      xs[p] = x[p] + 0.5 * dt * v[p];
      vs[p] = v[p] + 0.5 * dt * a1_[p];
    }
    Forces(xs, vs, &a2_);
    std::vector<cv::Vec3d> v2 = vs;
    for (int p = 0; p < n_; ++p) {
      xs[p] = x[p] + 0.5 * dt * v2[p];
      vs[p] = v[p] + 0.5 * dt * a2_[p];
    }
    Forces(xs, vs, &a3_);
    std::vector<cv::Vec3d> v3 = vs;
    for (int p = 0; p < n_; ++p) {
      xs[p] = x[p] + dt * v3[p];
      vs[p] = v[p] + dt * a3_[p];
    }
    Forces(xs, vs, &a4_);
    for (int p = 0; p < n_; ++p) {
      x_[p] = x[p] + dt / 6.0 * (v[p] + 2.0 * v2[p] + 2.0 * v3[p] + vs[p]);
      v_[p] = v[p] + dt / 6.0 * (a1_[p] + 2.0 * a2_[p] + 2.0 * a3_[p] + a4_[p]);
    }
    return internal;
  }

  void Record(FlattenResult* result) {
    std::vector<cv::Vec3d> frame(mesh_.kind.size(), cv::Vec3d(0, 0, 0));
    for (int p = 0; p < n_; ++p) frame[idx_.node[p]] = x_[p];
    result->trajectory.push_back(std::move(frame));
  }

  const Mesh& mesh_;
  const FlattenOptions& o_;
  Indexing idx_;
  int n_;
  std::vector<S> springs_;
  std::vector<cv::Vec3d> x_, v_, a1_, a2_, a3_, a4_;
  std::vector<uint8_t> contact_;  // Particles on the plane during the current step.
};

}  // namespace

const char* ToString(FlattenSolver solver) {
  switch (solver) {
    case FlattenSolver::kGaussNewton:
      return "gauss-newton";
    case FlattenSolver::kEuler:
      return "euler";
    case FlattenSolver::kRungeKutta4:
      return "rk4";
  }
  return "?";
}

bool ParseFlattenSolver(const std::string& text, FlattenSolver* solver) {
  for (FlattenSolver s :
       {FlattenSolver::kGaussNewton, FlattenSolver::kEuler, FlattenSolver::kRungeKutta4}) {
    if (text == ToString(s)) {
      *solver = s;
      return true;
    }
  }
  return false;
}

bool FlattenOptions::Check(std::string* why) const {
  if (max_iterations < 1 || !(tolerance_mm > 0)) {
    *why = "max_iterations must be >= 1 and tolerance_mm > 0";
    return false;
  }
  if (!(stiffness > 0) || spring_damping < 0 || gravity < 0 || drag < 0 || !(time_step > 0) ||
      restitution < 0 || restitution > 1 || max_steps < 1 || record_every < 0) {
    *why =
        "simulator constants out of range (stiffness > 0, damping/gravity/drag >= 0, "
        "time_step > 0, restitution in [0, 1])";
    return false;
  }
  return true;
}

void MeasureStrain(const Mesh& mesh, const std::vector<cv::Point2d>& flat, FlattenResult* result) {
  // Over the leaf's own springs: a skirt node is the surface extrapolated past the leaf's edge
  // (beside a crease that runs off the edge its springs cannot all be kept), not the leaf.
  std::vector<double> strains;
  strains.reserve(mesh.springs.size());
  double sum = 0;
  for (const Spring& s : mesh.springs) {
    if (mesh.kind[s.a] == NodeKind::kSkirt || mesh.kind[s.b] == NodeKind::kSkirt) continue;
    strains.push_back(std::fabs(cv::norm(flat[s.a] - flat[s.b]) / s.rest_mm - 1.0));
    sum += strains.back();
  }
  const size_t count = strains.size();
  result->mean_strain = count ? sum / count : 0;
  result->max_strain = count ? *std::max_element(strains.begin(), strains.end()) : 0;
  if (count) {
    const size_t k = std::min<size_t>(kWidespreadSprings, count) - 1;
    std::nth_element(strains.begin(), strains.begin() + k, strains.end(), std::greater<>());
    result->widespread_strain = strains[k];
  }
  // A fold flips a quad's orientation relative to how the camera saw it. Cells with two or
  // more skirt nodes lie mostly past the page's data, extrapolated: beyond a steep edge (a curl's
  // corner seen edge on) their camera image may turn over while the page's own cells do not;
  // they are not counted.
  int folded = 0;
  for (const cv::Vec4i& q : mesh.quads) {
    int skirt = 0;
    for (int c = 0; c < 4; ++c) skirt += mesh.kind[q[c]] == NodeKind::kSkirt;
    if (skirt >= 2) continue;
    auto area = [](cv::Point2d a, cv::Point2d b, cv::Point2d c) {
      return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
    };
    // Every corner's triangle keeps its orientation unless the quad folded or twisted. The
    // camera image's y points along -world y: a preserved orientation has the opposite sign.
    bool flipped = false;
    for (int c = 0; c < 4; ++c) {
      const int a = q[c], b = q[(c + 1) % 4], d = q[(c + 3) % 4];
      const double before = area(mesh.pixel[a], mesh.pixel[b], mesh.pixel[d]);
      const double after = area(flat[a], flat[b], flat[d]);
      flipped |= (before > 0) == (after > 0);
    }
    folded += flipped;
  }
  result->folded_quads = folded;
}

FlattenResult Flatten(const Mesh& mesh, const FlattenOptions& options) {
  FlattenResult result;
  std::string why;
  if (!options.Check(&why)) {
    result.status = Status::Error("flatten options: " + why);
    return result;
  }
  if (!mesh.status.ok()) {
    result.status = Status::Error("cannot flatten: " + mesh.status.message());
    return result;
  }
  result = options.solver == FlattenSolver::kGaussNewton ? GaussNewton(mesh, options)
                                                         : Simulator(mesh, options).Run();
  if (!result.status.ok()) return result;
  for (const cv::Point2d& p : result.flat) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y)) {
      result.status = Status::Error("flattening diverged (non-finite positions)");
      return result;
    }
  }
  MeasureStrain(mesh, result.flat, &result);
  return result;
}

}  // namespace vellum
