#include "solvers/seam_levelling.h"

#include <Eigen/OrderingMethods>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>

#include "models/error.h"

namespace artex {

bool SeamLevellingOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (!(smoothness > 0.0))
    msg << "levelling.smoothness: expected > 0, found " << smoothness;
  else if (!(regularisation > 0.0))
    msg << "levelling.regularisation: expected > 0, found " << regularisation;
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

SeamLeveller::SeamLeveller(int num_vertices, const Eigen::MatrixX3i& triangles,
                           const SeamLevellingOptions& options)
    : num_vertices_(num_vertices), triangles_(triangles), options_(options) {
  std::string why;
  if (!options_.IsValid(&why)) throw Error(why);
  const int f_count = static_cast<int>(triangles.rows());
  if (num_vertices < 0 ||
      (f_count > 0 && (triangles.minCoeff() < 0 || triangles.maxCoeff() >= num_vertices))) {
    std::ostringstream msg;
    msg << "seam levelling: triangle indices must lie in [0, " << num_vertices << ")";
    throw Error(msg.str());
  }
  // Corners per vertex.
  corner_offsets_.assign(num_vertices + 1, 0);
  for (int k = 0; k < 3 * f_count; ++k) ++corner_offsets_[triangles(k / 3, k % 3) + 1];
  for (int v = 0; v < num_vertices; ++v) corner_offsets_[v + 1] += corner_offsets_[v];
  corners_.resize(3 * static_cast<std::size_t>(f_count));
  std::vector<int> fill(corner_offsets_.begin(), corner_offsets_.end() - 1);
  for (int k = 0; k < 3 * f_count; ++k) corners_[fill[triangles(k / 3, k % 3)]++] = k;
  // Fill-reducing vertex order: AMD on the vertex graph (the unknowns' graph is this graph
  // with its vertices split along seams).
  order_.resize(num_vertices);
  if (num_vertices == 0) return;
  std::vector<Eigen::Triplet<double>> entries;
  entries.reserve(6 * static_cast<std::size_t>(f_count) + num_vertices);
  for (int v = 0; v < num_vertices; ++v) entries.emplace_back(v, v, 1.0);
  for (int f = 0; f < f_count; ++f) {
    for (int c = 0; c < 3; ++c) {
      entries.emplace_back(triangles(f, c), triangles(f, (c + 1) % 3), 1.0);
      entries.emplace_back(triangles(f, (c + 1) % 3), triangles(f, c), 1.0);
    }
  }
  Eigen::SparseMatrix<double> graph(num_vertices, num_vertices);
  graph.setFromTriplets(entries.begin(), entries.end());
  Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> inverse_order;
  Eigen::AMDOrdering<int>()(graph.selfadjointView<Eigen::Lower>(), inverse_order);
  // inverse_order maps new positions to vertices (Eigen's Pinv convention).
  for (int i = 0; i < num_vertices; ++i) order_[i] = inverse_order.indices()[i];
}

SeamLeveller::~SeamLeveller() = default;

void SeamLeveller::Level(const std::vector<int>& labels,
                         const std::function<bool(int, int, Eigen::Vector3f*)>& colour,
                         Eigen::MatrixX3f* corrections, SeamLevellingSummary* summary) const {
  const auto start = std::chrono::steady_clock::now();
  const int f_count = static_cast<int>(triangles_.rows());
  if (static_cast<int>(labels.size()) != f_count) {
    std::ostringstream msg;
    msg << "seam levelling: expected " << f_count << " labels, found " << labels.size();
    throw Error(msg.str());
  }
  // Unknowns (vertex, label) numbered vertex by vertex in the elimination order, labels
  // ascending within a vertex: vertex_first[i] .. vertex_first[i + 1] for the i-th vertex.
  std::vector<int> corner_unknown(3 * static_cast<std::size_t>(f_count), -1);
  std::vector<int> unknown_vertex, unknown_label;
  std::vector<int> vertex_first(num_vertices_ + 1, 0);
  std::vector<int> local;
  for (int i = 0; i < num_vertices_; ++i) {
    const int v = order_[i];
    local.clear();
    for (int k = corner_offsets_[v]; k < corner_offsets_[v + 1]; ++k) {
      const int l = labels[corners_[k] / 3];
      if (l >= 0) local.push_back(l);
    }
    std::sort(local.begin(), local.end());
    local.erase(std::unique(local.begin(), local.end()), local.end());
    const int base = static_cast<int>(unknown_vertex.size());
    for (int l : local) {
      unknown_vertex.push_back(v);
      unknown_label.push_back(l);
    }
    for (int k = corner_offsets_[v]; k < corner_offsets_[v + 1]; ++k) {
      const int l = labels[corners_[k] / 3];
      if (l < 0) continue;
      corner_unknown[corners_[k]] =
          base + static_cast<int>(std::lower_bound(local.begin(), local.end(), l) - local.begin());
    }
    vertex_first[i + 1] = static_cast<int>(unknown_vertex.size());
  }
  const int n = static_cast<int>(unknown_vertex.size());
  std::vector<Eigen::Vector3f> f_value(n);
  std::vector<uint8_t> known(n, 0);
  for (int u = 0; u < n; ++u) known[u] = colour(unknown_vertex[u], unknown_label[u], &f_value[u]);

  // Normal equations, lower triangle only (row >= column).
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(static_cast<std::size_t>(n) + 9 * static_cast<std::size_t>(f_count));
  const auto add_pair = [&triplets](int a, int b, double w) {
    triplets.emplace_back(a, a, w);
    triplets.emplace_back(b, b, w);
    triplets.emplace_back(std::max(a, b), std::min(a, b), -w);
  };
  Eigen::MatrixX3d rhs = Eigen::MatrixX3d::Zero(n, 3);
  double before = 0.0;
  int seams = 0;
  // Seam equations: (g_a - g_b) = (f_b - f_a).
  for (int i = 0; i < num_vertices_; ++i) {
    for (int a = vertex_first[i]; a < vertex_first[i + 1]; ++a) {
      for (int b = a + 1; b < vertex_first[i + 1]; ++b) {
        if (!known[a] || !known[b]) continue;
        const Eigen::Vector3d d = (f_value[b] - f_value[a]).cast<double>();
        add_pair(a, b, 1.0);
        rhs.row(a) += d.transpose();
        rhs.row(b) -= d.transpose();
        before += d.squaredNorm();
        ++seams;
      }
    }
  }
  // Smoothness along triangle edges inside one label.
  for (int f = 0; f < f_count; ++f) {
    if (labels[f] < 0) continue;
    for (int c = 0; c < 3; ++c)
      add_pair(corner_unknown[3 * f + c], corner_unknown[3 * f + (c + 1) % 3], options_.smoothness);
  }
  for (int u = 0; u < n; ++u) triplets.emplace_back(u, u, options_.regularisation);
  Eigen::SparseMatrix<double> normal(n, n);
  normal.setFromTriplets(triplets.begin(), triplets.end());
  Eigen::MatrixX3d g = Eigen::MatrixX3d::Zero(n, 3);
  if (n > 0) {
    // The unknowns are already in a fill-reducing order.
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Lower, Eigen::NaturalOrdering<int>>
        solver(normal);
    if (solver.info() != Eigen::Success) throw Error("seam levelling: factorisation failed");
    g = solver.solve(rhs);
  }
  corrections->setZero(3 * f_count, 3);
  for (int k = 0; k < 3 * f_count; ++k) {
    if (corner_unknown[k] >= 0) corrections->row(k) = g.row(corner_unknown[k]).cast<float>();
  }
  if (summary) {
    double after = 0.0;
    for (int i = 0; i < num_vertices_; ++i) {
      for (int a = vertex_first[i]; a < vertex_first[i + 1]; ++a) {
        for (int b = a + 1; b < vertex_first[i + 1]; ++b) {
          if (!known[a] || !known[b]) continue;
          after += ((f_value[a].cast<double>() + g.row(a).transpose()) -
                    (f_value[b].cast<double>() + g.row(b).transpose()))
                       .squaredNorm();
        }
      }
    }
    summary->unknowns = n;
    summary->seam_equations = seams;
    summary->seam_residual_before = seams ? std::sqrt(before / seams) : 0.0;
    summary->seam_residual_after = seams ? std::sqrt(after / seams) : 0.0;
    summary->seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
}

void LevelSeams(int num_vertices, const Eigen::MatrixX3i& triangles, const std::vector<int>& labels,
                const std::function<bool(int, int, Eigen::Vector3f*)>& colour,
                const SeamLevellingOptions& options, Eigen::MatrixX3f* corrections,
                SeamLevellingSummary* summary) {
  SeamLeveller(num_vertices, triangles, options).Level(labels, colour, corrections, summary);
}

}  // namespace artex
