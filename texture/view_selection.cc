#include "texture/view_selection.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numeric>
#include <sstream>
#include <utility>

#include "models/error.h"

namespace artex {
namespace {
// Tables ahead whose colours the pairwise-table loop prefetches.
constexpr int kPrefetchTables = 4;
// The data cost D of an image that cannot texture a triangle.
constexpr double kNotCandidate = std::numeric_limits<double>::infinity();

// condition ? a : b through a bit mask, without a jump.
inline double Select(bool condition, double a, double b) {
  std::uint64_t bits_a, bits_b;
  std::memcpy(&bits_a, &a, sizeof a);
  std::memcpy(&bits_b, &b, sizeof b);
  const std::uint64_t mask = -static_cast<std::uint64_t>(condition);
  const std::uint64_t bits = (bits_a & mask) | (bits_b & ~mask);
  double out;
  std::memcpy(&out, &bits, sizeof out);
  return out;
}
}  // namespace

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
  // The lifetime part of D per slot (the same for every triangle of an image).
  std::vector<double> slot_age_cost(slots);
  for (int s = 0; s < slots; ++s)
    slot_age_cost[s] = ViewAgeCost(input.current_frame - slot_frame[s], options.terms);
  constexpr int kChunk = 256;
  tbb::parallel_for(
      tbb::blocked_range<int>(0, f_count, kChunk), [&](const tbb::blocked_range<int>& range) {
        // A local copy: the compiler then knows that writing costs does not change the terms.
        const TextureTermOptions terms = options.terms;
        // D of the chunk's triangles slot by slot (each slot's arrays read in storage order).
        const int begin = range.begin(), size = range.end() - range.begin();
        // In a buffer this thread keeps (grown as needed): no allocation per chunk, which with
        // one malloc arena for all threads (pipeline.heap_arenas) would wait for the others'.
        // Nothing else runs on this thread while it is in use: the body does not wait for
        // other tasks.
        thread_local std::vector<double> chunk_buffer;
        const std::size_t chunk_values = static_cast<std::size_t>(slots) * size;
        if (chunk_buffer.size() < chunk_values) chunk_buffer.resize(chunk_values);
        double* const chunk_d = chunk_buffer.data();
        for (int s = 0; s < slots; ++s) {
          const uint8_t* visible = slot_visible[s] + begin;
          const float* quality = slot_quality[s] + begin;
          const double age_cost = slot_age_cost[s];
          double* out = &chunk_d[static_cast<std::size_t>(s) * size];
          // ViewDataCostFromAge without jumps (the compiler branches on its conditions, and
          // visibility patterns are irregular: they mispredict): both outcomes are computed and
          // one is selected by a bit mask, the same value.
          const double beta = terms.beta, min_quality = terms.min_quality;
          for (int k = 0; k < size; ++k) {
            const double q = quality[k];
            const double d = beta * (1.0 - q) + age_cost;
            const bool candidate = (visible[k] != 0) & !(q < min_quality);
            out[k] = Select(candidate, d, kNotCandidate);
          }
        }
        std::vector<int> best(keep + 1);       // the best slots by (D, slot), ascending
        std::vector<double> best_d(keep + 1);  // and their D
        int memo_frame = -1, memo_slot = -1;   // the last warm-start lookup
        for (int f = range.begin(); f < range.end(); ++f) {
          // D of this triangle in slot s: column[s * size].
          const double* column = &chunk_d[f - begin];
          if (!input.previous_frames.empty()) {
            const int frame = input.previous_frames[f];
            if (frame < 0) {
              warm[f] = untextured;
            } else {
              if (frame != memo_frame) {
                memo_frame = frame;
                memo_slot = pool.SlotOfFrame(frame);  // -1 when no longer pooled
              }
              warm[f] = memo_slot;
            }
          }
          // The best `keep` by (D, slot). Newest slots first: with the lifetime term they tend to
          // be the best, so older ones rarely enter and the loop mostly skips. A slot s enters
          // before an equal D of a later (newer) slot, as (D, s) orders it first.
          int kept = 0;
          for (int s = slots - 1; s >= 0; --s) {
            const double d = column[static_cast<std::size_t>(s) * size];
            if (!(d < inf)) continue;  // not a candidate (+inf)
            if (kept == keep && !(d <= best_d[kept - 1])) continue;
            int k = kept < keep ? kept++ : kept - 1;
            while (k > 0 && best_d[k - 1] >= d) {
              best[k] = best[k - 1];
              best_d[k] = best_d[k - 1];
              --k;
            }
            best[k] = s;
            best_d[k] = d;
          }
          int* labels = &cand_labels[static_cast<std::size_t>(f) * stride];
          double* costs = &cand_costs[static_cast<std::size_t>(f) * stride];
          int n = 0;
          for (int k = 0; k < kept; ++k) labels[n++] = best[k];
          const int w = warm[f];
          if (w >= 0 && w < slots && column[static_cast<std::size_t>(w) * size] < inf &&
              std::find(labels, labels + n, w) == labels + n)
            labels[n++] = w;
          std::sort(labels, labels + n);
          labels[n++] = untextured;
          // Hysteresis: other labels than a pooled previous image pay switch_cost.
          const bool keeps = w >= 0 && w != untextured && options.terms.switch_cost > 0.0;
          for (int k = 0; k < n; ++k) {
            const int l = labels[k];
            costs[k] = l == untextured ? options.untextured_cost
                                       : column[static_cast<std::size_t>(l) * size];
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
  const int num_free = static_cast<int>(triangle_of.size());
  const double lambda = options.terms.lambda;

  // The pairwise terms. Edges between two free triangles are edges of the MRF: they go in
  // ordered by their lower node, lower node first (the solvers walk nodes in ascending order,
  // and reading the tables in storage order is what keeps them fast: they do not fit in cache).
  // Edges with one fixed side: lambda w c(l, untextured) joins the free side's unaries. Edges
  // between two fixed triangles cost a constant 0 (both untextured).
  std::vector<int> mrf_edges, fixed_edges;  // ascending
  mrf_edges.reserve(e_count);
  bool by_lower_node = true;  // mrf_edges already ordered by their lower node
  for (int e = 0, last = -1; e < e_count; ++e) {
    const int i = node_of[mesh.edge_faces(e, 0)], j = node_of[mesh.edge_faces(e, 1)];
    if (i >= 0 && j >= 0) {
      mrf_edges.push_back(e);
      by_lower_node &= std::min(i, j) >= last;
      last = std::min(i, j);
    } else if (i >= 0 || j >= 0) {
      fixed_edges.push_back(e);
    }
  }
  // The mesh's edges follow its triangle order (TextureMesh::Build), and so do the nodes: the
  // MRF edges are then in order already; otherwise a counting sort (stable) orders them.
  if (!by_lower_node) {
    std::vector<int> start(num_free + 1, 0);
    const auto lower = [&](int e) {
      return std::min(node_of[mesh.edge_faces(e, 0)], node_of[mesh.edge_faces(e, 1)]);
    };
    for (int e : mrf_edges) ++start[lower(e) + 1];
    for (int i = 0; i < num_free; ++i) start[i + 1] += start[i];
    std::vector<int> sorted(mrf_edges.size());
    for (int e : mrf_edges) sorted[start[lower(e)]++] = e;
    mrf_edges.swap(sorted);
  }
  const int num_edges = static_cast<int>(mrf_edges.size());
  const int num_fixed = static_cast<int>(fixed_edges.size());
  // Per table (MRF edges first, then the edges with a fixed side): its mesh edge, the triangles
  // of its rows and columns (the free one first for fixed sides) and where it starts.
  std::vector<int> table_edge(num_edges + num_fixed), row_face(num_edges + num_fixed),
      column_face(num_edges + num_fixed);
  for (int k = 0; k < num_edges + num_fixed; ++k) {
    const int e = k < num_edges ? mrf_edges[k] : fixed_edges[k - num_edges];
    const int fi = mesh.edge_faces(e, 0), fj = mesh.edge_faces(e, 1);
    // Rows: the lower node of an MRF edge, the free side of the others.
    const int i = node_of[fi], j = node_of[fj];
    const bool first_rows = k < num_edges ? i < j : i >= 0;
    table_edge[k] = e;
    row_face[k] = first_rows ? fi : fj;
    column_face[k] = first_rows ? fj : fi;
  }
  std::vector<std::int64_t> table_offset(num_edges + num_fixed + 1, 0);
  for (int k = 0; k < num_edges + num_fixed; ++k)
    table_offset[k + 1] =
        table_offset[k] + static_cast<std::int64_t>(count[row_face[k]]) * count[column_face[k]];
  // The MRF's tables, then those of the fixed sides (one row each).
  std::vector<float> tables(table_offset[num_edges]);
  std::vector<float> fixed_tables(table_offset[num_edges + num_fixed] - table_offset[num_edges]);

  // The tables over the candidates of both sides (in parallel).
  const int samples =
      slots > 0 ? static_cast<int>(pool.entry(0).edge_colors.rows() / std::max(1, e_count)) : 0;
  std::vector<const std::uint16_t*> slot_colors(slots);
  for (int s = 0; s < slots; ++s) slot_colors[s] = pool.entry(s).edge_colors.data();
  const std::size_t edge_values = static_cast<std::size_t>(samples) * 3;
  const auto compute_tables = [&](const tbb::blocked_range<int>& range) {
    std::vector<int> pos_in_j(stride), pos_in_i(stride);
    for (int t = range.begin(); t < range.end(); ++t) {
      // The colours of an edge in each pooled image are far apart in memory (one array per
      // image): those of a later table's candidates are requested ahead of their use.
      if (samples > 0 && t + kPrefetchTables < range.end()) {
        const int ahead = t + kPrefetchTables;
        const std::size_t first = static_cast<std::size_t>(table_edge[ahead]) * edge_values;
        for (const int g : {row_face[ahead], column_face[ahead]}) {
          const int* labels = &cand_labels[static_cast<std::size_t>(g) * stride];
          for (int k = 0; k + 1 < count[g]; ++k) {  // the last label is "untextured"
            const char* at = reinterpret_cast<const char*>(slot_colors[labels[k]] + first);
            __builtin_prefetch(at);
            __builtin_prefetch(at + edge_values * sizeof(std::uint16_t) - 1);
          }
        }
      }
      const int e = table_edge[t];
      const int u = mesh.edges(e, 0), v = mesh.edges(e, 1);
      double distance = inf;
      if (!input.seam_distance.empty())
        distance = 0.5 * (input.seam_distance[u] + input.seam_distance[v]);
      const double psi = TemporalSeamCost(distance, options.terms);
      const int fi = row_face[t], fj = column_face[t];
      const int* li = &cand_labels[static_cast<std::size_t>(fi) * stride];
      const int* lj = &cand_labels[static_cast<std::size_t>(fj) * stride];
      float* table = t < num_edges ? &tables[table_offset[t]]
                                   : &fixed_tables[table_offset[t] - table_offset[num_edges]];
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
              const std::uint16_t* ca =
                  slot_colors[a] + static_cast<std::size_t>(e) * edge_values;
              const std::uint16_t* cb =
                  slot_colors[b] + static_cast<std::size_t>(e) * edge_values;
              double sum = 0.0;
              int n = 0;
              for (int k = 0; k < 3 * samples; k += 3) {
                // A colour not seen in a or b (its three channels unseen together).
                if (ca[k] == kEdgeColorUnseen || cb[k] == kEdgeColorUnseen) continue;
                const float d0 = float(ca[k]) - float(cb[k]),
                            d1 = float(ca[k + 1]) - float(cb[k + 1]),
                            d2 = float(ca[k + 2]) - float(cb[k + 2]);
                sum += std::sqrt(d0 * d0 + d1 * d1 + d2 * d2);
                ++n;
              }
              if (n > 0) pi = sum / (n * static_cast<double>(kEdgeColorScale));
            }
            cost = static_cast<float>(SeamPairCost(pi, psi, options.terms));
          }
          table[p * nj + q] = cost;
        }
      }
    }
  };
  constexpr int kTableGrain = 1024;

