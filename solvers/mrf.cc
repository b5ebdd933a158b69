#include "solvers/mrf.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>
#include <sstream>

#include "models/error.h"
#include "models/numeric.h"
#include "solvers/alpha_beta_swap.h"
#include "solvers/alpha_expansion.h"
#include "solvers/icm.h"
#include "solvers/trws.h"

namespace artex {
namespace {

std::int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

MrfProblem::MrfProblem(int num_labels) : num_labels_(num_labels) {
  if (num_labels < 1) {
    throw Error("MrfProblem: num_labels: expected >= 1, found " + std::to_string(num_labels));
  }
}

MrfProblem MrfProblem::FromDenseUnaries(int num_nodes, int num_labels,
                                        const std::vector<double>& unaries) {
  if (num_nodes < 0) {
    throw Error("MrfProblem::FromDenseUnaries: num_nodes: expected >= 0, found " +
                std::to_string(num_nodes));
  }
  MrfProblem problem(num_labels);
  const std::size_t expected = static_cast<std::size_t>(num_nodes) * num_labels;
  if (unaries.size() != expected) {
    throw Error("MrfProblem::FromDenseUnaries: unaries: expected num_nodes * num_labels = " +
                std::to_string(expected) + " entries, found " + std::to_string(unaries.size()));
  }
  for (int i = 0; i < num_nodes; ++i) {
    problem.AddNodeDense(std::vector<double>(unaries.begin() + std::size_t(i) * num_labels,
                                             unaries.begin() + std::size_t(i + 1) * num_labels));
  }
  return problem;
}

int MrfProblem::AddNode(const std::vector<int>& labels, const std::vector<double>& costs) {
  if (labels.size() != costs.size()) {
    throw Error("MrfProblem::AddNode (node " + std::to_string(num_nodes()) +
                "): costs: expected one per label (" + std::to_string(labels.size()) + "), found " +
                std::to_string(costs.size()));
  }
  return AddNode(labels.data(), costs.data(), static_cast<int>(labels.size()));
}

int MrfProblem::AddNode(const int* labels, const double* costs, int count) {
  const int node = num_nodes();
  // Messages are built only on failure (AddNode runs once per node of large problems).
  const auto fail = [node](const std::string& what) {
    throw Error("MrfProblem::AddNode (node " + std::to_string(node) + "): " + what);
  };
  const std::size_t begin = labels_.size();
  bool ascending = true;
  for (int k = 0; k < count; ++k) {
    if (labels[k] < 0 || labels[k] >= num_labels_) {
      fail("labels[" + std::to_string(k) + "]: expected in [0, " + std::to_string(num_labels_) +
           "), found " + std::to_string(labels[k]));
    }
    if (std::isnan(costs[k]) || costs[k] == -kInf) {
      fail("costs[" + std::to_string(k) + "]: expected finite or +inf, found " +
           std::to_string(costs[k]));
    }
    if (k > 0 && labels[k] <= labels[k - 1]) ascending = false;
  }
  if (!ascending) {
    std::vector<int> sorted_labels(labels, labels + count);
    std::sort(sorted_labels.begin(), sorted_labels.end());
    const auto dup = std::adjacent_find(sorted_labels.begin(), sorted_labels.end());
    if (dup != sorted_labels.end())
      fail("labels: expected distinct labels, found " + std::to_string(*dup) + " twice");
    std::vector<std::pair<int, double>> entries;
    for (int k = 0; k < count; ++k)
      if (costs[k] < kInf) entries.emplace_back(labels[k], costs[k]);
    std::sort(entries.begin(), entries.end());
    for (const auto& [label, cost] : entries) {
      labels_.push_back(label);
      unaries_.push_back(cost);
    }
  } else {
    for (int k = 0; k < count; ++k) {
      if (!(costs[k] < kInf)) continue;
      labels_.push_back(labels[k]);
      unaries_.push_back(costs[k]);
    }
  }
  const int kept = static_cast<int>(labels_.size() - begin);
  if (kept == 0) {
    fail(
        "costs: expected at least one finite unary (a node must have a feasible label), found "
        "none");
  }
  node_offsets_.push_back(static_cast<int>(labels_.size()));
  max_candidates_ = std::max(max_candidates_, kept);
  return node;
}

void MrfProblem::Reserve(int nodes, std::int64_t candidates, int edges,
                         std::int64_t table_entries) {
  node_offsets_.reserve(node_offsets_.size() + nodes);
  labels_.reserve(labels_.size() + candidates);
  unaries_.reserve(unaries_.size() + candidates);
  edge_nodes_.reserve(edge_nodes_.size() + 2 * static_cast<std::size_t>(edges));
  edge_weights_.reserve(edge_weights_.size() + edges);
  table_offsets_.reserve(table_offsets_.size() + edges);
  tables_.reserve(tables_.size() + table_entries);
}

int MrfProblem::AddNodeDense(const std::vector<double>& costs) {
  if (static_cast<int>(costs.size()) != num_labels_) {
    throw Error("MrfProblem::AddNodeDense (node " + std::to_string(num_nodes()) +
                "): costs: expected " + std::to_string(num_labels_) + " entries, found " +
                std::to_string(costs.size()));
  }
  std::vector<int> labels(num_labels_);
  std::iota(labels.begin(), labels.end(), 0);
  return AddNode(labels, costs);
}

namespace {

void CheckEdge(const MrfProblem& p, int i, int j, double weight, const char* function) {
  const auto fail = [&](const std::string& what) {
    throw Error(std::string("MrfProblem::") + function + " (edge " + std::to_string(p.num_edges()) +
                "): " + what);
  };
  for (int node : {i, j}) {
    if (node < 0 || node >= p.num_nodes()) {
      fail("node: expected in [0, " + std::to_string(p.num_nodes()) + "), found " +
           std::to_string(node));
    }
  }
  if (i == j) fail("nodes: expected two distinct nodes, found " + std::to_string(i) + " twice");
  if (!std::isfinite(weight) || weight < 0.0)
    fail("weight: expected finite and >= 0, found " + std::to_string(weight));
}

// Throws unless the `size` entries of edge `edge`'s table are finite.
void CheckTable(const float* table, std::int64_t size, std::int64_t edge, const char* function) {
  for (std::int64_t k = 0; k < size; ++k) {
    if (!std::isfinite(table[k])) {
      throw Error(std::string("MrfProblem::") + function + " (edge " + std::to_string(edge) +
                  "): table[" + std::to_string(k) + "]: expected finite, found " +
                  std::to_string(table[k]));
    }
  }
}

}  // namespace

int MrfProblem::AddPottsEdge(int i, int j, double weight) {
  CheckEdge(*this, i, j, weight, "AddPottsEdge");
  return AppendEdge(i, j, weight, -1);
}

int MrfProblem::AddEdge(int i, int j, double weight, const std::function<double(int, int)>& cost) {
  CheckEdge(*this, i, j, weight, "AddEdge");
  if (!cost) throw Error("MrfProblem::AddEdge: cost: expected a callable, found an empty one");
  const int ki = num_candidates(i);
  const int kj = num_candidates(j);
  const std::int64_t offset = static_cast<std::int64_t>(tables_.size());
  tables_.resize(tables_.size() + static_cast<std::size_t>(ki) * kj);
  const int* li = candidate_labels(i);
  const int* lj = candidate_labels(j);
  for (int a = 0; a < ki; ++a) {
    for (int b = 0; b < kj; ++b) {
      const double c = cost(li[a], lj[b]);
      if (!std::isfinite(c)) {
        tables_.resize(offset);
        throw Error("MrfProblem::AddEdge (edge " + std::to_string(num_edges()) + "): cost(" +
                    std::to_string(li[a]) + ", " + std::to_string(lj[b]) +
                    "): expected finite, found " + std::to_string(c));
      }
      tables_[offset + a * kj + b] = static_cast<float>(c);
    }
  }
  return AppendEdge(i, j, weight, offset);
}

int MrfProblem::AddEdgeTable(int i, int j, double weight, const float* table) {
  CheckEdge(*this, i, j, weight, "AddEdgeTable");
  const std::int64_t size = static_cast<std::int64_t>(num_candidates(i)) * num_candidates(j);
  CheckTable(table, size, num_edges(), "AddEdgeTable");
  const std::int64_t offset = static_cast<std::int64_t>(tables_.size());
  tables_.insert(tables_.end(), table, table + size);
  return AppendEdge(i, j, weight, offset);
}

void MrfProblem::AddEdgeTables(const std::vector<int>& first, const std::vector<int>& second,
                               const std::vector<double>& weights, std::vector<float> tables) {
  const std::size_t n = first.size();
  if (second.size() != n || weights.size() != n) {
    throw Error(
        "MrfProblem::AddEdgeTables: expected as many second nodes and weights as first "
        "nodes (" +
        std::to_string(n) + "), found " + std::to_string(second.size()) + " and " +
        std::to_string(weights.size()));
  }
  // One quick pass over the edges and one over the tables (large problems); only when they
  // find something does the detailed pass run, to name it.
  const int nodes = num_nodes();
  bool valid = true;
  std::int64_t size = 0;
  for (std::size_t k = 0; k < n && valid; ++k) {
    const int i = first[k], j = second[k];
    valid = i >= 0 && i < nodes && j >= 0 && j < nodes && i != j && weights[k] >= 0.0 &&
            weights[k] <= std::numeric_limits<double>::max();
    if (valid) size += static_cast<std::int64_t>(num_candidates(i)) * num_candidates(j);
  }
  bool finite = true;
  for (const float t : tables) finite &= std::abs(t) <= std::numeric_limits<float>::max();
  if (!valid || !finite || size != static_cast<std::int64_t>(tables.size())) {
    const int e0 = num_edges();
    size = 0;
    for (std::size_t k = 0; k < n; ++k) {
      CheckEdge(*this, first[k], second[k], weights[k], "AddEdgeTables");
      const std::int64_t entries =
          static_cast<std::int64_t>(num_candidates(first[k])) * num_candidates(second[k]);
      if (size + entries > static_cast<std::int64_t>(tables.size())) {
        throw Error("MrfProblem::AddEdgeTables (edge " + std::to_string(e0 + k) +
                    "): tables: expected at least " + std::to_string(size + entries) +
                    " entries, found " + std::to_string(tables.size()));
      }
      CheckTable(tables.data() + size, entries, e0 + static_cast<std::int64_t>(k), "AddEdgeTables");
      size += entries;
    }
    throw Error("MrfProblem::AddEdgeTables: tables: expected " + std::to_string(size) +
                " entries, found " + std::to_string(tables.size()));
  }
  std::int64_t offset = static_cast<std::int64_t>(tables_.size());
  if (tables_.empty())
    tables_ = std::move(tables);
  else
    tables_.insert(tables_.end(), tables.begin(), tables.end());
  const std::size_t base = edge_weights_.size();
  edge_nodes_.resize(2 * (base + n));
  edge_weights_.insert(edge_weights_.end(), weights.begin(), weights.end());
  table_offsets_.resize(base + n);
  for (std::size_t k = 0; k < n; ++k) {
    edge_nodes_[2 * (base + k)] = first[k];
    edge_nodes_[2 * (base + k) + 1] = second[k];
    table_offsets_[base + k] = offset;
    offset += static_cast<std::int64_t>(num_candidates(first[k])) * num_candidates(second[k]);
  }
}

int MrfProblem::AppendEdge(int i, int j, double weight, std::int64_t table_offset) {
  edge_nodes_.push_back(i);
  edge_nodes_.push_back(j);
  edge_weights_.push_back(weight);
  table_offsets_.push_back(table_offset);
  return num_edges() - 1;
}

void MrfProblem::set_smoothness(double lambda) {
  if (!std::isfinite(lambda) || lambda < 0.0) {
    throw Error("MrfProblem::set_smoothness: lambda: expected finite and >= 0, found " +
                std::to_string(lambda));
  }
  lambda_ = lambda;
}

int MrfProblem::CandidateIndex(int node, int label) const {
  const int* begin = candidate_labels(node);
  const int* end = begin + num_candidates(node);
  const int* it = std::lower_bound(begin, end, label);
  return (it != end && *it == label) ? static_cast<int>(it - begin) : -1;
}

double MrfProblem::UnaryCost(int node, int label) const {
  const int k = CandidateIndex(node, label);
  return k < 0 ? kInf : candidate_unaries(node)[k];
}

double MrfProblem::EnergyLocal(const std::vector<int>& local) const {
  double energy = 0.0;
  for (int i = 0; i < num_nodes(); ++i) energy += candidate_unaries(i)[local[i]];
  for (int e = 0; e < num_edges(); ++e) {
    energy += PairwiseLocal(e, local[edge_first(e)], local[edge_second(e)]);
  }
  return energy;
}

double MrfProblem::Energy(const std::vector<int>& labels) const {
  if (static_cast<int>(labels.size()) != num_nodes()) {
    throw Error("MrfProblem::Energy: labels: expected " + std::to_string(num_nodes()) +
                " entries, found " + std::to_string(labels.size()));
  }
  for (int i = 0; i < num_nodes(); ++i) {
    if (labels[i] < 0 || labels[i] >= num_labels_) {
      throw Error("MrfProblem::Energy: labels[" + std::to_string(i) + "]: expected in [0, " +
                  std::to_string(num_labels_) + "), found " + std::to_string(labels[i]));
    }
  }
  if (!IsFeasible(labels)) return kInf;
  return EnergyLocal(ToLocal(labels));
}

bool MrfProblem::IsFeasible(const std::vector<int>& labels, std::string* why) const {
  if (static_cast<int>(labels.size()) != num_nodes()) {
    if (why) {
      *why = "expected " + std::to_string(num_nodes()) + " labels, found " +
             std::to_string(labels.size());
    }
    return false;
  }
  for (int i = 0; i < num_nodes(); ++i) {
    if (CandidateIndex(i, labels[i]) < 0) {
      if (why) {
        *why = "label " + std::to_string(labels[i]) + " of node " + std::to_string(i) +
               " is not one of its candidates";
      }
      return false;
    }
  }
  return true;
}

std::vector<int> MrfProblem::ToLocal(const std::vector<int>& labels) const {
  std::vector<int> local(num_nodes());
  for (int i = 0; i < num_nodes(); ++i) local[i] = CandidateIndex(i, labels[i]);
  return local;
}

std::vector<int> MrfProblem::ToGlobal(const std::vector<int>& local) const {
  std::vector<int> labels(num_nodes());
  for (int i = 0; i < num_nodes(); ++i) labels[i] = candidate_labels(i)[local[i]];
  return labels;
}

std::vector<int> MrfProblem::UnaryArgmin() const {
  std::vector<int> labels(num_nodes());
  for (int i = 0; i < num_nodes(); ++i) {
    const double* d = candidate_unaries(i);
    labels[i] = candidate_labels(i)[std::min_element(d, d + num_candidates(i)) - d];
  }
  return labels;
}

std::size_t MrfProblem::MemoryBytes() const {
  return node_offsets_.size() * sizeof(int) + labels_.size() * sizeof(int) +
         unaries_.size() * sizeof(double) + edge_nodes_.size() * sizeof(int) +
         edge_weights_.size() * sizeof(double) + table_offsets_.size() * sizeof(std::int64_t) +
         tables_.size() * sizeof(float);
}

MrfAdjacency BuildMrfAdjacency(const MrfProblem& problem) {
  MrfAdjacency adjacency;
  const int n = problem.num_nodes();
  adjacency.offsets.assign(n + 1, 0);
  for (int e = 0; e < problem.num_edges(); ++e) {
    ++adjacency.offsets[problem.edge_first(e) + 1];
    ++adjacency.offsets[problem.edge_second(e) + 1];
  }
  for (int i = 0; i < n; ++i) adjacency.offsets[i + 1] += adjacency.offsets[i];
  adjacency.edges.resize(adjacency.offsets[n]);
  std::vector<int> fill(adjacency.offsets.begin(), adjacency.offsets.end() - 1);
  for (int e = 0; e < problem.num_edges(); ++e) {
    adjacency.edges[fill[problem.edge_first(e)]++] = e;
    adjacency.edges[fill[problem.edge_second(e)]++] = e;
  }
  return adjacency;
}

MrfLabelIndex BuildMrfLabelIndex(const MrfProblem& problem) {
  MrfLabelIndex index;
  const int num_labels = problem.num_labels();
  index.offsets.assign(num_labels + 1, 0);
  for (int i = 0; i < problem.num_nodes(); ++i) {
    for (int k = 0; k < problem.num_candidates(i); ++k) {
      ++index.offsets[problem.candidate_labels(i)[k] + 1];
    }
  }
  for (int l = 0; l < num_labels; ++l) index.offsets[l + 1] += index.offsets[l];
  index.nodes.resize(index.offsets[num_labels]);
  index.local.resize(index.offsets[num_labels]);
  std::vector<int> fill(index.offsets.begin(), index.offsets.end() - 1);
  for (int i = 0; i < problem.num_nodes(); ++i) {
    for (int k = 0; k < problem.num_candidates(i); ++k) {
      const int p = fill[problem.candidate_labels(i)[k]]++;
      index.nodes[p] = i;
      index.local[p] = k;
    }
  }
  return index;
}

namespace {

struct TypeName {
  MrfSolverType type;
  const char* name;
};
constexpr TypeName kTypeNames[] = {{MrfSolverType::kAlphaExpansion, "alpha_expansion"},
                                   {MrfSolverType::kAlphaBetaSwap, "swap"},
                                   {MrfSolverType::kIcm, "icm"},
                                   {MrfSolverType::kTrws, "trws"}};

}  // namespace

const char* MrfSolverTypeToString(MrfSolverType type) {
  for (const TypeName& entry : kTypeNames) {
    if (entry.type == type) return entry.name;
  }
  return "unknown";
}

MrfSolverType ParseMrfSolverType(const std::string& name) {
  std::string valid;
  for (const TypeName& entry : kTypeNames) {
    if (name == entry.name) return entry.type;
    valid += std::string(valid.empty() ? "" : ", ") + entry.name;
  }
  throw Error("MRF solver type: expected one of " + valid + ", found \"" + name + "\"");
}

std::vector<MrfSolverType> AllMrfSolverTypes() {
  std::vector<MrfSolverType> types;
  for (const TypeName& entry : kTypeNames) types.push_back(entry.type);
  return types;
}

bool MrfSolverOptions::IsValid(std::string* error) const {
  auto fail = [error](const std::string& message) {
    if (error) *error = "MrfSolverOptions." + message;
    return false;
  };
  if (std::string(MrfSolverTypeToString(type)) == "unknown") {
    return fail("type: expected a valid MrfSolverType, found " +
                std::to_string(static_cast<int>(type)));
  }
  if (max_iterations < 1) {
    return fail("max_iterations: expected >= 1, found " + std::to_string(max_iterations));
  }
  if (!(energy_tolerance >= 0.0) || !std::isfinite(energy_tolerance)) {
    return fail("energy_tolerance: expected finite and >= 0, found " +
                std::to_string(energy_tolerance));
  }
  if (expansion_parallel_min_nodes < 0) {
    return fail("expansion_parallel_min_nodes: expected >= 0, found " +
                std::to_string(expansion_parallel_min_nodes));
  }
  if (trws_max_iterations < 1) {
    return fail("trws_max_iterations: expected >= 1, found " + std::to_string(trws_max_iterations));
  }
  if (!(trws_bound_tolerance >= 0.0) || !std::isfinite(trws_bound_tolerance)) {
    return fail("trws_bound_tolerance: expected finite and >= 0, found " +
                std::to_string(trws_bound_tolerance));
  }
  if (!(trws_gap_tolerance >= 0.0) || !std::isfinite(trws_gap_tolerance)) {
    return fail("trws_gap_tolerance: expected finite and >= 0, found " +
                std::to_string(trws_gap_tolerance));
  }
  if (!(max_seconds > 0.0)) {
    return fail("max_seconds: expected > 0, found " + std::to_string(max_seconds));
  }
  return true;
}

std::string MrfSummary::BriefReport() const {
  std::ostringstream out;
  out << MrfSolverTypeToString(type) << ": energy " << initial_energy << " -> " << energy;
  if (lower_bound > -kInf) out << ", lower bound " << lower_bound << " (gap " << Gap() << ")";
  out << ", " << iterations << " iterations, " << seconds * 1e3 << " ms, " << termination;
  if (warm_started) out << ", warm start";
  return out.str();
}

std::unique_ptr<MrfSolver> MrfSolver::Create(const MrfSolverOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw Error(error);
  switch (options.type) {
    case MrfSolverType::kAlphaExpansion:
      return std::make_unique<AlphaExpansionSolver>(options);
    case MrfSolverType::kAlphaBetaSwap:
      return std::make_unique<AlphaBetaSwapSolver>(options);
    case MrfSolverType::kIcm:
      return std::make_unique<IcmSolver>(options);
    case MrfSolverType::kTrws:
      return std::make_unique<TrwsSolver>(options);
  }
  throw Error("MrfSolverOptions.type: unknown value");
}

namespace mrf_internal {

SolveRun::SolveRun(const MrfProblem& problem, const MrfSolverOptions& options,
                   const std::vector<int>& input_labels, MrfSummary* summary)
    : problem_(problem), options_(options), summary_(summary), start_ns_(NowNs()) {
  *summary_ = MrfSummary();
  summary_->type = options.type;
  summary_->warm_started = options.warm_start && problem.IsFeasible(input_labels);
  local_ = problem.ToLocal(summary_->warm_started ? input_labels : problem.UnaryArgmin());
  summary_->initial_energy = problem.EnergyLocal(local_);
  summary_->energy = summary_->initial_energy;
}

double SolveRun::Seconds() const { return 1e-9 * static_cast<double>(NowNs() - start_ns_); }

bool SolveRun::EndIteration(double energy, double lower_bound) {
  ++summary_->iterations;
  summary_->trace.push_back(energy);
  if (lower_bound > -kInf) summary_->bound_trace.push_back(lower_bound);
  MrfIterationInfo info;
  info.iteration = summary_->iterations;
  info.energy = energy;
  info.lower_bound = lower_bound;
  info.seconds = Seconds();
  if (options_.callback && !options_.callback(info)) {
    summary_->termination = "callback";
    return false;
  }
  if (info.seconds >= options_.max_seconds) {
    summary_->termination = "time_limit";
    return false;
  }
  return true;
}

void SolveRun::Finish(std::vector<int>* labels) {
  summary_->energy = problem_.EnergyLocal(local_);
  *labels = problem_.ToGlobal(local_);
  summary_->seconds = Seconds();
}

}  // namespace mrf_internal

}  // namespace artex
