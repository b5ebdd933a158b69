// Pairwise MRF problems with per-node candidate labels and the solver interface that minimises
// them (view selection for texturing, docs/design.md "Texture", paper eq. 14):
//   E(x) = sum_i D_i(x_i) + lambda * sum_{e=(i,j)} w_e * c_e(x_i, x_j),
// D_i = +inf outside node i's candidate set (a triangle not visible in image l). Layout,
// costs and the guarantees of each backend: docs/mrf.md.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace artex {

// The energy. Nodes store only their candidate labels (finite unaries), sorted ascending; an
// edge stores either nothing (Potts: c_e = [x_i != x_j]) or a K_i x K_j float table over the two
// candidate sets, so memory is O(sum_e K_i K_j) instead of O(E L^2). All validation happens when
// the problem is built: a built problem is always solvable (every node has a finite label).
class MrfProblem {
 public:
  // num_labels: size L of the global label set (e.g. images of the pool); >= 1.
  explicit MrfProblem(int num_labels);

  // Builds N nodes from a dense row-major N x L unary matrix; +inf entries are forbidden labels.
  // Throws artex::Error on a size mismatch, NaN or -inf, or a row without a finite entry.
  static MrfProblem FromDenseUnaries(int num_nodes, int num_labels,
                                     const std::vector<double>& unaries);

  // Adds a node and returns its index. labels: distinct, in [0, L); costs: same length, finite or
  // +inf (+inf drops that label). Throws artex::Error naming the node and the offending entry,
  // including when no finite cost remains.
  int AddNode(const std::vector<int>& labels, const std::vector<double>& costs);
  // Same with `count` labels and costs from arrays.
  int AddNode(const int* labels, const double* costs, int count);
  // Same with a dense row of L costs (+inf = forbidden).
  int AddNodeDense(const std::vector<double>& costs);

  // Adds an edge between existing nodes i != j and returns its index. weight: finite, >= 0.
  // Parallel edges are allowed (their costs add up).
  int AddPottsEdge(int i, int j, double weight);
  // c_e(l_i, l_j) = cost(l_i, l_j) in global labels, evaluated here once for every pair of
  // candidates of i and j and stored in single precision; must be finite there. Equal labels may
  // cost non-zero (the texturing terms have c_e(l, l) = 0). Throws artex::Error on bad input.
  int AddEdge(int i, int j, double weight, const std::function<double(int, int)>& cost);

  // Same with the table given directly: K_i x K_j row-major over the candidates of i and j in
  // ascending label order (num_candidates / candidate_labels); must be finite.
  int AddEdgeTable(int i, int j, double weight, const float* table);
  // Adds the edges k = 0 .. n - 1 between first[k] and second[k] with weight weights[k], as
  // AddEdgeTable would one by one, their tables stored one after the other in `tables` (sum over
  // k of K_first K_second entries; taken over without a copy when the problem has no tables
  // yet). Throws artex::Error naming the first offending edge; nothing is added then.
  void AddEdgeTables(const std::vector<int>& first, const std::vector<int>& second,
                     const std::vector<double>& weights, std::vector<float> tables);
  // Reserves room for this many more nodes, candidates (sum of K_i), edges and table entries
  // (sum of K_i K_j over table edges); optional.
  void Reserve(int nodes, std::int64_t candidates, int edges, std::int64_t table_entries);
  // Global smoothness weight lambda (finite, >= 0; default 1).
  void set_smoothness(double lambda);
  double smoothness() const { return lambda_; }

  int num_nodes() const { return static_cast<int>(node_offsets_.size()) - 1; }
  int num_labels() const { return num_labels_; }
  int num_edges() const { return static_cast<int>(edge_weights_.size()); }

  // Candidates of `node`: K = num_candidates(node) labels (ascending) and their finite unaries.
  int num_candidates(int node) const { return node_offsets_[node + 1] - node_offsets_[node]; }
  const int* candidate_labels(int node) const { return &labels_[node_offsets_[node]]; }
  const double* candidate_unaries(int node) const { return &unaries_[node_offsets_[node]]; }
  int max_candidates() const { return max_candidates_; }
  // Local index of `label` among node's candidates, or -1 (not a candidate / out of range).
  int CandidateIndex(int node, int label) const;
  // D_node(label); +inf when label is not a candidate (or out of range).
  double UnaryCost(int node, int label) const;

