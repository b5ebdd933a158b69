// Global seam levelling (Lempitsky & Ivanov 2007, as in the paper sec. 4): per-vertex, per-label
// additive colour corrections g_{v,l} minimising
//   sum over seam vertices v, label pairs (a, b):  |(f_{v,a} + g_{v,a}) - (f_{v,b} + g_{v,b})|^2
// + smoothness * sum over mesh edges (u, v) inside label l:  |g_{u,l} - g_{v,l}|^2
// + regularisation * sum |g_{v,l}|^2,
// a sparse linear least-squares problem (one factorisation, one solve per channel). The result
// is interpolated over triangles from their corners.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace artex {

struct SeamLevellingOptions {
  double smoothness = 0.1;       // weight of the smoothness equations; > 0
  double regularisation = 1e-3;  // weight pulling corrections to zero; > 0
  bool IsValid(std::string* error) const;
};

struct SeamLevellingSummary {
  int unknowns = 0;         // (vertex, label) pairs
  int seam_equations = 0;
  double seam_residual_before = 0.0;  // RMS colour jump at seam vertices
  double seam_residual_after = 0.0;
  double seconds = 0.0;
};

// triangles: F x 3; labels: F (label per triangle, < 0 = untextured, ignored);
// colour(v, l, &c): the colour of vertex v in label l's image, false when unknown.
// corrections: (3F) x 3, row 3 f + c = g at corner c of triangle f.
void LevelSeams(int num_vertices, const Eigen::MatrixX3i& triangles, const std::vector<int>& labels,
                const std::function<bool(int, int, Eigen::Vector3f*)>& colour,
                const SeamLevellingOptions& options, Eigen::MatrixX3f* corrections,
                SeamLevellingSummary* summary);

}  // namespace artex
