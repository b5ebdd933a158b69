#include "solvers/alpha_beta_swap.h"

#include <cmath>
#include <limits>

#include "solvers/alpha_expansion.h"

namespace artex {

MrfSummary AlphaBetaSwapSolver::Solve(const MrfProblem& problem, std::vector<int>* labels) {
  MrfSummary summary;
  mrf_internal::SolveRun run(problem, options_, *labels, &summary);
  std::vector<int>& x = run.local();
  const int n = problem.num_nodes();
  const int num_labels = problem.num_labels();
  const MrfAdjacency adjacency = BuildMrfAdjacency(problem);
  const MrfLabelIndex label_index = BuildMrfLabelIndex(problem);

  double energy = summary.initial_energy;
  std::vector<int> var_of(n, -1);
  mrf_internal::BinaryMove move;  // y = 0: alpha, y = 1: beta
  std::vector<char> y;
  mrf_internal::BinaryMoveCut cut;
  const int num_pairs = num_labels * (num_labels - 1) / 2;
  int unchanged_streak = 0;
  summary.termination = "max_iterations";

  for (int iteration = 0; iteration < options_.max_iterations; ++iteration) {
    const double sweep_start = energy;
    bool converged = num_pairs == 0;
    for (int alpha = 0; alpha < num_labels && !converged; ++alpha) {
      for (int beta = alpha + 1; beta < num_labels && !converged; ++beta) {
        for (int i : move.vars) var_of[i] = -1;
        move.Clear();
        // Every move variable has alpha as a candidate.
        for (int p = label_index.offsets[alpha]; p < label_index.offsets[alpha + 1]; ++p) {
          const int i = label_index.nodes[p];
          const int label = problem.candidate_labels(i)[x[i]];
          if (label != alpha && label != beta) continue;
          const int kb = problem.CandidateIndex(i, beta);
          if (kb < 0) continue;
          var_of[i] = move.size();
          move.Add(i, label_index.local[p], kb, label == beta);
        }
        const bool accepted =
            move.size() > 0 && mrf_internal::ApplyBinaryMove(problem, adjacency, move, var_of, &cut,
                                                             &y, &x, &energy, &summary);
        unchanged_streak = accepted ? 0 : unchanged_streak + 1;
        if (unchanged_streak >= num_pairs) converged = true;
      }
    }
    energy = problem.EnergyLocal(x);
    if (!run.EndIteration(energy, -std::numeric_limits<double>::infinity())) break;
    if (converged || sweep_start - energy <= options_.energy_tolerance * std::abs(sweep_start)) {
      summary.termination = "converged";
      break;
    }
  }
  run.Finish(labels);
  return summary;
}

}  // namespace artex
