// Gauss-Newton M-step (paper eq. 5): per iteration, assemble J^T J and J^T r block-sparsely
// from every term at the current delta, solve (J^T J) step = -J^T r (the Tikhonov term adds
// Gamma), optionally halve the step while it increases the cost, and accept delta += step.
// Iterate() exposes one iteration (GTSAM-style) so callers can interleave other work.
#pragma once

#include "solvers/fit_solver.h"

namespace artex {

class GaussNewtonSolver : public FitSolver {
 public:
  explicit GaussNewtonSolver(const FitSolverOptions& options);
  std::string name() const override { return "gauss_newton"; }
  FitSolverSummary Solve(const FitProblem& problem, Pose* pose) override;

  struct IterationResult {
    bool ok = false;            // false: non-finite cost / system, delta unchanged
    bool improved = false;      // the accepted step decreased the cost
    double cost_before = 0.0;
    double cost_after = 0.0;
    double max_step = 0.0;      // max |step component| of the accepted step
  };
  // One Gauss-Newton iteration at *delta (updated in place).
  IterationResult Iterate(const FitProblem& problem, Eigen::VectorXd* delta,
                          double* skinning_seconds = nullptr);

 private:
  FitSolverOptions options_;
  FitEvaluation eval_;     // reused across iterations
  FitEvaluation trial_;
  Eigen::MatrixXd information_;  // J^T J of the problem's information terms, last Iterate
};

}  // namespace artex
