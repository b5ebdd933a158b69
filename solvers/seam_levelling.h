// Global seam levelling (Lempitsky & Ivanov 2007, as in the paper sec. 4): per-vertex, per-label
// additive colour corrections g_{v,l} minimising
//   sum over seam vertices v, label pairs (a, b):  |(f_{v,a} + g_{v,a}) - (f_{v,b} + g_{v,b})|^2
// + smoothness * sum over mesh edges (u, v) inside label l:  |g_{u,l} - g_{v,l}|^2
// + regularisation * sum |g_{v,l}|^2,
// a sparse linear least-squares problem (one factorisation, one solve per channel). The result
// is interpolated over triangles from their corners.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace artex {

struct SeamLevellingOptions {
  double smoothness = 0.1;       // weight of the smoothness equations; > 0
  double regularisation = 1e-3;  // weight pulling corrections to zero; > 0
  bool IsValid(std::string* error) const;
};

struct SeamLevellingSummary {
  int unknowns = 0;  // (vertex, label) pairs
  int seam_equations = 0;
  double seam_residual_before = 0.0;  // RMS colour jump at seam vertices
  double seam_residual_after = 0.0;
  double seconds = 0.0;
};

namespace seam_levelling_internal {

// Solutions of the levelling's normal equations: n x 3, one row per unknown.
using Rows3 = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;

// The LDL^T factorisation of a sparse symmetric matrix in its given order, with the arithmetic
// of Eigen 3.4's SimplicialLDLT (Upper, natural order: the same elimination tree, row patterns
// in the same topological order, the same operations in the same order), so the same factor
// and solutions bit for bit; it keeps its buffers from one factorisation to the next and holds
// indices as int (half the index traffic of the Eigen::Index indices SimplicialLDLT needs to
// factorise in place without copying).
class LdltFactor {
 public:
  // Factorises the n x n matrix whose upper triangle (diagonal included, every diagonal entry
  // present) is given in compressed columns (outer: n + 1 offsets; rows ascending within a
  // column). False when a pivot is zero (the factor is then unusable).
  bool Factorize(int n, const int* outer, const int* inner, const double* value);
  // Solves L D L^T x = b in place for the three columns of x (= b on entry, n rows): one pass
  // over the factor per substitution for all three columns, with SimplicialLDLT::solve's
  // arithmetic per column.
  void Solve3(Rows3* x) const;

  // The factor, in SimplicialLDLT's layout: the strict lower triangle of unit L in compressed
  // columns (rows ascending) and D.
  const std::vector<int>& l_outer() const { return l_outer_; }
  const std::vector<int>& l_inner() const { return l_inner_; }
  const std::vector<double>& l_value() const { return l_value_; }
  const std::vector<double>& d() const { return d_; }

 private:
  int n_ = 0;
  std::vector<int> parent_;  // elimination tree (-1: root)
  std::vector<int> count_;   // nonzeros per column of L
  std::vector<int> tags_, pattern_;
  std::vector<double> y_;
  std::vector<int> l_outer_, l_inner_;
  std::vector<double> l_value_, d_;
};

}  // namespace seam_levelling_internal

// Levels seams of many labellings of one mesh (e.g. one per frame). The fill-reducing order
// of the sparse factorisation is computed once from the mesh (approximate minimum degree on the
// vertex graph); the unknowns of a vertex are numbered consecutively in that order, so every
// call writes the upper triangle of the normal equations column by column and only factorises.
// Calls reuse the leveller's buffers: one leveller levels one labelling at a time.
// Throws artex::Error for invalid options or triangle indices outside [0, num_vertices).
class SeamLeveller {
 public:
  SeamLeveller(int num_vertices, const Eigen::MatrixX3i& triangles,
               const SeamLevellingOptions& options);
  ~SeamLeveller();

  // labels: F (label per triangle, < 0 = untextured, ignored); colour(v, l, &c): the colour of
  // vertex v in label l's image, false when unknown (only asked at vertices with two or more
  // labels). corrections: (3F) x 3, row 3 f + c = g at corner c of triangle f (0 for untextured
  // triangles). summary may be null.
  void Level(const std::vector<int>& labels,
             const std::function<bool(int, int, Eigen::Vector3f*)>& colour,
             Eigen::MatrixX3f* corrections, SeamLevellingSummary* summary);

 private:
  int num_vertices_;
  int num_triangles_;
  SeamLevellingOptions options_;
  std::vector<int> order_;  // vertices in elimination order
  // Per position in order_ (CSR, V + 1 offsets): the vertex's corners 3 f + c, and per corner
  // how many smoothness pairs of its triangle add to the vertex's diagonal (2 unless the
  // triangle repeats a vertex).
  std::vector<int> corner_offsets_;
  std::vector<int> corners_;
  std::vector<uint8_t> corner_pairs_;
  // Per position in order_ (CSR, V + 1 offsets): the mesh edges to vertices earlier in the
  // order, by their position; per edge (CSR, edges + 1 offsets) the earlier vertex's corner in
  // each triangle with that edge (twice if the triangle has it twice by repeating a vertex).
  std::vector<int> edge_offsets_;
  std::vector<int> edge_corner_offsets_;
  std::vector<int> edge_corners_;
  // Kept from call to call (their buffers): the normal equations' upper triangle (compressed
  // columns) and its factorisation.
  std::vector<int> normal_outer_, normal_inner_;
  std::vector<double> normal_value_;
  seam_levelling_internal::LdltFactor factor_;
};

// One-off levelling (builds a SeamLeveller): triangles F x 3; labels, colour, corrections and
// summary as in SeamLeveller::Level.
void LevelSeams(int num_vertices, const Eigen::MatrixX3i& triangles, const std::vector<int>& labels,
                const std::function<bool(int, int, Eigen::Vector3f*)>& colour,
                const SeamLevellingOptions& options, Eigen::MatrixX3f* corrections,
                SeamLevellingSummary* summary);

}  // namespace artex
