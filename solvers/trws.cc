#include "solvers/trws.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "models/numeric.h"

namespace artex {
namespace {

// Message storage: for edge e = (s, t), the message into s (K_s values) then into t (K_t).
struct Messages {
  std::vector<std::int64_t> offset;  // per edge
  std::vector<double> values;

  explicit Messages(const MrfProblem& problem) : offset(problem.num_edges()) {
    std::int64_t total = 0;
    for (int e = 0; e < problem.num_edges(); ++e) {
      offset[e] = total;
      total += problem.num_candidates(problem.edge_first(e)) +
               problem.num_candidates(problem.edge_second(e));
    }
    values.assign(total, 0.0);
  }
  // Message along edge e into `node` (one of its ends).
  double* Into(const MrfProblem& problem, int e, int node) {
    double* m = &values[offset[e]];
    return node == problem.edge_first(e) ? m : m + problem.num_candidates(problem.edge_first(e));
  }
};

// out(b) = min_a h(a) + lambda w_e c_e(a, b) over the candidates a of `from` and b of `to`,
// normalised to min 0; returns the subtracted minimum.
double UpdateMessage(const MrfProblem& problem, int e, int from, const double* h, double* out) {
  const int to = problem.edge_other(e, from);
  const int kf = problem.num_candidates(from);
  const int kt = problem.num_candidates(to);
  const double scale = problem.smoothness() * problem.edge_weight(e);
  const float* table = problem.edge_table(e);
  if (table == nullptr) {
    // Potts: out(b) = min(min_a h(a) + scale, h(a with the label of b)).
    const double h_min = *std::min_element(h, h + kf) + scale;
    const int* lf = problem.candidate_labels(from);
    const int* lt = problem.candidate_labels(to);
    int a = 0;
    for (int b = 0; b < kt; ++b) {
      while (a < kf && lf[a] < lt[b]) ++a;
      out[b] = (a < kf && lf[a] == lt[b]) ? std::min(h_min, h[a]) : h_min;
    }
  } else if (from == problem.edge_first(e)) {  // table rows are `from`
    for (int b = 0; b < kt; ++b) out[b] = kInf;
    for (int a = 0; a < kf; ++a) {
      const float* row = table + static_cast<std::int64_t>(a) * kt;
      for (int b = 0; b < kt; ++b) out[b] = std::min(out[b], h[a] + scale * row[b]);
    }
  } else {  // table rows are `to`
    for (int b = 0; b < kt; ++b) {
      const float* row = table + static_cast<std::int64_t>(b) * kf;
      double best = kInf;
      for (int a = 0; a < kf; ++a) best = std::min(best, h[a] + scale * row[a]);
      out[b] = best;
    }
  }
  const double m = *std::min_element(out, out + kt);
  for (int b = 0; b < kt; ++b) out[b] -= m;
  return m;
}

}  // namespace

MrfSummary TrwsSolver::Solve(const MrfProblem& problem, std::vector<int>* labels) {
  MrfSummary summary;
  mrf_internal::SolveRun run(problem, options_, *labels, &summary);
  std::vector<int>& best = run.local();
  const int n = problem.num_nodes();
  const MrfAdjacency adjacency = BuildMrfAdjacency(problem);

  // gamma_i = 1 / max(n_in, n_out): the share of node i's unary in each monotonic chain.
  std::vector<double> gamma(n, 1.0);
  for (int i = 0; i < n; ++i) {
    int in = 0, out = 0;
    for (int p = adjacency.offsets[i]; p < adjacency.offsets[i + 1]; ++p) {
      const int e = adjacency.edges[p];
      const int other = problem.edge_other(e, i);
      (other < i ? in : out) += 1;
    }
    gamma[i] = 1.0 / std::max(1, std::max(in, out));
  }

  Messages messages(problem);
  const int k_max = problem.max_candidates();
  std::vector<double> belief(k_max), h(k_max);
  std::vector<int> x(n);
  double best_energy = summary.initial_energy;
  double bound = -kInf;
  summary.termination = "max_iterations";

  // belief = theta_i + all incoming messages; returns its minimum (and subtracts it).
  auto compute_belief = [&](int i) {
    const int k = problem.num_candidates(i);
    const double* d = problem.candidate_unaries(i);
    std::copy(d, d + k, belief.begin());
    for (int p = adjacency.offsets[i]; p < adjacency.offsets[i + 1]; ++p) {
      const double* m = messages.Into(problem, adjacency.edges[p], i);
      for (int a = 0; a < k; ++a) belief[a] += m[a];
    }
    const double m = *std::min_element(belief.begin(), belief.begin() + k);
    for (int a = 0; a < k; ++a) belief[a] -= m;
    return m;
  };
  // Sends messages from i to its neighbours on one side (later if forward); returns the sum of
  // the normalisation constants.
  auto send = [&](int i, bool forward) {
    const int k = problem.num_candidates(i);
    double constants = 0.0;
    for (int p = adjacency.offsets[i]; p < adjacency.offsets[i + 1]; ++p) {
      const int e = adjacency.edges[p];
      const int other = problem.edge_other(e, i);
      if ((other > i) != forward) continue;
      const double* back = messages.Into(problem, e, i);
      for (int a = 0; a < k; ++a) h[a] = gamma[i] * belief[a] - back[a];
      constants += UpdateMessage(problem, e, i, h.data(), messages.Into(problem, e, other));
    }
    return constants;
  };

  for (int iteration = 0; iteration < options_.trws_max_iterations; ++iteration) {
    for (int i = 0; i < n; ++i) {
      compute_belief(i);
      send(i, true);
    }
    // Backward pass. With belief_i >= 0 normalised and gamma_i * n_in(i) <= 1, every edge (j, i),
    // j < i, satisfies theta_ji >= M_{i->j} + c_ij + M_{j->i} - gamma_i belief_i, so
    // E(x) >= sum_i min(theta_i + incoming) + sum c for every x: a valid lower bound.
    double pass_bound = 0.0;
    for (int i = n - 1; i >= 0; --i) {
      pass_bound += compute_belief(i);
      pass_bound += send(i, false);
    }
    // Primal labelling: forward order, earlier nodes fixed, later ones through their messages.
    double energy = 0.0;
    for (int i = 0; i < n; ++i) {
      const int k = problem.num_candidates(i);
      const double* d = problem.candidate_unaries(i);
      std::copy(d, d + k, belief.begin());
      for (int p = adjacency.offsets[i]; p < adjacency.offsets[i + 1]; ++p) {
        const int e = adjacency.edges[p];
        const int s = problem.edge_first(e);
        const int t = problem.edge_second(e);
        const int other = s == i ? t : s;
        if (other < i) {
          for (int a = 0; a < k; ++a) {
            belief[a] +=
                s == i ? problem.PairwiseLocal(e, a, x[t]) : problem.PairwiseLocal(e, x[s], a);
          }
        } else {
          const double* m = messages.Into(problem, e, i);
          for (int a = 0; a < k; ++a) belief[a] += m[a];
        }
      }
      x[i] =
          static_cast<int>(std::min_element(belief.begin(), belief.begin() + k) - belief.begin());
      energy += d[x[i]];
      for (int p = adjacency.offsets[i]; p < adjacency.offsets[i + 1]; ++p) {
        const int e = adjacency.edges[p];
        const int s = problem.edge_first(e);
        const int t = problem.edge_second(e);
        if ((s == i ? t : s) < i) energy += problem.PairwiseLocal(e, x[s], x[t]);
      }
    }
    if (energy < best_energy) {
      best_energy = energy;
      best = x;
    }
    const double previous_bound = bound;
    bound = std::max(bound, pass_bound);  // the best bound seen is valid
    if (!run.EndIteration(best_energy, bound)) break;
    const double scale = std::max(std::abs(best_energy), std::abs(bound));
    if (best_energy - bound <= options_.trws_gap_tolerance * scale) {
      summary.termination = "optimal";
      break;
    }
    if (iteration > 0 && bound - previous_bound <= options_.trws_bound_tolerance * scale) {
      summary.termination = "converged";
      break;
    }
  }
  summary.lower_bound = bound;
  run.Finish(labels);
  return summary;
}

}  // namespace artex
