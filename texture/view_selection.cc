#include "texture/view_selection.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <sstream>

#include "models/error.h"

namespace artex {

bool ViewSelectionOptions::IsValid(std::string* error) const {
  if (!terms.IsValid(error)) return false;
  std::ostringstream msg;
  if (!(untextured_cost > 1.0) || !std::isfinite(untextured_cost))
    msg << "texture.untextured_cost: expected a finite value > 1, found " << untextured_cost;
  else if (max_candidates < 0)
    msg << "texture.max_candidates: expected >= 0, found " << max_candidates;
  else if (!(unseen_colour_cost >= 0.0))
    msg << "texture.unseen_colour_cost: expected >= 0, found " << unseen_colour_cost;
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

ViewSelectionResult SelectViews(const ViewSelectionInput& input,
                                const ViewSelectionOptions& options, MrfSolver* solver) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(why);
  const TextureMesh& mesh = *input.mesh;
  const ImagePool& pool = *input.pool;
  const int f_count = static_cast<int>(mesh.triangles.rows());
  const int slots = pool.size();
  const int untextured = slots;  // the extra label
  const double inf = std::numeric_limits<double>::infinity();

  // Warm start in slots.
  std::vector<int> warm(f_count, -1);
  for (int f = 0; f < f_count && !input.previous_frames.empty(); ++f) {
    const int frame = input.previous_frames[f];
    warm[f] = frame < 0 ? untextured : pool.SlotOfFrame(frame);
  }

  MrfProblem problem(slots + 1);
  ViewSelectionResult result;
  std::vector<int> labels;
  std::vector<double> costs;
  std::vector<int> order(slots);
  for (int f = 0; f < f_count; ++f) {
    std::vector<double> d(slots);
    for (int s = 0; s < slots; ++s) {
      const PoolEntry& e = pool.entry(s);
      d[s] = ViewDataCost(e.visibility.visible[f] != 0, e.visibility.quality[f],
                          input.current_frame - e.frame_index, options.terms);
    }
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return d[a] < d[b]; });
    labels.clear();
    costs.clear();
    const int keep = options.max_candidates > 0 ? options.max_candidates : slots;
    for (int k = 0; k < slots; ++k) {
      const int s = order[k];
      if (!std::isfinite(d[s])) break;
      if (k < keep || s == warm[f]) {
        labels.push_back(s);
        costs.push_back(d[s]);
      }
    }
    labels.push_back(untextured);
    costs.push_back(options.untextured_cost);
    // AddNode expects ascending labels.
    std::vector<int> idx(labels.size());
    std::iota(idx.begin(), idx.end(), 0);
    std::sort(idx.begin(), idx.end(), [&](int a, int b) { return labels[a] < labels[b]; });
    std::vector<int> sorted_labels;
    std::vector<double> sorted_costs;
    for (int i : idx) {
      sorted_labels.push_back(labels[i]);
      sorted_costs.push_back(costs[i]);
    }
    result.num_candidates += static_cast<int>(sorted_labels.size());
    problem.AddNode(sorted_labels, sorted_costs);
  }
  (void)inf;

  const int e_count = static_cast<int>(mesh.edges.rows());
  const int samples =
      slots > 0 ? static_cast<int>(pool.entry(0).edge_colors.rows() / std::max(1, e_count)) : 0;
  for (int e = 0; e < e_count; ++e) {
    const int u = mesh.edges(e, 0), v = mesh.edges(e, 1);
    double distance = inf;
    if (!input.seam_distance.empty())
      distance = 0.5 * (input.seam_distance[u] + input.seam_distance[v]);
    const double psi = TemporalSeamCost(distance, options.terms);
    const double weight = input.edge_weight.empty() ? 1.0 : input.edge_weight[e];
    problem.AddEdge(mesh.edge_faces(e, 0), mesh.edge_faces(e, 1), weight, [&](int a, int b) {
      if (a == b) return 0.0;
      double pi = options.unseen_colour_cost;
      if (a != untextured && b != untextured && samples > 0) {
        const Eigen::MatrixX3f& ca = pool.entry(a).edge_colors;
        const Eigen::MatrixX3f& cb = pool.entry(b).edge_colors;
        double sum = 0.0;
        int n = 0;
        for (int k = 0; k < samples; ++k) {
          const Eigen::Index row = static_cast<Eigen::Index>(e) * samples + k;
          if (!ca.row(row).allFinite() || !cb.row(row).allFinite()) continue;
          sum += (ca.row(row) - cb.row(row)).norm();
          ++n;
        }
        if (n > 0) pi = sum / n;
      }
      return SeamPairCost(pi, psi, options.terms);
    });
  }
  problem.set_smoothness(options.terms.lambda);

  // Warm start: previous labels where still candidates, else the best unary.
  std::vector<int> x = problem.UnaryArgmin();
  for (int f = 0; f < f_count; ++f) {
    if (warm[f] >= 0 && problem.CandidateIndex(f, warm[f]) >= 0) x[f] = warm[f];
  }
  result.mrf = solver->Solve(problem, &x);
  result.frames.resize(f_count);
  for (int f = 0; f < f_count; ++f)
    result.frames[f] = x[f] == untextured ? -1 : pool.entry(x[f]).frame_index;
  return result;
}

}  // namespace artex
