#include "solvers/ceres_lm.h"

#include <chrono>
#include <cmath>
#include <mutex>

#include <ceres/ceres.h>

#include "models/numeric.h"

namespace artex {

namespace {

// All terms stacked into one residual block over the P-dim tangent offset.
class StackedCostFunction : public ceres::CostFunction {
 public:
  explicit StackedCostFunction(const FitProblem* problem) : problem_(problem) {
    set_num_residuals(problem->num_residuals());
    mutable_parameter_block_sizes()->push_back(problem->num_parameters());
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const int p = problem_->num_parameters();
    const bool need_jacobian = jacobians != nullptr && jacobians[0] != nullptr;
    const bool skin = problem_->needs_skinning();
    FitEvaluation eval;
    const auto start = std::chrono::steady_clock::now();
    PrepareFitEvaluation(problem_->skinning, problem_->anchor,
                         Eigen::Map<const Eigen::VectorXd>(parameters[0], p), skin,
                         skin && need_jacobian, &eval);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      skinning_seconds_ += SecondsSince(start);
    }
    int offset = 0;
    for (const FittingTerm* term : problem_->terms) {
      double* jac = need_jacobian ? jacobians[0] + static_cast<size_t>(offset) * p : nullptr;
      if (!term->Evaluate(eval, residuals + offset, jac)) return false;
      offset += term->num_residuals();
    }
    return true;
  }

  double skinning_seconds() const { return skinning_seconds_; }

 private:
  const FitProblem* problem_;
  mutable std::mutex mutex_;
  mutable double skinning_seconds_ = 0.0;
};

}  // namespace

CeresLmSolver::CeresLmSolver(const FitSolverOptions& options) : options_(options) {}

FitSolverSummary CeresLmSolver::Solve(const FitProblem& problem, Pose* pose) {
  const auto start = std::chrono::steady_clock::now();
  ValidateFitProblem(problem);
  const int p = problem.num_parameters();
  FitSolverSummary summary;
  Eigen::VectorXd delta = Eigen::VectorXd::Zero(p);

  ceres::Problem::Options problem_options;
  problem_options.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.manifold_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem ceres_problem(problem_options);
  StackedCostFunction cost(&problem);
  ceres_problem.AddResidualBlock(&cost, nullptr, delta.data());
  if (!problem.constant_parameters.empty()) {
    if (static_cast<int>(problem.constant_parameters.size()) >= p) {
      ceres_problem.SetParameterBlockConstant(delta.data());
    } else {
      ceres_problem.SetManifold(delta.data(),
                                new ceres::SubsetManifold(p, problem.constant_parameters));
    }
  }

  ceres::Solver::Options solver_options;
  solver_options.minimizer_type = ceres::TRUST_REGION;
  solver_options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  solver_options.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
  solver_options.max_num_iterations = options_.max_iterations;
  solver_options.function_tolerance = options_.function_tolerance;
  solver_options.parameter_tolerance = options_.parameter_tolerance;
  solver_options.gradient_tolerance = 0.0;
  solver_options.num_threads = options_.num_threads;
  solver_options.logging_type = ceres::SILENT;
  solver_options.minimizer_progress_to_stdout = false;

  ceres::Solver::Summary ceres_summary;
  ceres::Solve(solver_options, &ceres_problem, &ceres_summary);

  // Ceres reports 0.5 |r|^2; artex costs are |r|^2.
  summary.initial_cost = 2.0 * ceres_summary.initial_cost;
  summary.final_cost = 2.0 * ceres_summary.final_cost;
  summary.iterations = static_cast<int>(ceres_summary.iterations.size()) - 1;
  for (const ceres::IterationSummary& it : ceres_summary.iterations) {
    if (it.iteration > 0) summary.cost_trace.push_back(2.0 * it.cost);
  }
  summary.message = ceres_summary.message;
  switch (ceres_summary.termination_type) {
    case ceres::CONVERGENCE:
      summary.termination = FitTermination::kConverged;
      break;
    case ceres::NO_CONVERGENCE:
      summary.termination = FitTermination::kMaxIterations;
      break;
    default:
      summary.termination = FitTermination::kFailure;
      break;
  }
  if (!delta.allFinite() || !std::isfinite(summary.final_cost)) {
    summary.termination = FitTermination::kFailure;
  }
  summary.delta = delta;
  if (summary.termination != FitTermination::kFailure) *pose = problem.anchor.Retracted(delta);
  summary.skinning_seconds = cost.skinning_seconds();
  summary.seconds = SecondsSince(start);
  return summary;
}

}  // namespace artex
