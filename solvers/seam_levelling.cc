#include "solvers/seam_levelling.h"

#include <Eigen/OrderingMethods>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <sstream>

#include "models/error.h"

namespace artex {
namespace seam_levelling_internal {

void SolveLdlt3(const SparseMatrix& l, const Eigen::VectorXd& d, Rows3* x) {
  const Eigen::Index n = l.cols();
  const Eigen::Index* outer = l.outerIndexPtr();
  const Eigen::Index* inner = l.innerIndexPtr();
  const double* value = l.valuePtr();
  const auto end = [&](Eigen::Index i) {
    return l.isCompressed() ? outer[i + 1] : outer[i] + l.innerNonZeroPtr()[i];
  };
  double* b = x->data();
  // Forward, L y = b: Eigen's column-oriented substitution, which skips a column whose
  // value is zero (that keeps the signs of zeros, which subtracting 0 * l could flip).
  for (Eigen::Index i = 0; i < n; ++i) {
    const double t0 = b[3 * i], t1 = b[3 * i + 1], t2 = b[3 * i + 2];
    const Eigen::Index p_end = end(i);
    if (t0 != 0.0 && t1 != 0.0 && t2 != 0.0) {
      for (Eigen::Index p = outer[i]; p < p_end; ++p) {
        double* r = b + 3 * inner[p];
        const double v = value[p];
        r[0] -= t0 * v;
        r[1] -= t1 * v;
        r[2] -= t2 * v;
      }
    } else if (t0 != 0.0 || t1 != 0.0 || t2 != 0.0) {
      for (Eigen::Index p = outer[i]; p < p_end; ++p) {
        double* r = b + 3 * inner[p];
        const double v = value[p];
        if (t0 != 0.0) r[0] -= t0 * v;
        if (t1 != 0.0) r[1] -= t1 * v;
        if (t2 != 0.0) r[2] -= t2 * v;
      }
    }
  }
  // D z = y as Eigen computes it: the inverse diagonal times y.
  for (Eigen::Index i = 0; i < n; ++i) {
    const double inverse = 1.0 / d[i];
    for (int c = 0; c < 3; ++c) b[3 * i + c] = inverse * b[3 * i + c];
  }
  // Backward, L^T x = z: row-oriented over the transpose (column i of L), in storage order.
  for (Eigen::Index i = n - 1; i >= 0; --i) {
    double t0 = b[3 * i], t1 = b[3 * i + 1], t2 = b[3 * i + 2];
    const Eigen::Index p_end = end(i);
    for (Eigen::Index p = outer[i]; p < p_end; ++p) {
      const double* r = b + 3 * inner[p];
      const double v = value[p];
      t0 -= v * r[0];
      t1 -= v * r[1];
      t2 -= v * r[2];
    }
    b[3 * i] = t0;
    b[3 * i + 1] = t1;
    b[3 * i + 2] = t2;
  }
}

}  // namespace seam_levelling_internal

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
    : num_vertices_(num_vertices),
      num_triangles_(static_cast<int>(triangles.rows())),
      options_(options) {
  std::string why;
  if (!options_.IsValid(&why)) throw Error(why);
  const int f_count = num_triangles_;
  if (num_vertices < 0 ||
      (f_count > 0 && (triangles.minCoeff() < 0 || triangles.maxCoeff() >= num_vertices))) {
    std::ostringstream msg;
    msg << "seam levelling: triangle indices must lie in [0, " << num_vertices << ")";
    throw Error(msg.str());
  }
  order_.resize(num_vertices);
  corner_offsets_.assign(num_vertices + 1, 0);
  edge_offsets_.assign(num_vertices + 1, 0);
  edge_corner_offsets_.assign(1, 0);
  if (num_vertices == 0) return;
  // Fill-reducing vertex order: AMD on the vertex graph (the unknowns' graph is this graph
  // with its vertices split along seams).
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
  std::vector<int> position(num_vertices);
  for (int i = 0; i < num_vertices; ++i) {
    order_[i] = inverse_order.indices()[i];
    position[order_[i]] = i;
  }
  // Corners per position, with the number of the triangle's smoothness pairs (a, b) with b != a
  // at each (a pair of equal vertices, in a triangle that repeats a vertex, is no equation).
  for (int k = 0; k < 3 * f_count; ++k) ++corner_offsets_[position[triangles(k / 3, k % 3)] + 1];
  for (int i = 0; i < num_vertices; ++i) corner_offsets_[i + 1] += corner_offsets_[i];
  corners_.resize(3 * static_cast<std::size_t>(f_count));
  corner_pairs_.resize(corners_.size());
  std::vector<int> fill(corner_offsets_.begin(), corner_offsets_.end() - 1);
  for (int k = 0; k < 3 * f_count; ++k) {
    const int f = k / 3, c = k % 3;
    const int a = triangles(f, c), next = triangles(f, (c + 1) % 3),
              previous = triangles(f, (c + 2) % 3);
    const int slot = fill[position[a]]++;
    corners_[slot] = k;
    corner_pairs_[slot] = static_cast<uint8_t>((a != next) + (a != previous));
  }
  // Edges to earlier vertices: (later position, earlier position, earlier vertex's corner).
  std::vector<std::array<int, 3>> sides;
  sides.reserve(3 * static_cast<std::size_t>(f_count));
  for (int f = 0; f < f_count; ++f) {
    for (int c = 0; c < 3; ++c) {
      const int d = (c + 1) % 3;
      const int pc = position[triangles(f, c)], pd = position[triangles(f, d)];
      if (pc < pd) sides.push_back({pd, pc, 3 * f + c});
      if (pd < pc) sides.push_back({pc, pd, 3 * f + d});
    }
  }
  std::sort(sides.begin(), sides.end());
  edge_corners_.reserve(sides.size());
  for (std::size_t s = 0; s < sides.size(); ++s) {
    if (s == 0 || sides[s][0] != sides[s - 1][0] || sides[s][1] != sides[s - 1][1]) {
      if (s > 0) edge_corner_offsets_.push_back(static_cast<int>(s));
      ++edge_offsets_[sides[s][0] + 1];
    }
    edge_corners_.push_back(sides[s][2]);
  }
  if (!sides.empty()) edge_corner_offsets_.push_back(static_cast<int>(sides.size()));
  for (int i = 0; i < num_vertices; ++i) edge_offsets_[i + 1] += edge_offsets_[i];
}

SeamLeveller::~SeamLeveller() = default;

void SeamLeveller::Level(const std::vector<int>& labels,
                         const std::function<bool(int, int, Eigen::Vector3f*)>& colour,
                         Eigen::MatrixX3f* corrections, SeamLevellingSummary* summary) const {
  const auto start = std::chrono::steady_clock::now();
  const int f_count = num_triangles_;
  if (static_cast<int>(labels.size()) != f_count) {
    std::ostringstream msg;
    msg << "seam levelling: expected " << f_count << " labels, found " << labels.size();
    throw Error(msg.str());
  }
  // Unknowns (vertex, label) numbered vertex by vertex in the elimination order, labels
  // ascending within a vertex: vertex_first[i] .. vertex_first[i + 1] for the i-th vertex.
  // unknown_pairs: smoothness pairs on the unknown's diagonal.
  std::vector<int> corner_unknown(3 * static_cast<std::size_t>(f_count), -1);
  std::vector<int> unknown_label, unknown_pairs;
  unknown_label.reserve(num_vertices_);
  unknown_pairs.reserve(num_vertices_);
  std::vector<int> vertex_first(num_vertices_ + 1, 0);
  std::vector<int> local, corner_label;  // the vertex's distinct labels; its corners' labels
  const int* corners = corners_.data();
  for (int i = 0; i < num_vertices_; ++i) {
    const int begin = corner_offsets_[i], count = corner_offsets_[i + 1] - begin;
    if (static_cast<int>(corner_label.size()) < count) corner_label.resize(count);
    local.clear();
    for (int j = 0; j < count; ++j) {
      const int l = labels[corners[begin + j] / 3];
      corner_label[j] = l;
      if (l < 0 || (!local.empty() && local.back() == l)) continue;
      bool seen = false;
      for (int m : local) seen |= m == l;
      if (!seen) local.push_back(l);
    }
    if (local.size() > 1) std::sort(local.begin(), local.end());
    const int first = static_cast<int>(unknown_label.size());
    for (int l : local) {
      unknown_label.push_back(l);
      unknown_pairs.push_back(0);
    }
    for (int j = 0; j < count; ++j) {
      const int l = corner_label[j];
      if (l < 0) continue;
      int u = first;
      while (unknown_label[u] != l) ++u;
      corner_unknown[corners[begin + j]] = u;
      unknown_pairs[u] += corner_pairs_[begin + j];
    }
    vertex_first[i + 1] = static_cast<int>(unknown_label.size());
  }
  const int n = static_cast<int>(unknown_label.size());
  // Colours are only needed where a vertex has two or more labels.
  std::vector<Eigen::Vector3f> f_value(n);
  std::vector<uint8_t> known(n, 0);
  for (int i = 0; i < num_vertices_; ++i) {
    if (vertex_first[i + 1] - vertex_first[i] < 2) continue;
    for (int u = vertex_first[i]; u < vertex_first[i + 1]; ++u)
      known[u] = colour(order_[i], unknown_label[u], &f_value[u]);
  }

  // Normal equations: diagonal, right-hand side.
  Eigen::VectorXd diagonal(n);
  for (int u = 0; u < n; ++u)
    diagonal[u] = options_.regularisation + options_.smoothness * unknown_pairs[u];
  // The right-hand sides, solved in place into the corrections g.
  seam_levelling_internal::Rows3 g = seam_levelling_internal::Rows3::Zero(n, 3);
  double before = 0.0;
  int seams = 0;
  // Seam equations: (g_a - g_b) = (f_b - f_a).
  for (int i = 0; i < num_vertices_; ++i) {
    for (int a = vertex_first[i]; a < vertex_first[i + 1]; ++a) {
      for (int b = a + 1; b < vertex_first[i + 1]; ++b) {
        if (!known[a] || !known[b]) continue;
        const Eigen::Vector3d d = (f_value[b] - f_value[a]).cast<double>();
        diagonal[a] += 1.0;
        diagonal[b] += 1.0;
        g.row(a) += d.transpose();
        g.row(b) -= d.transpose();
        before += d.squaredNorm();
        ++seams;
      }
    }
  }
  // Upper triangle in compressed columns, rows ascending: column u = (v, l) holds the
  // smoothness pairs to (v', l) for earlier vertices v' (one per triangle with the edge v v'
  // and label l), the seam pairs to v's earlier labels, then the diagonal. SimplicialLDLT reads
  // this layout directly when it is told the order is natural (below).
  using Matrix = seam_levelling_internal::SparseMatrix;
  Matrix normal(n, n);
  normal.resizeNonZeros(n + seams + static_cast<Eigen::Index>(edge_corners_.size()));
  Eigen::Index* outer = normal.outerIndexPtr();
  Eigen::Index* inner = normal.innerIndexPtr();
  double* value = normal.valuePtr();
  int nz = 0;
  for (int i = 0; i < num_vertices_; ++i) {
    for (int u = vertex_first[i]; u < vertex_first[i + 1]; ++u) {
      const int l = unknown_label[u];
      outer[u] = nz;
      for (int e = edge_offsets_[i]; e < edge_offsets_[i + 1]; ++e) {
        int count = 0, row = -1;
        for (int p = edge_corner_offsets_[e]; p < edge_corner_offsets_[e + 1]; ++p) {
          const int corner = edge_corners_[p];
          if (labels[corner / 3] != l) continue;
          ++count;
          row = corner_unknown[corner];
        }
        if (count == 0) continue;
        inner[nz] = row;
        value[nz++] = -options_.smoothness * count;
      }
      for (int a = vertex_first[i]; a < u; ++a) {
        if (!known[a] || !known[u]) continue;
        inner[nz] = a;
        value[nz++] = -1.0;
      }
      inner[nz] = u;
      value[nz++] = diagonal[u];
    }
  }
  outer[n] = nz;
  normal.resizeNonZeros(nz);
  if (n > 0) {
    // The unknowns are already in a fill-reducing order. Eigen 3.4 recognises no ordering only
    // as NaturalOrdering<Eigen::Index> (hence Eigen::Index indices): it then factorises `normal`
    // where it lies; with NaturalOrdering<int> it would copy it twice (to a full symmetric
    // matrix, then to an upper triangle permuted by the empty permutation).
    Eigen::SimplicialLDLT<Matrix, Eigen::Upper, Eigen::NaturalOrdering<Eigen::Index>> solver(
        normal);
    if (solver.info() != Eigen::Success) throw Error("seam levelling: factorisation failed");
    // The three channels in one pass over the factor (solver.solve(g) would make one per
    // channel; the same corrections bit for bit).
    seam_levelling_internal::SolveLdlt3(solver.matrixL().nestedExpression(), solver.vectorD(), &g);
  }
  corrections->resize(3 * f_count, 3);
  for (int k = 0; k < 3 * f_count; ++k) {
    const int u = corner_unknown[k];
    if (u >= 0)
      corrections->row(k) = g.row(u).cast<float>();
    else
      corrections->row(k).setZero();
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
