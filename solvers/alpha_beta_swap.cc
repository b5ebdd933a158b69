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
  // Local indices of alpha (k[0]) and beta (k[1]) at each move variable.
  std::vector<int> k_alpha, k_beta, vars;
  std::vector<char> y, y_now;
  mrf_internal::BinaryMoveCut cut;
  const int num_pairs = num_labels * (num_labels - 1) / 2;
  int unchanged_streak = 0;
  summary.termination = "max_iterations";

  for (int iteration = 0; iteration < options_.max_iterations; ++iteration) {
    const double sweep_start = energy;
    bool converged = num_pairs == 0;
    for (int alpha = 0; alpha < num_labels && !converged; ++alpha) {
      for (int beta = alpha + 1; beta < num_labels && !converged; ++beta) {
        for (int i : vars) var_of[i] = -1;
        vars.clear();
        k_alpha.clear();
        k_beta.clear();
        y_now.clear();
        // Every move variable has alpha as a candidate.
        for (int p = label_index.offsets[alpha]; p < label_index.offsets[alpha + 1]; ++p) {
          const int i = label_index.nodes[p];
          const int label = problem.candidate_labels(i)[x[i]];
          if (label != alpha && label != beta) continue;
          const int kb = problem.CandidateIndex(i, beta);
          if (kb < 0) continue;
          var_of[i] = static_cast<int>(vars.size());
          vars.push_back(i);
          k_alpha.push_back(label_index.local[p]);
          k_beta.push_back(kb);
          y_now.push_back(label == beta);
        }
        bool accepted = false;
        const int num_vars = static_cast<int>(vars.size());
        if (num_vars > 0) {
          cut.Reset(num_vars);
          auto move_label = [&](int v, bool to_beta) { return to_beta ? k_beta[v] : k_alpha[v]; };
          for (int v = 0; v < num_vars; ++v) {
            const int i = vars[v];
            const double* d = problem.candidate_unaries(i);
            cut.AddUnary(v, d[k_alpha[v]], d[k_beta[v]]);
            for (int p = adjacency.offsets[i]; p < adjacency.offsets[i + 1]; ++p) {
              const int e = adjacency.edges[p];
              const int s = problem.edge_first(e);
              const int t = problem.edge_second(e);
              const int other = s == i ? t : s;
              const int w = var_of[other];
              if (w >= 0) {
                if (s != i) continue;  // added once, from the first node
                summary.truncated_terms +=
                    cut.AddPair(v, w, problem.PairwiseLocal(e, k_alpha[v], k_alpha[w]),
                                problem.PairwiseLocal(e, k_alpha[v], k_beta[w]),
                                problem.PairwiseLocal(e, k_beta[v], k_alpha[w]),
                                problem.PairwiseLocal(e, k_beta[v], k_beta[w]), y_now[v], y_now[w]);
              } else if (s == i) {
                cut.AddUnary(v, problem.PairwiseLocal(e, k_alpha[v], x[t]),
                             problem.PairwiseLocal(e, k_beta[v], x[t]));
              } else {
                cut.AddUnary(v, problem.PairwiseLocal(e, x[s], k_alpha[v]),
                             problem.PairwiseLocal(e, x[s], k_beta[v]));
              }
            }
          }
          cut.Solve(&y);
          double delta = 0.0;
          bool any = false;
          for (int v = 0; v < num_vars; ++v) {
            if (y[v] == y_now[v]) continue;
            any = true;
            const int i = vars[v];
            const double* d = problem.candidate_unaries(i);
            delta += d[move_label(v, y[v])] - d[x[i]];
            for (int p = adjacency.offsets[i]; p < adjacency.offsets[i + 1]; ++p) {
              const int e = adjacency.edges[p];
              const int s = problem.edge_first(e);
              const int t = problem.edge_second(e);
              const int other = s == i ? t : s;
              const int w = var_of[other];
              const bool other_moves = w >= 0 && y[w] != y_now[w];
              if (other_moves && s != i) continue;  // counted from the first node
              const int new_i = move_label(v, y[v]);
              const int new_other = other_moves ? move_label(w, y[w]) : x[other];
              const double after = s == i ? problem.PairwiseLocal(e, new_i, new_other)
                                          : problem.PairwiseLocal(e, new_other, new_i);
              delta += after - problem.PairwiseLocal(e, x[s], x[t]);
            }
          }
          if (any && delta < 0.0) {
            for (int v = 0; v < num_vars; ++v) x[vars[v]] = move_label(v, y[v]);
            energy += delta;
            accepted = true;
            ++summary.accepted_moves;
          }
        }
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
