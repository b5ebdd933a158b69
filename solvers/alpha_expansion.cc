#include "solvers/alpha_expansion.h"

#include <maxflow/graph.h>
#include <tbb/parallel_invoke.h>

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

// Cache-line aligned (and so padded): cuts of parts sweeping concurrently are allocated one
// after the other, and max-flow writes its graph's bookkeeping all the time.
struct alignas(64) BinaryMoveCut::Impl {
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

std::vector<char> BisectByLevels(const MrfProblem& problem, const MrfAdjacency& adjacency) {
  const int n = problem.num_nodes();
  std::vector<int> level(n, -1);
  std::vector<int> order;  // breadth-first order, components one after another
  order.reserve(n);
  int next_level = 0;
  for (int root = 0; root < n; ++root) {
    if (level[root] >= 0) continue;
    level[root] = next_level;
    order.push_back(root);
    for (std::size_t k = order.size() - 1; k < order.size(); ++k) {
      const int i = order[k];
      next_level = std::max(next_level, level[i] + 1);
      for (int p = adjacency.offsets[i]; p < adjacency.offsets[i + 1]; ++p) {
        const int e = adjacency.edges[p];
        const int j = problem.edge_other(e, i);
        if (level[j] < 0) {
          level[j] = level[i] + 1;
          order.push_back(j);
        }
      }
    }
  }
  // Work per level: candidates per node (the move variables an expansion sweep visits).
  std::vector<long> work(next_level + 1, 0);
  long total = 0;
  for (int i = 0; i < n; ++i) {
    work[level[i]] += problem.num_candidates(i);
    total += problem.num_candidates(i);
  }
  int separator = 0;
  for (long below = 0; separator < next_level; ++separator) {
    if (2 * (below + work[separator]) >= total) break;
    below += work[separator];
  }
  std::vector<char> part(n);
  for (int i = 0; i < n; ++i)
    part[i] = level[i] < separator ? 0 : level[i] > separator ? 1 : kSeparatorPart;
  return part;
}

namespace {

// The label index restricted to the nodes of one part.
MrfLabelIndex RestrictLabelIndex(const MrfLabelIndex& index, const std::vector<char>& part,
                                 char which) {
  MrfLabelIndex out;
  const int num_labels = static_cast<int>(index.offsets.size()) - 1;
  out.offsets.assign(num_labels + 1, 0);
  for (int l = 0; l < num_labels; ++l) {
    for (int p = index.offsets[l]; p < index.offsets[l + 1]; ++p) {
      if (part[index.nodes[p]] != which) continue;
      out.nodes.push_back(index.nodes[p]);
      out.local.push_back(index.local[p]);
    }
    out.offsets[l + 1] = static_cast<int>(out.nodes.size());
  }
  return out;
}

// Per-label flags of one part, padded so that the flags of parts sweeping concurrently never
// share a cache line (the padding stays 0).
constexpr int kFlagPadding = 64;
std::vector<char> LabelFlags(int num_labels, char value) {
  std::vector<char> flags(num_labels + kFlagPadding, 0);
  std::fill(flags.begin(), flags.begin() + num_labels, value);
  return flags;
}

// One expansion sweep over the nodes of one label index (all nodes, or one part with the other
// nodes fixed), with its own cut, move, node-to-variable map and energy bookkeeping. The two
// halves sweep concurrently, each on its own copy of the labelling (their nodes interleave in
// memory: shared arrays would be written from both threads within the same cache lines);
// aligned for the same reason.
struct alignas(64) Sweeper {
  const MrfProblem* problem;
  const MrfAdjacency* adjacency;
  const MrfLabelIndex* labels;  // the nodes this sweeper moves
  std::vector<char> dirty;      // labels whose expansion might still lower the energy (padded)
  mrf_internal::BinaryMove move;
  std::vector<char> y;
  mrf_internal::BinaryMoveCut* cut;  // this sweeper's own
  std::vector<int> var_of;           // move variable of node i, -1 when fixed
  MrfSummary counts;                 // accepted_moves, truncated_terms

  Sweeper(const MrfProblem& p, const MrfAdjacency& a, const MrfLabelIndex& l,
          mrf_internal::BinaryMoveCut* c)
      : problem(&p),
        adjacency(&a),
        labels(&l),
        dirty(LabelFlags(p.num_labels(), 1)),
        cut(c),
        var_of(p.num_nodes(), -1) {}

  // A label's move depends only on the labels of its variables (nodes having it as a candidate)
  // and of their neighbours: marks dirty the labels whose move node i's label enters.
  void MarkDirtyAround(int i) {
    for (int k = 0; k < problem->num_candidates(i); ++k) dirty[problem->candidate_labels(i)[k]] = 1;
    for (int p = adjacency->offsets[i]; p < adjacency->offsets[i + 1]; ++p) {
      const int e = adjacency->edges[p];
      const int j = problem->edge_other(e, i);
      for (int k = 0; k < problem->num_candidates(j); ++k)
        dirty[problem->candidate_labels(j)[k]] = 1;
    }
  }

