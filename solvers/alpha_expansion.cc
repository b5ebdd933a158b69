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

namespace {

long BuildMoveCut(const MrfProblem& problem, const MrfAdjacency& adjacency, const BinaryMove& move,
                  const std::vector<int>& var_of, const std::vector<int>& x, BinaryMoveCut* cut) {
  long truncated = 0;
  cut->Reset(move.size());
  for (int v = 0; v < move.size(); ++v) {
    const int i = move.vars[v];
    const double* d = problem.candidate_unaries(i);
    cut->AddUnary(v, d[move.label0[v]], d[move.label1[v]]);
    for (int p = adjacency.offsets[i]; p < adjacency.offsets[i + 1]; ++p) {
      const int e = adjacency.edges[p];
      const int s = problem.edge_first(e);
      const int t = problem.edge_second(e);
      const int other = s == i ? t : s;
      const int w = var_of[other];
      if (w >= 0) {
        if (s != i) continue;  // a pair of variables is added once, from its first node
        truncated += cut->AddPair(v, w, problem.PairwiseLocal(e, move.label0[v], move.label0[w]),
                                  problem.PairwiseLocal(e, move.label0[v], move.label1[w]),
                                  problem.PairwiseLocal(e, move.label1[v], move.label0[w]),
                                  problem.PairwiseLocal(e, move.label1[v], move.label1[w]),
                                  move.current[v], move.current[w]);
      } else if (s == i) {
        cut->AddUnary(v, problem.PairwiseLocal(e, move.label0[v], x[t]),
                      problem.PairwiseLocal(e, move.label1[v], x[t]));
      } else {
        cut->AddUnary(v, problem.PairwiseLocal(e, x[s], move.label0[v]),
                      problem.PairwiseLocal(e, x[s], move.label1[v]));
      }
    }
  }
  return truncated;
}

bool MoveEnergyChange(const MrfProblem& problem, const MrfAdjacency& adjacency,
                      const BinaryMove& move, const std::vector<int>& var_of,
                      const std::vector<int>& x, const std::vector<char>& y, double* delta) {
  *delta = 0.0;
  bool any = false;
  for (int v = 0; v < move.size(); ++v) {
    if (y[v] == move.current[v]) continue;
    any = true;
    const int i = move.vars[v];
    const double* d = problem.candidate_unaries(i);
    const int new_i = move.Label(v, y[v]);
    *delta += d[new_i] - d[x[i]];
    for (int p = adjacency.offsets[i]; p < adjacency.offsets[i + 1]; ++p) {
      const int e = adjacency.edges[p];
      const int s = problem.edge_first(e);
      const int t = problem.edge_second(e);
      const int other = s == i ? t : s;
      const int w = var_of[other];
      const bool other_moves = w >= 0 && y[w] != move.current[w];
      if (other_moves && s != i) continue;  // counted from the first node
      const int new_other = other_moves ? move.Label(w, y[w]) : x[other];
      const double after = s == i ? problem.PairwiseLocal(e, new_i, new_other)
                                  : problem.PairwiseLocal(e, new_other, new_i);
      *delta += after - problem.PairwiseLocal(e, x[s], x[t]);
    }
  }
  return any;
}

}  // namespace

bool ApplyBinaryMove(const MrfProblem& problem, const MrfAdjacency& adjacency,
                     const BinaryMove& move, const std::vector<int>& var_of, BinaryMoveCut* cut,
                     std::vector<char>* y, std::vector<int>* x, double* energy,
                     MrfSummary* summary) {
  summary->truncated_terms += BuildMoveCut(problem, adjacency, move, var_of, *x, cut);
  cut->Solve(y);
  double delta = 0.0;
  if (!MoveEnergyChange(problem, adjacency, move, var_of, *x, *y, &delta) || !(delta < 0.0))
    return false;
  for (int v = 0; v < move.size(); ++v) (*x)[move.vars[v]] = move.Label(v, (*y)[v]);
  *energy += delta;
  ++summary->accepted_moves;
  return true;
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
  std::vector<int> var_of(n, -1);  // move variable of node i, -1 when fixed
  mrf_internal::BinaryMove move;   // y = 0 keeps the current label, y = 1 switches to alpha
  std::vector<char> y;
  mrf_internal::BinaryMoveCut cut;
  // A label is dirty while its expansion might still lower the energy. Its move depends only on
  // the labels of its variables (nodes having it as a candidate) and of their neighbours, so it
  // is clean after an expansion that changed nothing, or after an accepted exact move (no
  // majorised pair term: the labelling is then optimal over the move space, and the next
  // expansion's move space is a subset of it), until a node in that neighbourhood changes.
  std::vector<char> dirty(num_labels, 1);
  const auto mark_dirty_around = [&](int i) {
    for (int k = 0; k < problem.num_candidates(i); ++k) dirty[problem.candidate_labels(i)[k]] = 1;
    for (int p = adjacency.offsets[i]; p < adjacency.offsets[i + 1]; ++p) {
      const int e = adjacency.edges[p];
      const int j = problem.edge_first(e) == i ? problem.edge_second(e) : problem.edge_first(e);
      for (int k = 0; k < problem.num_candidates(j); ++k) dirty[problem.candidate_labels(j)[k]] = 1;
    }
  };
  summary.termination = "max_iterations";

  for (int iteration = 0; iteration < options_.max_iterations; ++iteration) {
    const double sweep_start = energy;
    for (int alpha = 0; alpha < num_labels; ++alpha) {
      if (!dirty[alpha]) continue;
      dirty[alpha] = 0;
      for (int i : move.vars) var_of[i] = -1;
      move.Clear();
      for (int p = label_index.offsets[alpha]; p < label_index.offsets[alpha + 1]; ++p) {
        const int i = label_index.nodes[p];
        const int alpha_k = label_index.local[p];
        if (alpha_k != x[i]) {
          var_of[i] = move.size();
          move.Add(i, x[i], alpha_k, false);
        }
      }
      if (move.size() == 0) continue;
      const long truncated_before = summary.truncated_terms;
      if (!mrf_internal::ApplyBinaryMove(problem, adjacency, move, var_of, &cut, &y, &x, &energy,
                                         &summary))
        continue;
      for (int v = 0; v < move.size(); ++v)
        if (y[v] != move.current[v]) mark_dirty_around(move.vars[v]);
      dirty[alpha] = summary.truncated_terms > truncated_before;
    }
    energy = problem.EnergyLocal(x);  // drop the rounding of the accumulated deltas
    if (!run.EndIteration(energy, -std::numeric_limits<double>::infinity())) break;
    const bool converged = std::find(dirty.begin(), dirty.end(), 1) == dirty.end();
    if (converged || sweep_start - energy <= options_.energy_tolerance * std::abs(sweep_start)) {
      summary.termination = "converged";
      break;
    }
  }
  run.Finish(labels);
  return summary;
}

}  // namespace artex
