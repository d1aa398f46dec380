// Flattening the sheet onto the plane z = 0.
//
// kEuler and kRungeKutta4 are the paper's simulator (Brown & Seales 2004, sections 3.5-3.8,
// after Provot): particles of mass 1, Hooke springs with dampers, a global downward force,
// viscous drag, collision with z = 0 with restitution k_r and time-step halving on
// penetration, run until every particle lies on the plane and the internal forces are steady.
// kGaussNewton reaches the same state directly: it minimises the same spring energy,
// sum (|x_a - x_b| - r)^2, over positions on the plane, from the height map's projection
// (fold free, as the paper's 3.8 argues), by damped Gauss-Newton with a sparse Cholesky.
#pragma once

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "core/common/status.h"
#include "core/mesh/mesh.h"

namespace vellum {

enum class FlattenSolver { kGaussNewton, kEuler, kRungeKutta4 };

const char* ToString(FlattenSolver solver);
bool ParseFlattenSolver(const std::string& text, FlattenSolver* solver);

struct FlattenOptions {
  FlattenSolver solver = FlattenSolver::kGaussNewton;
  // Gauss-Newton.
  int local_global_iterations = 20;  // Limit of the local/global warm-up iterations.
  int max_iterations = 100;          // Gauss-Newton iteration limit.
  // Stop when no node moves more than this, mm: 10 nm, 25 000 times below the default rig's
  // 0.25 mm pixel. (A sheet whose springs disagree, e.g. round a peeled corner, converges only
  // linearly under Gauss-Newton; a tighter bar there costs iterations and buys nothing.)
  double tolerance_mm = 1e-5;
  // Simulator (units: mm, unit mass, time in simulation units). Gravity must be strong enough
  // to crush the small tents a falling curl can form (at 200 a 67 degree curl could stall);
  // drag keeps the fall at ~100 mm per unit, 0.5 mm per step.
  double stiffness = 400.0;           // Spring constant k_s, per unit mass.
  double spring_damping = 2.0;        // Spring damper k_d.
  double gravity = 1000.0;            // Global downward acceleration, mm / unit^2.
  double drag = 10.0;                 // Viscous drag mu_d (f = -mu_d v).
  double restitution = 0.1;           // k_r: v_new = v_t - k_r v_n at the plane.
  double time_step = 0.005;           // Initial time step; halved when a step penetrates.
  double plane_epsilon_mm = 1e-3;     // A particle with z < epsilon is on the plane.
  double force_tolerance = 1e-6;      // Steady state: mean |F_int| change per step below this.
  double settle_tolerance_mm = 1e-5;  // ... and no particle moving more than this per step.
  int max_steps = 200000;             // Step limit.
  int record_every = 0;               // Record positions every k steps (0: no trajectory).

  bool Check(std::string* why) const;
};

struct FlattenResult {
  Status status = Status::Error("flattening not run");
  std::vector<cv::Point2d> flat;  // Flattened (x, y) per node, mm; (0, 0) for inactive nodes.
  int iterations = 0;             // Gauss-Newton iterations or simulator steps.
  double mean_strain = 0;         // Mean |length / rest - 1| over springs.
  double max_strain = 0;          // Max of the same.
  // The strain that kWidespreadSprings springs or more keep. A crease sharper than the decoder
  // resolves shortens every spring across it (dozens, on a leaf), as does more than the leaf held
  // in the sheet; a node whose fit cuts a crease's corner strains only its own few springs, and
  // the sheet takes that up within its cell.
  double widespread_strain = 0;
  int folded_quads = 0;                            // Quads whose orientation flipped (a fold-over).
  std::vector<std::vector<cv::Vec3d>> trajectory;  // Simulator: recorded positions.
};

// How many springs must keep a strain for it to be widespread (FlattenResult::widespread_strain).
inline constexpr int kWidespreadSprings = 10;

FlattenResult Flatten(const Mesh& mesh, const FlattenOptions& options = FlattenOptions());

// Residual strain and fold count of flat positions on a mesh (used by every solver).
void MeasureStrain(const Mesh& mesh, const std::vector<cv::Point2d>& flat, FlattenResult* result);

}  // namespace vellum