  // One expansion per dirty label of this sweeper's nodes.
  void Sweep(std::vector<int>* x) {
    const MrfLabelIndex& index = *labels;
    double energy_change = 0.0;  // ApplyBinaryMove's running sum (the caller re-evaluates)
    for (int alpha = 0; alpha < problem->num_labels(); ++alpha) {
      if (!dirty[alpha]) continue;
      // A label is clean after an expansion that changed nothing, or after an accepted exact
      // move (no majorised pair term: the labelling is then optimal over the move space, and
      // the next expansion's move space is a subset of it), until a node in its neighbourhood
      // changes.
      dirty[alpha] = 0;
      for (int i : move.vars) var_of[i] = -1;
      move.Clear();
      for (int p = index.offsets[alpha]; p < index.offsets[alpha + 1]; ++p) {
        const int i = index.nodes[p];
        const int alpha_k = index.local[p];
        if (alpha_k != (*x)[i]) {
          var_of[i] = move.size();
          move.Add(i, (*x)[i], alpha_k, false);
        }
      }
      if (move.size() == 0) continue;
      const long truncated_before = counts.truncated_terms;
      if (!mrf_internal::ApplyBinaryMove(*problem, *adjacency, move, var_of, cut, &y, x,
                                         &energy_change, &counts))
        continue;
      for (int v = 0; v < move.size(); ++v) {
        if (y[v] == move.current[v]) continue;
        MarkDirtyAround(move.vars[v]);
      }
      dirty[alpha] = counts.truncated_terms > truncated_before;
    }
    for (int i : move.vars) var_of[i] = -1;
    move.Clear();
  }
};

bool AnyDirty(const std::vector<char>& dirty) {
  return std::find(dirty.begin(), dirty.end(), 1) != dirty.end();
}

}  // namespace

}  // namespace mrf_internal

AlphaExpansionSolver::AlphaExpansionSolver(const MrfSolverOptions& options) : options_(options) {
  for (auto& cut : cuts_) cut = std::make_unique<mrf_internal::BinaryMoveCut>();
}

AlphaExpansionSolver::~AlphaExpansionSolver() = default;

MrfSummary AlphaExpansionSolver::Solve(const MrfProblem& problem, std::vector<int>* labels) {
  using mrf_internal::Sweeper;
  MrfSummary summary;
  mrf_internal::SolveRun run(problem, options_, *labels, &summary);
  std::vector<int>& x = run.local();
  const int n = problem.num_nodes();
  // Parallel sweeps: two parts sweep concurrently with the separator fixed, then the separator.
  const bool parallel =
      options_.expansion_parallel_min_nodes > 0 && n >= options_.expansion_parallel_min_nodes;
  MrfAdjacency adjacency;
  MrfLabelIndex label_index;
  std::vector<char> part;
  MrfLabelIndex part_index[3];
  if (parallel) {
    // The node-order passes of large problems overlap.
    tbb::parallel_invoke(
        [&] {
          adjacency = BuildMrfAdjacency(problem);
          part = mrf_internal::BisectByLevels(problem, adjacency);
        },
        [&] { label_index = BuildMrfLabelIndex(problem); });
    const auto restrict_to = [&](int k) {
      part_index[k] = mrf_internal::RestrictLabelIndex(label_index, part, static_cast<char>(k));
    };
    tbb::parallel_invoke([&] { restrict_to(0); }, [&] { restrict_to(1); }, [&] { restrict_to(2); });
  } else {
    adjacency = BuildMrfAdjacency(problem);
    label_index = BuildMrfLabelIndex(problem);
  }
  Sweeper whole(problem, adjacency, label_index, cuts_[0].get());
  Sweeper sides[2] = {Sweeper(problem, adjacency, part_index[0], cuts_[1].get()),
                      Sweeper(problem, adjacency, part_index[1], cuts_[2].get())};
  Sweeper separator(problem, adjacency, part_index[static_cast<int>(mrf_internal::kSeparatorPart)],
                    cuts_[3].get());
  std::vector<int> side_x[2];  // the halves' copies of the labelling

  double energy = summary.initial_energy;
  summary.termination = "max_iterations";
  // The first sweep in parallel, then sequential sweeps over all nodes (from every label), so
  // that "converged" always means that no expansion move lowers the energy (measured: parallel
  // sweeps until they stall and then sequential ones converge slower than this).
  bool split = parallel;
  for (int iteration = 0; iteration < options_.max_iterations; ++iteration) {
    const double sweep_start = energy;
    bool converged = false;
    if (!split) {
      whole.Sweep(&x);
      converged = !mrf_internal::AnyDirty(whole.dirty);
    } else {
      side_x[0] = x;
      side_x[1] = x;
      tbb::parallel_invoke([&] { sides[0].Sweep(&side_x[0]); },
                           [&] { sides[1].Sweep(&side_x[1]); });
      for (int i = 0; i < n; ++i)
        if (part[i] != mrf_internal::kSeparatorPart) x[i] = side_x[static_cast<int>(part[i])][i];
      separator.Sweep(&x);  // from every label (all start dirty)
    }
    energy = problem.EnergyLocal(x);  // drop the rounding of the accumulated deltas
    if (!run.EndIteration(energy, -std::numeric_limits<double>::infinity())) break;
    if (split) {
      split = false;  // whole.dirty: every label
      continue;
    }
    if (converged || sweep_start - energy <= options_.energy_tolerance * std::abs(sweep_start)) {
      summary.termination = "converged";
      break;
    }
  }
  for (const Sweeper* s : {&whole, &sides[0], &sides[1], &separator}) {
    summary.accepted_moves += s->counts.accepted_moves;
    summary.truncated_terms += s->counts.truncated_terms;
  }
  run.Finish(labels);
  return summary;
}

}  // namespace artex
