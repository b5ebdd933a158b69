#include "solvers/fit_solver.h"

#include <cmath>
#include <limits>
#include <sstream>

#include "models/error.h"
#include "solvers/ceres_lm.h"
#include "solvers/gauss_newton.h"

namespace artex {

const std::map<std::string, FitSolverType>& FitSolverTypeNames() {
  static const std::map<std::string, FitSolverType> kNames = {
      {"gauss_newton", FitSolverType::kGaussNewton},
      {"ceres_lm", FitSolverType::kCeresLevenbergMarquardt}};
  return kNames;
}

std::string FitSolverTypeName(FitSolverType type) {
  for (const auto& [name, value] : FitSolverTypeNames()) {
    if (value == type) return name;
  }
  return "unknown";
}

bool FitSolverOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (max_iterations < 1) {
    msg << "max_iterations: expected >= 1, found " << max_iterations;
  } else if (!(std::isfinite(function_tolerance) && function_tolerance >= 0.0)) {
    msg << "function_tolerance: expected a finite value >= 0, found " << function_tolerance;
  } else if (!(std::isfinite(parameter_tolerance) && parameter_tolerance >= 0.0)) {
    msg << "parameter_tolerance: expected a finite value >= 0, found " << parameter_tolerance;
  } else if (max_step_halvings < 0) {
    msg << "max_step_halvings: expected >= 0, found " << max_step_halvings;
  } else if (num_threads < 1) {
    msg << "num_threads: expected >= 1, found " << num_threads;
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

std::unique_ptr<FitSolver> FitSolver::Create(const FitSolverOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw Error("fit solver options: " + error);
  switch (options.type) {
    case FitSolverType::kGaussNewton:
      return std::make_unique<GaussNewtonSolver>(options);
    case FitSolverType::kCeresLevenbergMarquardt:
      return std::make_unique<CeresLmSolver>(options);
  }
  throw Error("fit solver options: type: unknown solver type");
}

int FitProblem::num_residuals() const {
  int n = 0;
  for (const FittingTerm* term : terms) n += term->num_residuals();
  return n;
}

bool FitProblem::needs_skinning() const {
  for (const FittingTerm* term : terms) {
    if (term->needs_skinning()) return true;
  }
  return false;
}

double FitProblem::Cost(const Eigen::VectorXd& delta, FitEvaluation* scratch) const {
  PrepareFitEvaluation(skinning, anchor, delta, needs_skinning(), false, scratch);
  double cost = 0.0;
  for (const FittingTerm* term : terms) cost += term->Cost(*scratch);
  return std::isfinite(cost) ? cost : std::numeric_limits<double>::quiet_NaN();
}

void ValidateFitProblem(const FitProblem& problem) {
  const int p = problem.num_parameters();
  if (problem.needs_skinning() && problem.skinning == nullptr) {
    throw Error("fit problem: a term needs the skinning but none was given");
  }
  if (problem.skinning != nullptr &&
      problem.skinning->model().num_joints() != problem.anchor.num_joints()) {
    std::ostringstream msg;
    msg << "fit problem: anchor pose: expected " << problem.skinning->model().num_joints()
        << " joints, found " << problem.anchor.num_joints();
    throw Error(msg.str());
  }
  for (int index : problem.constant_parameters) {
    if (index < 0 || index >= p) {
      std::ostringstream msg;
      msg << "fit problem: constant_parameters: expected indices in [0, " << p << "), found "
          << index;
      throw Error(msg.str());
    }
  }
  if (!problem.anchor.AllFinite()) throw Error("fit problem: anchor pose is not finite");
}

const char* FitTerminationName(FitTermination termination) {
  switch (termination) {
    case FitTermination::kConverged:
      return "converged";
    case FitTermination::kMaxIterations:
      return "max_iterations";
    case FitTermination::kNoProgress:
      return "no_progress";
    case FitTermination::kFailure:
      return "failure";
  }
  return "unknown";
}

std::string FitSolverSummary::BriefReport() const {
  std::ostringstream out;
  out << FitTerminationName(termination) << ": " << iterations << " iterations, cost "
      << initial_cost << " -> " << final_cost << ", " << seconds * 1e3 << " ms";
  if (!message.empty()) out << " (" << message << ")";
  return out.str();
}

}  // namespace artex
