#include "solvers/icm.h"

#include <cmath>
#include <limits>

namespace artex {

MrfSummary IcmSolver::Solve(const MrfProblem& problem, std::vector<int>* labels) {
  MrfSummary summary;
  mrf_internal::SolveRun run(problem, options_, *labels, &summary);
  std::vector<int>& x = run.local();
  const int n = problem.num_nodes();
  const MrfAdjacency adjacency = BuildMrfAdjacency(problem);
  std::vector<double> cost(problem.max_candidates());
  double energy = summary.initial_energy;
  summary.termination = "max_iterations";

  for (int iteration = 0; iteration < options_.max_iterations; ++iteration) {
    const double sweep_start = energy;
    bool changed = false;
    for (int i = 0; i < n; ++i) {
      const int k = problem.num_candidates(i);
      const double* d = problem.candidate_unaries(i);
      for (int a = 0; a < k; ++a) cost[a] = d[a];
      for (int p = adjacency.offsets[i]; p < adjacency.offsets[i + 1]; ++p) {
        const int e = adjacency.edges[p];
        const int s = problem.edge_first(e);
        const int t = problem.edge_second(e);
        for (int a = 0; a < k; ++a) {
          cost[a] += s == i ? problem.PairwiseLocal(e, a, x[t]) : problem.PairwiseLocal(e, x[s], a);
        }
      }
      int best = x[i];
      for (int a = 0; a < k; ++a) {
        if (cost[a] < cost[best]) best = a;  // strict: ties keep the current label
      }
      if (best != x[i]) {
        changed = true;
        x[i] = best;
      }
    }
    energy = problem.EnergyLocal(x);
    if (!run.EndIteration(energy, -std::numeric_limits<double>::infinity())) break;
    if (!changed || sweep_start - energy <= options_.energy_tolerance * std::abs(sweep_start)) {
      summary.termination = "converged";
      break;
    }
  }
  run.Finish(labels);
  return summary;
}

}  // namespace artex