  // The fixed sides' tables first (few); their terms join the unaries (in the single precision
  // the MRF stores pairwise costs in), edge by edge in ascending order.
  tbb::parallel_for(tbb::blocked_range<int>(num_edges, num_edges + num_fixed, kTableGrain),
                    compute_tables);
  for (int k = 0; k < num_fixed; ++k) {
    const int e = fixed_edges[k];
    const int free = row_face[num_edges + k];
    const double weight = input.edge_weight.empty() ? 1.0 : input.edge_weight[e];
    const float* table = &fixed_tables[table_offset[num_edges + k] - table_offset[num_edges]];
    double* costs = &cand_costs[static_cast<std::size_t>(free) * stride];
    for (int p = 0; p < count[free]; ++p) costs[p] += lambda * weight * table[p];
  }

  // The MRF's tables, and meanwhile its nodes (their unaries are complete now).
  MrfProblem problem(slots + 1);
  std::vector<int> first(num_edges), second(num_edges);
  std::vector<double> weights(num_edges);
  tbb::parallel_invoke(
      [&] {
        tbb::parallel_for(tbb::blocked_range<int>(0, num_edges, kTableGrain), compute_tables);
      },
      [&] {
        for (int f = 0; f < f_count; ++f) result.num_candidates += count[f];
        problem.Reserve(num_free + 1, result.num_candidates, 0, 0);
        // Candidate labels are ascending with finite costs, so the problem's local candidate
        // order is the order of cand_labels and the tables go in as they are.
        for (int f : triangle_of) {
          const std::size_t base = static_cast<std::size_t>(f) * stride;
          problem.AddNode(&cand_labels[base], &cand_costs[base], count[f]);
        }
        // One extra isolated node carries the fixed triangles' constant, so that every energy
        // the solver sees (its relative stopping tests, the callback) is that of the whole
        // labelling.
        if (num_free < f_count) problem.AddNode({untextured}, {constant});
        for (int k = 0; k < num_edges; ++k) {
          first[k] = node_of[row_face[k]];
          second[k] = node_of[column_face[k]];
          weights[k] = input.edge_weight.empty() ? 1.0 : input.edge_weight[table_edge[k]];
        }
      });
  problem.AddEdgeTables(first, second, weights, std::move(tables));
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
