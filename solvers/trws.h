// Sequential tree-reweighted message passing, TRW-S (Kolmogorov 2006), on the general graph
// with the node order 0..N-1 (monotonic chains; node weight gamma_i = 1 / max(#edges to earlier
// nodes, #edges to later nodes)). Each iteration is a forward and a backward pass of
// normalised messages; the backward pass yields a lower bound valid for any messages (docs/mrf.md)
// and a labelling is read out after it (forward order, conditioned on earlier nodes); the best
// labelling is kept. Exact on chains; the bound certifies every solver's gap.
#pragma once

#include <vector>

#include "solvers/mrf.h"

namespace artex {

class TrwsSolver : public MrfSolver {
 public:
  explicit TrwsSolver(const MrfSolverOptions& options) : options_(options) {}
  MrfSummary Solve(const MrfProblem& problem, std::vector<int>* labels) override;

 private:
  MrfSolverOptions options_;
};

}  // namespace artex
