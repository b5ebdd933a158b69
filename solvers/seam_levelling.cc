#include "solvers/seam_levelling.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>
#include <unordered_map>

#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

#include "models/error.h"

namespace artex {

bool SeamLevellingOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (!(smoothness > 0.0)) msg << "levelling.smoothness: expected > 0, found " << smoothness;
  else if (!(regularisation > 0.0))
    msg << "levelling.regularisation: expected > 0, found " << regularisation;
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

void LevelSeams(int num_vertices, const Eigen::MatrixX3i& triangles, const std::vector<int>& labels,
                const std::function<bool(int, int, Eigen::Vector3f*)>& colour,
                const SeamLevellingOptions& options, Eigen::MatrixX3f* corrections,
                SeamLevellingSummary* summary) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(why);
  const auto start = std::chrono::steady_clock::now();
  const int f_count = static_cast<int>(triangles.rows());
  // Unknown index per (vertex, label) used by some triangle corner.
  std::unordered_map<long long, int> unknown_of;
  std::vector<std::pair<int, int>> unknowns;  // (vertex, label)
  const auto key = [](int v, int l) { return static_cast<long long>(v) << 20 | l; };
  std::vector<int> corner_unknown(3 * static_cast<std::size_t>(f_count), -1);
  for (int f = 0; f < f_count; ++f) {
    if (labels[f] < 0) continue;
    for (int c = 0; c < 3; ++c) {
      const int v = triangles(f, c);
      auto [it, inserted] = unknown_of.emplace(key(v, labels[f]), static_cast<int>(unknowns.size()));
      if (inserted) unknowns.emplace_back(v, labels[f]);
      corner_unknown[3 * f + c] = it->second;
    }
  }
  const int n = static_cast<int>(unknowns.size());
  // Labels present at each vertex.
  std::vector<std::vector<int>> vertex_unknowns(num_vertices);
  for (int u = 0; u < n; ++u) vertex_unknowns[unknowns[u].first].push_back(u);

  std::vector<Eigen::Triplet<double>> triplets;
  Eigen::MatrixX3d rhs = Eigen::MatrixX3d::Zero(n, 3);
  double before = 0.0;
  int seams = 0;
  std::vector<Eigen::Vector3f> f_value(n);
  std::vector<uint8_t> known(n, 0);
  for (int u = 0; u < n; ++u) known[u] = colour(unknowns[u].first, unknowns[u].second, &f_value[u]);
  // Seam equations: (g_a - g_b) = (f_b - f_a).
  for (int v = 0; v < num_vertices; ++v) {
    const auto& list = vertex_unknowns[v];
    for (std::size_t i = 0; i < list.size(); ++i) {
      for (std::size_t j = i + 1; j < list.size(); ++j) {
        const int a = list[i], b = list[j];
        if (!known[a] || !known[b]) continue;
        const Eigen::Vector3d d = (f_value[b] - f_value[a]).cast<double>();
        triplets.emplace_back(a, a, 1.0);
        triplets.emplace_back(b, b, 1.0);
        triplets.emplace_back(a, b, -1.0);
        triplets.emplace_back(b, a, -1.0);
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
    for (int c = 0; c < 3; ++c) {
      const int a = corner_unknown[3 * f + c], b = corner_unknown[3 * f + (c + 1) % 3];
      const double w = options.smoothness;
      triplets.emplace_back(a, a, w);
      triplets.emplace_back(b, b, w);
      triplets.emplace_back(a, b, -w);
      triplets.emplace_back(b, a, -w);
    }
  }
  for (int u = 0; u < n; ++u) triplets.emplace_back(u, u, options.regularisation);
  Eigen::SparseMatrix<double> normal(n, n);
  normal.setFromTriplets(triplets.begin(), triplets.end());
  Eigen::MatrixX3d g = Eigen::MatrixX3d::Zero(n, 3);
  if (n > 0) {
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(normal);
    if (solver.info() != Eigen::Success) throw Error("seam levelling: factorisation failed");
    g = solver.solve(rhs);
  }
  corrections->setZero(3 * f_count, 3);
  for (int k = 0; k < 3 * f_count; ++k) {
    if (corner_unknown[k] >= 0) corrections->row(k) = g.row(corner_unknown[k]).cast<float>();
  }
  if (summary) {
    double after = 0.0;
    for (int v = 0; v < num_vertices; ++v) {
      const auto& list = vertex_unknowns[v];
      for (std::size_t i = 0; i < list.size(); ++i)
        for (std::size_t j = i + 1; j < list.size(); ++j) {
          const int a = list[i], b = list[j];
          if (!known[a] || !known[b]) continue;
          after += ((f_value[a].cast<double>() + g.row(a).transpose()) -
                    (f_value[b].cast<double>() + g.row(b).transpose())).squaredNorm();
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

}  // namespace artex
