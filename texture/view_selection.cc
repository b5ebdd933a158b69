#include "texture/view_selection.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <limits>
#include <numeric>
#include <sstream>
#include <utility>

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
  const int e_count = static_cast<int>(mesh.edges.rows());
  const int slots = pool.size();
  const int untextured = slots;  // the extra label
  const int width = slots + 1;   // candidates per triangle at most
  const double inf = std::numeric_limits<double>::infinity();

  // Candidates per triangle (ascending labels) and their data costs, in parallel: the best
  // max_candidates images by D (ties: older slot first), the warm-start label (the previous
  // frame's image when still pooled, "untextured" when it was untextured), "untextured".
  const int keep = options.max_candidates > 0 ? std::min(options.max_candidates, slots) : slots;
  const int stride = std::min(width, keep + 2);  // candidates per triangle at most
  ViewSelectionResult result;
  std::vector<int> warm(f_count, -1);
  std::vector<int> count(f_count, 0);
  std::vector<int> cand_labels(static_cast<std::size_t>(f_count) * stride);
  std::vector<double> cand_costs(static_cast<std::size_t>(f_count) * stride);
  std::vector<const uint8_t*> slot_visible(slots);
  std::vector<const float*> slot_quality(slots);
  std::vector<int> slot_frame(slots);
  for (int s = 0; s < slots; ++s) {
    slot_visible[s] = pool.entry(s).visibility.visible.data();
    slot_quality[s] = pool.entry(s).visibility.quality.data();
    slot_frame[s] = pool.entry(s).frame_index;
  }
  // (frame, slot) ascending, for the warm-start slot of each triangle's previous frame.
  std::vector<std::pair<int, int>> frame_slots(slots);
  for (int s = 0; s < slots; ++s) frame_slots[s] = {slot_frame[s], s};
  std::sort(frame_slots.begin(), frame_slots.end());
  constexpr int kChunk = 256;
  tbb::parallel_for(
      tbb::blocked_range<int>(0, f_count, kChunk), [&](const tbb::blocked_range<int>& range) {
        // D of the chunk's triangles slot by slot (each slot's arrays read in storage order).
        const int begin = range.begin(), size = range.end() - range.begin();
        std::vector<double> chunk_d(static_cast<std::size_t>(slots) * size);
        for (int s = 0; s < slots; ++s) {
          const double age = input.current_frame - slot_frame[s];
          double* out = &chunk_d[static_cast<std::size_t>(s) * size];
          for (int k = 0; k < size; ++k) {
            const int f = begin + k;
            out[k] = slot_visible[s][f] ? ViewDataCost(true, slot_quality[s][f], age, options.terms)
                                        : inf;
          }
        }
        std::vector<double> d(slots);
        std::vector<int> best(keep + 1);  // the best slots by (D, slot), ascending
        for (int f = range.begin(); f < range.end(); ++f) {
          for (int s = 0; s < slots; ++s)
            d[s] = chunk_d[static_cast<std::size_t>(s) * size + (f - begin)];
          if (!input.previous_frames.empty()) {
            const int frame = input.previous_frames[f];
            if (frame < 0) {
              warm[f] = untextured;
            } else {
              // The last slot holding that frame, if any.
              const auto it = std::upper_bound(frame_slots.begin(), frame_slots.end(),
                                               std::make_pair(frame, slots));
              if (it != frame_slots.begin() && std::prev(it)->first == frame)
                warm[f] = std::prev(it)->second;
            }
          }
          // The best `keep` by (D, slot). Newest slots first: with the lifetime term they tend to
          // be the best, so older ones rarely enter and the loop mostly skips. A slot s enters
          // before an equal D of a later (newer) slot, as (D, s) orders it first.
          int kept = 0;
          for (int s = slots - 1; s >= 0; --s) {
            if (!std::isfinite(d[s])) continue;
            if (kept == keep && !(d[s] <= d[best[kept - 1]])) continue;
            int k = kept < keep ? kept++ : kept - 1;
            while (k > 0 && d[best[k - 1]] >= d[s]) {
              best[k] = best[k - 1];
              --k;
            }
            best[k] = s;
          }
          int* labels = &cand_labels[static_cast<std::size_t>(f) * stride];
          double* costs = &cand_costs[static_cast<std::size_t>(f) * stride];
          int n = 0;
          for (int k = 0; k < kept; ++k) labels[n++] = best[k];
          const int w = warm[f];
          if (w >= 0 && w < slots && std::isfinite(d[w]) &&
              std::find(labels, labels + n, w) == labels + n)
            labels[n++] = w;
          std::sort(labels, labels + n);
          labels[n++] = untextured;
          // Hysteresis: other labels than a pooled previous image pay switch_cost.
          const bool keeps = w >= 0 && w != untextured && options.terms.switch_cost > 0.0;
          for (int k = 0; k < n; ++k) {
            const int l = labels[k];
            costs[k] = l == untextured ? options.untextured_cost : d[l];
            if (keeps && l != w) costs[k] += options.terms.switch_cost;
          }
          count[f] = n;
        }
      });

  // Triangles whose only candidate is "untextured" (seen by no pooled image) are fixed: they are
  // left out of the MRF, their data cost is a constant and their pairwise terms become unaries
  // of their neighbours (the same energy; moves of every solver see the same costs).
  std::vector<int> node_of(f_count, -1);
  std::vector<int> triangle_of;
  double constant = 0.0;
  // Nodes in the mesh's breadth-first triangle order when it has one (memory locality).
  const bool ordered = static_cast<int>(mesh.triangle_order.size()) == f_count;
  for (int k = 0; k < f_count; ++k) {
    const int f = ordered ? mesh.triangle_order[k] : k;
    if (count[f] > 1) {
      node_of[f] = static_cast<int>(triangle_of.size());
      triangle_of.push_back(f);
    } else {
      constant += cand_costs[static_cast<std::size_t>(f) * stride];
    }
  }
  const double lambda = options.terms.lambda;

  // Pairwise tables over the candidates of both sides, computed in parallel.
  const int samples =
      slots > 0 ? static_cast<int>(pool.entry(0).edge_colors.rows() / std::max(1, e_count)) : 0;
  std::vector<std::int64_t> table_offset(e_count + 1, 0);
  for (int e = 0; e < e_count; ++e)
    table_offset[e + 1] =
        table_offset[e] +
        static_cast<std::int64_t>(count[mesh.edge_faces(e, 0)]) * count[mesh.edge_faces(e, 1)];
  std::vector<float> tables(table_offset[e_count]);
  tbb::parallel_for(
      tbb::blocked_range<int>(0, e_count, 1024), [&](const tbb::blocked_range<int>& range) {
        std::vector<int> pos_in_j(stride), pos_in_i(stride);
        for (int e = range.begin(); e < range.end(); ++e) {
          const int u = mesh.edges(e, 0), v = mesh.edges(e, 1);
          double distance = inf;
          if (!input.seam_distance.empty())
            distance = 0.5 * (input.seam_distance[u] + input.seam_distance[v]);
          const double psi = TemporalSeamCost(distance, options.terms);
          const int fi = mesh.edge_faces(e, 0), fj = mesh.edge_faces(e, 1);
          const int* li = &cand_labels[static_cast<std::size_t>(fi) * stride];
          const int* lj = &cand_labels[static_cast<std::size_t>(fj) * stride];
          float* table = &tables[table_offset[e]];
          const int ni = count[fi], nj = count[fj];
          // Where each side's labels sit among the other side's (-1: absent), for reusing the
          // symmetric V(b, a) = V(a, b).
          for (int p = 0; p < ni; ++p) {
            const int q = static_cast<int>(std::lower_bound(lj, lj + nj, li[p]) - lj);
            pos_in_j[p] = q < nj && lj[q] == li[p] ? q : -1;
          }
          for (int q = 0; q < nj; ++q) {
            const int p = static_cast<int>(std::lower_bound(li, li + ni, lj[q]) - li);
            pos_in_i[q] = p < ni && li[p] == lj[q] ? p : -1;
          }
          for (int p = 0; p < ni; ++p) {
            for (int q = 0; q < nj; ++q) {
              const int a = li[p], b = lj[q];
              float cost = 0.0f;
              const int p2 = pos_in_i[q], q2 = pos_in_j[p];
              if (a != b && p2 >= 0 && q2 >= 0 && p2 * nj + q2 < p * nj + q) {
                cost = table[p2 * nj + q2];
              } else if (a != b) {
                double pi = options.unseen_colour_cost;
                if (a != untextured && b != untextured && samples > 0) {
                  const float* ca =
                      pool.entry(a).edge_colors.data() + static_cast<std::size_t>(e) * samples * 3;
                  const float* cb =
                      pool.entry(b).edge_colors.data() + static_cast<std::size_t>(e) * samples * 3;
                  double sum = 0.0;
                  int n = 0;
                  for (int k = 0; k < 3 * samples; k += 3) {
                    const float d0 = ca[k] - cb[k], d1 = ca[k + 1] - cb[k + 1],
                                d2 = ca[k + 2] - cb[k + 2];
                    const float squared = d0 * d0 + d1 * d1 + d2 * d2;
                    if (std::isnan(squared)) continue;  // a colour not seen in a or b
                    sum += std::sqrt(squared);
                    ++n;
                  }
                  if (n > 0) pi = sum / n;
                }
                cost = static_cast<float>(SeamPairCost(pi, psi, options.terms));
              }
              table[p * nj + q] = cost;
            }
          }
        }
      });

  // Edges with one fixed side: lambda w c(l, untextured) joins the free side's unaries (in the
  // single precision the MRF stores pairwise costs in).
  for (int e = 0; e < e_count; ++e) {
    const int fi = mesh.edge_faces(e, 0), fj = mesh.edge_faces(e, 1);
    if ((node_of[fi] >= 0) == (node_of[fj] >= 0)) continue;
    const bool first_free = node_of[fi] >= 0;
    const int free = first_free ? fi : fj;
    const double weight = input.edge_weight.empty() ? 1.0 : input.edge_weight[e];
    const float* table = &tables[table_offset[e]];
    double* costs = &cand_costs[static_cast<std::size_t>(free) * stride];
    // The fixed side has one candidate, so the table is a row or a column of count[free].
    for (int p = 0; p < count[free]; ++p) costs[p] += lambda * weight * table[p];
  }

  const int num_free = static_cast<int>(triangle_of.size());
  MrfProblem problem(slots + 1);
  for (int f = 0; f < f_count; ++f) result.num_candidates += count[f];
  problem.Reserve(num_free + 1, result.num_candidates, e_count, table_offset[e_count]);
  // Candidate labels are ascending with finite costs, so the problem's local candidate order is
  // the order of cand_labels and the tables go in as they are.
  for (int f : triangle_of) {
    const std::size_t base = static_cast<std::size_t>(f) * stride;
    problem.AddNode(&cand_labels[base], &cand_costs[base], count[f]);
  }
  // One extra isolated node carries the fixed triangles' constant, so that every energy the
  // solver sees (its relative stopping tests, the callback) is that of the whole labelling.
  if (num_free < f_count) problem.AddNode({untextured}, {constant});
  // Edges go in ordered by their lower node (first): the solvers walk nodes
  // in ascending order, and reading the tables in storage order is what keeps them fast (the
  // tables do not fit in cache). V is symmetric, so a swapped edge takes the transposed table.
  std::vector<int> edge_start(num_free + 1, 0);
  for (int e = 0; e < e_count; ++e) {
    const int i = node_of[mesh.edge_faces(e, 0)], j = node_of[mesh.edge_faces(e, 1)];
    if (i >= 0 && j >= 0) ++edge_start[std::min(i, j) + 1];
  }
  for (int i = 0; i < num_free; ++i) edge_start[i + 1] += edge_start[i];
  std::vector<int> sorted_edges(edge_start[num_free]);
  {
    std::vector<int> fill(edge_start.begin(), edge_start.end() - 1);
    for (int e = 0; e < e_count; ++e) {
      const int i = node_of[mesh.edge_faces(e, 0)], j = node_of[mesh.edge_faces(e, 1)];
      if (i >= 0 && j >= 0) sorted_edges[fill[std::min(i, j)]++] = e;
    }
  }
  std::vector<float> transposed(static_cast<std::size_t>(stride) * stride);
  for (int e : sorted_edges) {
    const int fi = mesh.edge_faces(e, 0), fj = mesh.edge_faces(e, 1);
    const double weight = input.edge_weight.empty() ? 1.0 : input.edge_weight[e];
    const float* table = &tables[table_offset[e]];
    if (node_of[fi] < node_of[fj]) {
      problem.AddEdgeTable(node_of[fi], node_of[fj], weight, table);
    } else {
      const int ni = count[fi], nj = count[fj];
      for (int p = 0; p < ni; ++p)
        for (int q = 0; q < nj; ++q) transposed[q * ni + p] = table[p * nj + q];
      problem.AddEdgeTable(node_of[fj], node_of[fi], weight, transposed.data());
    }
  }
  problem.set_smoothness(lambda);

  // Warm start: previous labels where still candidates, else the best unary.
  std::vector<int> x = problem.UnaryArgmin();  // the constant node: its only label
  for (int i = 0; i < num_free; ++i) {
    const int f = triangle_of[i];
    if (warm[f] >= 0 && problem.CandidateIndex(i, warm[f]) >= 0) x[i] = warm[f];
  }
  result.mrf = solver->Solve(problem, &x);
  result.frames.assign(f_count, -1);
  for (int i = 0; i < num_free; ++i)
    result.frames[triangle_of[i]] = x[i] == untextured ? -1 : pool.entry(x[i]).frame_index;
  return result;
}

}  // namespace artex
