// Ceres Levenberg-Marquardt M-step: one ceres::CostFunction over the P-dim tangent offset delta
// stacks the residuals of every term (their Evaluate is the CostFunction contract), Jacobians
// analytic from the skinning blocks; constant parameters via ceres::SubsetManifold.
#pragma once

#include "solvers/fit_solver.h"

namespace artex {

class CeresLmSolver : public FitSolver {
 public:
  explicit CeresLmSolver(const FitSolverOptions& options);
  std::string name() const override { return "ceres_lm"; }
  FitSolverSummary Solve(const FitProblem& problem, Pose* pose) override;

 private:
  FitSolverOptions options_;
};

}  // namespace artex