  int edge_first(int e) const { return edge_nodes_[2 * e]; }
  int edge_second(int e) const { return edge_nodes_[2 * e + 1]; }
  // The node at the other end of edge e from `node` (one of its two nodes).
  int edge_other(int e, int node) const {
    return edge_nodes_[2 * e] == node ? edge_nodes_[2 * e + 1] : edge_nodes_[2 * e];
  }
  double edge_weight(int e) const { return edge_weights_[e]; }
  // K_first x K_second row-major table of c_e over local candidate indices; nullptr for Potts.
  const float* edge_table(int e) const {
    return table_offsets_[e] < 0 ? nullptr : &tables_[table_offsets_[e]];
  }
  // lambda * w_e * c_e at local candidate indices a (of edge_first) and b (of edge_second).
  inline double PairwiseLocal(int e, int a, int b) const;

  // E(x) for a labelling in global labels. Throws artex::Error when labels.size() != N or a
  // label is outside [0, L); returns +inf when some label is not a candidate of its node.
  double Energy(const std::vector<int>& labels) const;
  // E(x) for local candidate indices (no checks; every index must be in [0, K_i)).
  double EnergyLocal(const std::vector<int>& local) const;
  // True iff labels has N entries, each a candidate of its node; otherwise explains in *why.
  bool IsFeasible(const std::vector<int>& labels, std::string* why = nullptr) const;
  // Global labels <-> local candidate indices (ToLocal requires IsFeasible).
  std::vector<int> ToLocal(const std::vector<int>& labels) const;
  std::vector<int> ToGlobal(const std::vector<int>& local) const;
  // Per-node argmin of the unaries (first minimum), in global labels.
  std::vector<int> UnaryArgmin() const;
  // Bytes held by the problem's arrays.
  std::size_t MemoryBytes() const;

 private:
  // Stores a checked edge whose table (if any, offset >= 0) is already in tables_.
  int AppendEdge(int i, int j, double weight, std::int64_t table_offset);

  int num_labels_;
  double lambda_ = 1.0;
  int max_candidates_ = 0;
  std::vector<int> node_offsets_{0};         // N + 1
  std::vector<int> labels_;                  // sum_i K_i, ascending per node
  std::vector<double> unaries_;              // sum_i K_i
  std::vector<int> edge_nodes_;              // 2 E
  std::vector<double> edge_weights_;         // E
  std::vector<std::int64_t> table_offsets_;  // E; -1 = Potts
  std::vector<float> tables_;                // sum over table edges of K_i K_j
};

inline double MrfProblem::PairwiseLocal(int e, int a, int b) const {
  const double scale = lambda_ * edge_weights_[e];
  const std::int64_t offset = table_offsets_[e];
  const int t = edge_nodes_[2 * e + 1];
  if (offset < 0) {
    return labels_[node_offsets_[edge_nodes_[2 * e]] + a] == labels_[node_offsets_[t] + b] ? 0.0
                                                                                           : scale;
  }
  return scale * tables_[offset + static_cast<std::int64_t>(a) * num_candidates(t) + b];
}

// Incident edges per node (CSR): edges of node i are edges[offsets[i] .. offsets[i+1]).
struct MrfAdjacency {
  std::vector<int> offsets;
  std::vector<int> edges;
};
MrfAdjacency BuildMrfAdjacency(const MrfProblem& problem);

// Nodes having each label as a candidate (CSR over labels): entries offsets[l] .. offsets[l+1]
// of nodes / local hold the node and the label's local index at that node, nodes ascending.
struct MrfLabelIndex {
  std::vector<int> offsets;
  std::vector<int> nodes;
  std::vector<int> local;
};
MrfLabelIndex BuildMrfLabelIndex(const MrfProblem& problem);

enum class MrfSolverType { kAlphaExpansion, kAlphaBetaSwap, kIcm, kTrws };
// "alpha_expansion", "swap", "icm", "trws".
const char* MrfSolverTypeToString(MrfSolverType type);
// Inverse of MrfSolverTypeToString; throws artex::Error listing the valid names.
MrfSolverType ParseMrfSolverType(const std::string& name);
std::vector<MrfSolverType> AllMrfSolverTypes();

// Passed to the progress callback after every iteration (sweep / TRW-S pass pair).
struct MrfIterationInfo {
  int iteration = 0;    // 1-based
  double energy = 0.0;  // best energy so far
  double lower_bound = -std::numeric_limits<double>::infinity();
  double seconds = 0.0;  // since Solve started
};

