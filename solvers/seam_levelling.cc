#include "solvers/seam_levelling.h"

#include <Eigen/OrderingMethods>
#include <Eigen/SparseCore>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <sstream>

#include "models/error.h"

namespace artex {
namespace seam_levelling_internal {

bool LdltFactor::Factorize(int n, const int* outer, const int* inner, const double* value) {
  n_ = n;
  parent_.resize(n);
  count_.resize(n);
  tags_.resize(n);
  pattern_.resize(n);
  y_.resize(n);
  d_.resize(n);
  l_outer_.resize(n + 1);
  // Symbolic: the elimination tree and the column counts of L (SimplicialLDLT's
  // analyzePattern_preordered).
  int* parent = parent_.data();
  int* count = count_.data();
  int* tags = tags_.data();
  for (int k = 0; k < n; ++k) {
    parent[k] = -1;
    tags[k] = k;
    count[k] = 0;
    for (int p = outer[k]; p < outer[k + 1]; ++p) {
      int i = inner[p];
      if (i >= k) continue;
      // The path from i towards the root up to a node already met in this row.
      for (; tags[i] != k; i = parent[i]) {
        if (parent[i] == -1) parent[i] = k;
        ++count[i];
        tags[i] = k;
      }
    }
  }
  int* lp = l_outer_.data();
  lp[0] = 0;
  for (int k = 0; k < n; ++k) lp[k + 1] = lp[k] + count[k];
  l_inner_.resize(lp[n]);
  l_value_.resize(lp[n]);
  // Numeric, row by row (SimplicialLDLT's factorize_preordered): row k of L solves a sparse
  // triangular system whose pattern is the etree reach of column k of the matrix.
  int* li = l_inner_.data();
  double* lx = l_value_.data();
  int* pattern = pattern_.data();
  double* y = y_.data();
  double* d = d_.data();
  for (int k = 0; k < n; ++k) {
    y[k] = 0.0;
    int top = n;
    tags[k] = k;
    count[k] = 0;
    for (int p = outer[k]; p < outer[k + 1]; ++p) {
      int i = inner[p];
      if (i > k) continue;
      y[i] += value[p];
      int len = 0;
      for (; tags[i] != k; i = parent[i]) {
        pattern[len++] = i;
        tags[i] = k;
      }
      while (len > 0) pattern[--top] = pattern[--len];
    }
    double dk = y[k];
    y[k] = 0.0;
    for (; top < n; ++top) {
      const int i = pattern[top];
      const double yi = y[i];
      y[i] = 0.0;
      const double l_ki = yi / d[i];
      const int p_end = lp[i] + count[i];
      // y[r] -= L(r, i) yi over the column so far, four rows at a time: the rows of a column
      // are distinct, so loading the four before storing them is the same computation, and
      // the loads need not wait for the previous stores.
      int p = lp[i];
      for (; p + 4 <= p_end; p += 4) {
        const int r0 = li[p], r1 = li[p + 1], r2 = li[p + 2], r3 = li[p + 3];
        const double y0 = y[r0] - lx[p] * yi, y1 = y[r1] - lx[p + 1] * yi;
        const double y2 = y[r2] - lx[p + 2] * yi, y3 = y[r3] - lx[p + 3] * yi;
        y[r0] = y0;
        y[r1] = y1;
        y[r2] = y2;
        y[r3] = y3;
      }
      for (; p < p_end; ++p) y[li[p]] -= lx[p] * yi;
      dk -= l_ki * yi;
      li[p_end] = k;
      lx[p_end] = l_ki;
      ++count[i];
    }
    d[k] = dk;
    if (dk == 0.0) return false;
  }
  return true;
}

void LdltFactor::Solve3(Rows3* x) const {
  const int* lp = l_outer_.data();
  const int* li = l_inner_.data();
  const double* lx = l_value_.data();
  double* b = x->data();
  // Forward, L y = b: SimplicialLDLT's column-oriented substitution, which skips a column whose
  // value is zero (that keeps the signs of zeros, which subtracting 0 * l could flip).
  for (int i = 0; i < n_; ++i) {
    const double t0 = b[3 * i], t1 = b[3 * i + 1], t2 = b[3 * i + 2];
    if (t0 != 0.0 && t1 != 0.0 && t2 != 0.0) {
      for (int p = lp[i]; p < lp[i + 1]; ++p) {
        double* r = b + 3 * li[p];
        const double v = lx[p];
        r[0] -= t0 * v;
        r[1] -= t1 * v;
        r[2] -= t2 * v;
      }
    } else if (t0 != 0.0 || t1 != 0.0 || t2 != 0.0) {
      for (int p = lp[i]; p < lp[i + 1]; ++p) {
        double* r = b + 3 * li[p];
        const double v = lx[p];
        if (t0 != 0.0) r[0] -= t0 * v;
        if (t1 != 0.0) r[1] -= t1 * v;
        if (t2 != 0.0) r[2] -= t2 * v;
      }
    }
  }
  // D z = y as Eigen computes it: the inverse diagonal times y.
  for (int i = 0; i < n_; ++i) {
    const double inverse = 1.0 / d_[i];
    for (int c = 0; c < 3; ++c) b[3 * i + c] = inverse * b[3 * i + c];
  }
  // Backward, L^T x = z: row-oriented over the transpose (column i of L), in storage order.
  for (int i = n_ - 1; i >= 0; --i) {
    double t0 = b[3 * i], t1 = b[3 * i + 1], t2 = b[3 * i + 2];
    for (int p = lp[i]; p < lp[i + 1]; ++p) {
      const double* r = b + 3 * li[p];
      const double v = lx[p];
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
                         Eigen::MatrixX3f* corrections, SeamLevellingSummary* summary) {
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
  // and label l), the seam pairs to v's earlier labels, then the diagonal.
  normal_outer_.resize(n + 1);
  normal_inner_.resize(n + seams + edge_corners_.size());
  normal_value_.resize(normal_inner_.size());
  int* outer = normal_outer_.data();
  int* inner = normal_inner_.data();
  double* value = normal_value_.data();
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
  // The unknowns are already in a fill-reducing order: factorised as they are, with
  // SimplicialLDLT's arithmetic (LdltFactor).
  if (!factor_.Factorize(n, outer, inner, value))
    throw Error("seam levelling: factorisation failed");
  factor_.Solve3(&g);
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
