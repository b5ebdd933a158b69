#include "solvers/gauss_newton.h"

#include <chrono>
#include <cmath>

#include <Eigen/Cholesky>

#include "models/numeric.h"

namespace artex {

GaussNewtonSolver::GaussNewtonSolver(const FitSolverOptions& options) : options_(options) {}

GaussNewtonSolver::IterationResult GaussNewtonSolver::Iterate(const FitProblem& problem,
                                                              Eigen::VectorXd* delta,
                                                              double* skinning_seconds) {
  IterationResult result;
  const int p = problem.num_parameters();
  const bool skin = problem.needs_skinning();
  auto start = std::chrono::steady_clock::now();
  PrepareFitEvaluation(problem.skinning, problem.anchor, *delta, skin, skin, &eval_);
  if (skinning_seconds) *skinning_seconds += SecondsSince(start);

  Eigen::MatrixXd jtj = Eigen::MatrixXd::Zero(p, p);
  Eigen::VectorXd jtr = Eigen::VectorXd::Zero(p);
  double cost = 0.0;
  for (size_t t = 0; t < problem.terms.size(); ++t) {
    cost += problem.terms[t]->AccumulateNormalEquations(eval_, &jtj, &jtr);
    if (static_cast<int>(t) + 1 == problem.information_terms) information_ = jtj;
  }
  result.cost_before = cost;
  result.cost_after = cost;
  if (!std::isfinite(cost) || !jtj.allFinite() || !jtr.allFinite()) return result;
  for (int index : problem.constant_parameters) {
    jtj.row(index).setZero();
    jtj.col(index).setZero();
    jtj(index, index) = 1.0;
    jtr[index] = 0.0;
  }
  Eigen::LDLT<Eigen::MatrixXd> ldlt(jtj);
  Eigen::VectorXd step = ldlt.solve(-jtr);
  if (ldlt.info() != Eigen::Success || !step.allFinite()) return result;
  result.ok = true;

  // Accept the step, halving it while it increases the cost (if allowed).
  for (int halvings = 0;; ++halvings) {
    const Eigen::VectorXd trial = *delta + step;
    start = std::chrono::steady_clock::now();
    const double trial_cost = problem.Cost(trial, &trial_);
    if (skinning_seconds) *skinning_seconds += SecondsSince(start);
    const bool better = std::isfinite(trial_cost) && trial_cost <= cost;
    if (better || halvings >= options_.max_step_halvings) {
      if (!std::isfinite(trial_cost)) {
        result.ok = false;
        return result;
      }
      if (!better && options_.max_step_halvings > 0) return result;  // no progress: keep delta
      *delta = trial;
      result.improved = better;
      result.cost_after = trial_cost;
      result.max_step = step.cwiseAbs().maxCoeff();
      return result;
    }
    step *= 0.5;
  }
}

FitSolverSummary GaussNewtonSolver::Solve(const FitProblem& problem, Pose* pose) {
  const auto start = std::chrono::steady_clock::now();
  ValidateFitProblem(problem);
  FitSolverSummary summary;
  Eigen::VectorXd delta = Eigen::VectorXd::Zero(problem.num_parameters());
  summary.termination = FitTermination::kMaxIterations;
  for (int it = 0; it < options_.max_iterations; ++it) {
    const IterationResult r = Iterate(problem, &delta, &summary.skinning_seconds);
    if (it == 0) summary.initial_cost = r.cost_before;
    if (!r.ok) {
      summary.termination = FitTermination::kFailure;
      summary.message = "non-finite cost or singular normal equations";
      summary.final_cost = r.cost_before;
      break;
    }
    summary.iterations = it + 1;
    summary.final_cost = r.cost_after;
    summary.cost_trace.push_back(r.cost_after);
    if (r.max_step == 0.0) {
      summary.termination = FitTermination::kNoProgress;
      break;
    }
    const double decrease = r.cost_before - r.cost_after;
    if (r.max_step < options_.parameter_tolerance ||
        (decrease >= 0.0 &&
         decrease <= options_.function_tolerance * std::max(r.cost_before, 1e-300))) {
      summary.termination = FitTermination::kConverged;
      break;
    }
  }
  summary.delta = delta;
  if (problem.information_terms > 0) summary.information = information_;
  if (summary.termination != FitTermination::kFailure) *pose = problem.anchor.Retracted(delta);
  summary.seconds = SecondsSince(start);
  return summary;
}

}  // namespace artex
