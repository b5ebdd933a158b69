#include "solvers/alpha_expansion.h"

#include <maxflow/graph.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <new>

namespace artex {
namespace mrf_internal {
namespace {

using Graph = maxflow::Graph<double, double, double>;

// maxflow calls this instead of exit(1) when it cannot allocate memory.
void MaxflowError(const char* /*message*/) { throw std::bad_alloc(); }

}  // namespace

struct BinaryMoveCut::Impl {
  Graph graph{0, 0, &MaxflowError};
};

BinaryMoveCut::BinaryMoveCut() : impl_(std::make_unique<Impl>()) {}
BinaryMoveCut::~BinaryMoveCut() = default;

void BinaryMoveCut::Reset(int num_vars) {
  impl_->graph.reset();  // keeps the node and arc arrays allocated across moves
  if (num_vars > 0) impl_->graph.add_node(num_vars);
}

void BinaryMoveCut::AddUnary(int v, double cost0, double cost1) {
  // The source->v arc is cut when v ends on the sink side (y = 1), v->sink when y = 0.
  const double m = std::min(cost0, cost1);
  impl_->graph.add_tweights(v, cost1 - m, cost0 - m);
}

bool BinaryMoveCut::AddPair(int u, int v, double a, double b, double c, double d, bool cur_u,
                            bool cur_v) {
  bool truncated = false;
  const double excess = a + d - b - c;
  if (excess > 0.0) {
    truncated = true;
    if (!cur_u && cur_v) {
      c += excess;  // current state (0,1) = b stays exact
    } else if (cur_u && !cur_v) {
      b += excess;  // current state (1,0) = c stays exact
    } else {
      b += 0.5 * excess;
      c += 0.5 * excess;
    }
  }
  // E = a + (c - a) y_u + (d - c) y_v + (b + c - a - d)(1 - y_u) y_v.
  AddUnary(u, 0.0, c - a);
  AddUnary(v, 0.0, d - c);
  const double w = b + c - a - d;
  if (w > 0.0) impl_->graph.add_edge(u, v, w, 0.0);
  return truncated;
}

void BinaryMoveCut::Solve(std::vector<char>* y) {
  Graph& g = impl_->graph;
  const int n = g.get_node_num();
  y->assign(n, 0);
  if (n == 0) return;
  g.maxflow();
  for (int v = 0; v < n; ++v) (*y)[v] = g.what_segment(v, Graph::SOURCE) == Graph::SINK;
}

}  // namespace mrf_internal

MrfSummary AlphaExpansionSolver::Solve(const MrfProblem& problem, std::vector<int>* labels) {
  MrfSummary summary;
  mrf_internal::SolveRun run(problem, options_, *labels, &summary);
  std::vector<int>& x = run.local();
  const int n = problem.num_nodes();
  const int num_labels = problem.num_labels();
  const MrfAdjacency adjacency = BuildMrfAdjacency(problem);
  const MrfLabelIndex label_index = BuildMrfLabelIndex(problem);

  double energy = summary.initial_energy;
  std::vector<int> var_of(n, -1);   // move variable of node i, -1 when fixed
  std::vector<int> alpha_k(n, -1);  // local index of alpha at the move variables
  std::vector<int> vars;
  std::vector<char> y;
  mrf_internal::BinaryMoveCut cut;
  int unchanged_streak = 0;  // consecutive expansions that changed nothing
  summary.termination = "max_iterations";

  for (int iteration = 0; iteration < options_.max_iterations; ++iteration) {
    const double sweep_start = energy;
    bool converged = false;
    for (int alpha = 0; alpha < num_labels; ++alpha) {
      for (int i : vars) var_of[i] = -1;
      vars.clear();
      for (int p = label_index.offsets[alpha]; p < label_index.offsets[alpha + 1]; ++p) {
        const int i = label_index.nodes[p];
        alpha_k[i] = label_index.local[p];
        if (alpha_k[i] != x[i]) {
          var_of[i] = static_cast<int>(vars.size());
          vars.push_back(i);
        }
      }
      bool accepted = false;
      if (!vars.empty()) {
        cut.Reset(static_cast<int>(vars.size()));
        for (int v = 0; v < static_cast<int>(vars.size()); ++v) {
          const int i = vars[v];
          const double* d = problem.candidate_unaries(i);
          cut.AddUnary(v, d[x[i]], d[alpha_k[i]]);
          for (int p = adjacency.offsets[i]; p < adjacency.offsets[i + 1]; ++p) {
            const int e = adjacency.edges[p];
            const int s = problem.edge_first(e);
            const int t = problem.edge_second(e);
            const int other = s == i ? t : s;
            if (var_of[other] >= 0) {
              if (s != i) continue;  // a pair of variables is added once, from its first node
              summary.truncated_terms +=
                  cut.AddPair(v, var_of[t], problem.PairwiseLocal(e, x[s], x[t]),
                              problem.PairwiseLocal(e, x[s], alpha_k[t]),
                              problem.PairwiseLocal(e, alpha_k[s], x[t]),
                              problem.PairwiseLocal(e, alpha_k[s], alpha_k[t]), false, false);
            } else if (s == i) {
              cut.AddUnary(v, problem.PairwiseLocal(e, x[s], x[t]),
                           problem.PairwiseLocal(e, alpha_k[s], x[t]));
            } else {
              cut.AddUnary(v, problem.PairwiseLocal(e, x[s], x[t]),
                           problem.PairwiseLocal(e, x[s], alpha_k[t]));
            }
          }
        }
        cut.Solve(&y);
        // True energy change of the move (the cut minimised a majoriser of it).
        double delta = 0.0;
        bool any = false;
        for (int v = 0; v < static_cast<int>(vars.size()); ++v) {
          if (!y[v]) continue;
          any = true;
          const int i = vars[v];
          const double* d = problem.candidate_unaries(i);
          delta += d[alpha_k[i]] - d[x[i]];
          for (int p = adjacency.offsets[i]; p < adjacency.offsets[i + 1]; ++p) {
            const int e = adjacency.edges[p];
            const int s = problem.edge_first(e);
            const int t = problem.edge_second(e);
            const int other = s == i ? t : s;
            const bool other_moves = var_of[other] >= 0 && y[var_of[other]];
            if (other_moves && s != i) continue;  // counted from the first node
            const int new_s = (s == i || other_moves) ? alpha_k[s] : x[s];
            const int new_t = (t == i || other_moves) ? alpha_k[t] : x[t];
            delta += problem.PairwiseLocal(e, new_s, new_t) - problem.PairwiseLocal(e, x[s], x[t]);
          }
        }
        if (any && delta < 0.0) {
          for (int v = 0; v < static_cast<int>(vars.size()); ++v) {
            if (y[v]) x[vars[v]] = alpha_k[vars[v]];
          }
          energy += delta;
          accepted = true;
          ++summary.accepted_moves;
        }
      }
      unchanged_streak = accepted ? 0 : unchanged_streak + 1;
      if (unchanged_streak >= num_labels) {
        converged = true;  // every label's expansion in a row left the labelling unchanged
        break;
      }
    }
    energy = problem.EnergyLocal(x);  // drop the rounding of the accumulated deltas
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
