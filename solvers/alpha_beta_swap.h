// Alpha-beta swap (Boykov, Veksler & Zabih 2001): for every label pair (alpha, beta) the nodes
// labelled alpha or beta (and having both as candidates) are relabelled optimally among the two
// by one s-t min cut. Non-submodular terms are majorised around the current state as in
// alpha_expansion.h, and a move is accepted only when it lowers the true energy. A local
// minimum for swaps is exact on submodular two-label energies.
#pragma once

#include <vector>

#include "solvers/mrf.h"

namespace artex {

class AlphaBetaSwapSolver : public MrfSolver {
 public:
  explicit AlphaBetaSwapSolver(const MrfSolverOptions& options) : options_(options) {}
  MrfSummary Solve(const MrfProblem& problem, std::vector<int>* labels) override;

 private:
  MrfSolverOptions options_;
};

}  // namespace artex