struct MrfSolverOptions {
  MrfSolverType type = MrfSolverType::kAlphaExpansion;
  // Start from the labelling passed to Solve when it is feasible (e.g. the previous frame's);
  // otherwise, or when false, from the per-node unary argmin.
  bool warm_start = true;
  // Alpha-expansion / swap / ICM: maximum number of sweeps (expansion: one move per label; swap:
  // one move per label pair; ICM: one pass over the nodes). >= 1.
  int max_iterations = 50;
  // Stop when a sweep lowers the energy by <= energy_tolerance * |energy| (0: only when a sweep
  // changes nothing). >= 0.
  double energy_tolerance = 1e-9;
  // Alpha-expansion on problems of at least this many nodes (0: never): the first sweep of each
  // Solve splits the nodes into two halves and a separator (breadth-first levels, so no edge
  // joins the halves), sweeps the halves concurrently with the separator fixed, then sweeps the
  // separator; later sweeps are sequential. Every move is an exact expansion restricted to its
  // part, so the energy still never rises; the result differs from a sequential sweep's but not
  // with the number of threads. >= 0.
  int expansion_parallel_min_nodes = 4096;
  // TRW-S: maximum number of iterations (forward + backward pass each). >= 1.
  int trws_max_iterations = 100;
  // TRW-S: stop when an iteration raises the lower bound by <= trws_bound_tolerance *
  // max(|energy|, |bound|) (Kolmogorov 2006's criterion, relative). >= 0.
  double trws_bound_tolerance = 1e-7;
  // TRW-S: stop when energy - bound <= trws_gap_tolerance * max(|energy|, |bound|) (the labelling
  // is then provably optimal up to that gap). >= 0.
  double trws_gap_tolerance = 1e-9;
  // Wall-clock budget per Solve (seconds, > 0); checked after each iteration. Infinity keeps
  // Solve deterministic.
  double max_seconds = std::numeric_limits<double>::infinity();
  // Called after every iteration; returning false stops the solver ("callback").
  std::function<bool(const MrfIterationInfo&)> callback;

  bool IsValid(std::string* error) const;
};

struct MrfSummary {
  MrfSolverType type = MrfSolverType::kAlphaExpansion;
  double initial_energy = 0.0;  // energy of the starting labelling
  double energy = 0.0;          // energy of the returned labelling (recomputed from scratch)
  // Lower bound on the minimum energy; -inf when the solver provides none.
  double lower_bound = -std::numeric_limits<double>::infinity();
  int iterations = 0;
  double seconds = 0.0;
  std::vector<double> trace;        // energy after each iteration (best so far for TRW-S)
  std::vector<double> bound_trace;  // TRW-S: lower bound after each iteration
  // "converged", "optimal" (zero gap), "max_iterations", "time_limit" or "callback".
  std::string termination;
  bool warm_started = false;
  int accepted_moves = 0;    // expansion / swap: moves that lowered the energy
  long truncated_terms = 0;  // expansion / swap: non-submodular pair terms made submodular

  // energy - lower_bound (+inf without a bound).
  double Gap() const { return energy - lower_bound; }
  std::string BriefReport() const;
};

// Minimises an MrfProblem. Solve reads *labels as the warm start (global labels; see
// MrfSolverOptions::warm_start) and overwrites it with a feasible labelling (size N, every label
// a candidate of its node) whose energy is <= that of the starting labelling. Deterministic.
class MrfSolver {
 public:
  virtual ~MrfSolver() = default;
  virtual MrfSummary Solve(const MrfProblem& problem, std::vector<int>* labels) = 0;

  // Throws artex::Error when options.IsValid fails.
  static std::unique_ptr<MrfSolver> Create(const MrfSolverOptions& options);
};

namespace mrf_internal {

// Shared bookkeeping of the backends: the starting labelling (local indices), clock, trace,
// callback and termination tests.
class SolveRun {
 public:
  SolveRun(const MrfProblem& problem, const MrfSolverOptions& options,
           const std::vector<int>& input_labels, MrfSummary* summary);
  std::vector<int>& local() { return local_; }
  double Seconds() const;
  // Records one finished iteration (energy = current or best energy). Returns false, after
  // setting summary->termination, when the time limit or the callback asks to stop.
  bool EndIteration(double energy, double lower_bound);
  // Recomputes the energy of local(), writes labels (global) and timing into the summary.
  void Finish(std::vector<int>* labels);

 private:
  const MrfProblem& problem_;
  const MrfSolverOptions& options_;
  MrfSummary* summary_;
  std::vector<int> local_;
  std::int64_t start_ns_;
};

}  // namespace mrf_internal

}  // namespace artex
