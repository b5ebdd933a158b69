// M-step solvers of the kinematic fitting (paper eq. 3-5, docs/design.md "Fitting energy"): minimise
// F(delta) = sum over terms |r(anchor (+) delta)|^2 over the P-dim pose tangent delta, starting
// at delta = 0. Backends (selected by FitSolverOptions::type, created by FitSolver::Create):
//   Gauss-Newton:   (J^T J) step = -J^T r with the Tikhonov term inside J (the paper's
//                   (sum_t P_t J_t^T J_t + Gamma) Delta = sum_t P_t J_t^T (mu_t - v'_t)), retract
//   Ceres LM:       Levenberg-Marquardt over the same residuals (one CostFunction over delta)
#pragma once

#include <map>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "energies/fitting_term.h"
#include "models/pose.h"
#include "models/skinning.h"

namespace artex {

enum class FitSolverType { kGaussNewton, kCeresLevenbergMarquardt };
const std::map<std::string, FitSolverType>& FitSolverTypeNames();  // "gauss_newton", "ceres_lm"
std::string FitSolverTypeName(FitSolverType type);

struct FitSolverOptions {
  FitSolverType type = FitSolverType::kGaussNewton;
  // Inner iterations per M-step (paper: one Gauss-Newton step per EM iteration).
  int max_iterations = 1;
  // Stop when the relative cost decrease of an iteration falls below this.
  double function_tolerance = 1e-8;
  // Stop when max |step component| (m, rad, scale units) falls below this.
  double parameter_tolerance = 1e-9;
  // Gauss-Newton: halve a step that increases the cost up to this many times (0: always take
  // the full step, the paper's plain update).
  int max_step_halvings = 4;
  // Ceres: threads for the Jacobian evaluation / linear algebra.
  int num_threads = 1;

  bool IsValid(std::string* error) const;
};

// One M-step problem. Terms and skinning must outlive the solve.
struct FitProblem {
  const Skinning* skinning = nullptr;
  Pose anchor;                               // theta at delta = 0
  std::vector<const FittingTerm*> terms;
  std::vector<int> constant_parameters;      // tangent indices held at 0 (e.g. kScaleIndex)
  // > 0: FitSolverSummary::information receives J^T J of the first this many terms at the
  // last linearisation point (Gauss-Newton only; constant parameters not removed).
  int information_terms = 0;

  int num_parameters() const { return anchor.num_parameters(); }
  int num_residuals() const;
  bool needs_skinning() const;
  // sum over terms of |r|^2 at anchor (+) delta (NaN when not finite); `scratch` is reused.
  double Cost(const Eigen::VectorXd& delta, FitEvaluation* scratch) const;
};

enum class FitTermination { kConverged, kMaxIterations, kNoProgress, kFailure };
const char* FitTerminationName(FitTermination termination);

struct FitSolverSummary {
  FitTermination termination = FitTermination::kFailure;
  int iterations = 0;
  double initial_cost = 0.0;   // F(0), sum of squares
  double final_cost = 0.0;     // F(delta)
  std::vector<double> cost_trace;  // after each iteration
  Eigen::VectorXd delta;       // the accepted tangent offset
  Eigen::MatrixXd information;  // FitProblem::information_terms > 0: P x P, else empty
  double seconds = 0.0;
  double skinning_seconds = 0.0;  // posing the template (with Jacobians) inside the solve
  std::string message;

  std::string BriefReport() const;
};

class FitSolver {
 public:
  // Throws artex::Error on invalid options.
  static std::unique_ptr<FitSolver> Create(const FitSolverOptions& options);
  virtual ~FitSolver() = default;
  virtual std::string name() const = 0;
  // Minimises F from delta = 0; *pose = anchor (+) delta (unchanged on failure).
  virtual FitSolverSummary Solve(const FitProblem& problem, Pose* pose) = 0;
};

// Throws artex::Error when the problem is malformed (no skinning for a term that needs it,
// constant parameter out of range).
void ValidateFitProblem(const FitProblem& problem);

}  // namespace artex
