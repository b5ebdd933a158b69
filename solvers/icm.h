// Iterated conditional modes (Besag 1986): each node in index order takes its best candidate
// label given its neighbours' labels; sweeps until no node changes. Monotone, fast, weak: the
// baseline the graph-cut and message-passing solvers are compared against.
#pragma once

#include <vector>

#include "solvers/mrf.h"

namespace artex {

class IcmSolver : public MrfSolver {
 public:
  explicit IcmSolver(const MrfSolverOptions& options) : options_(options) {}
  MrfSummary Solve(const MrfProblem& problem, std::vector<int>* labels) override;

 private:
  MrfSolverOptions options_;
};

}  // namespace artex
