// NearestGrid: the nearest of a point set to a query (within a bound, or anywhere), on a uniform
// grid of cubic cells. Built in one counting sort (under a tenth of a kd-tree's build over a
// template's 12k vertices) and exact: the nearest point and its squared distance computed as
// PointCloudIndex computes it, the lowest index among equidistant points. A query visits the
// cells shell by shell from its own and stops at the first shell that cannot hold a nearer
// point, so it is fast while the answer lies within a few cells. Used where the points move
// every frame: the scale sample's ICP from the fitted pose (docs/fitting-speed.md) and the
// output stage's vertex error against the truth (experiments/surface_error.h).
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace artex {

// A search bound (squared distance) that keeps `known` in reach, for NearestWithin here and in
// PointCloudIndex, which take only points strictly below their bound: the squared distance from
// `query` to `known`, summed as both compute it, a hair more (+inf when not finite). The
// nearest point is then the same as without a bound, found sooner when `known` is close (the
// previous iteration's or frame's answer).
inline double BoundKeeping(const Eigen::Vector3d& query, const Eigen::Vector3d& known) {
  double d2 = 0.0;
  for (int d = 0; d < 3; ++d) {
    const double diff = query[d] - known[d];
    d2 += diff * diff;
  }
  return std::isfinite(d2) ? d2 * (1.0 + 1e-9) + 1e-300 : std::numeric_limits<double>::infinity();
}

class NearestGrid {
 public:
  // Throws artex::Error for a cell that is not finite and > 0, non-finite points, or a grid
  // over the points' bounding box of more than kMaxCells cells.
  NearestGrid(const Eigen::MatrixX3d& points, double cell);

  static constexpr int64_t kMaxCells = int64_t{1} << 24;
  // About one cell per point over the points' bounding box (surfaces leave most cells empty,
  // so an occupied cell holds a few points), at most 128 cells along each axis; 1 when empty.
  static double AutoCell(const Eigen::MatrixX3d& points);

  int size() const { return static_cast<int>(index_.size()); }
  // The index of the nearest point whose squared distance is below `bound2` (-1 when none:
  // distance2 +inf) and that squared distance, computed as PointCloudIndex computes it (the
  // same bits); of equidistant points the lowest index.
  int NearestWithin(const Eigen::Vector3d& query, double bound2, double* distance2) const;
  // Without a bound: -1 only when there are no points or the query is not finite.
  int Nearest(const Eigen::Vector3d& query, double* distance2) const {
    return NearestWithin(query, std::numeric_limits<double>::infinity(), distance2);
  }

 private:
  double cell_ = 0.0, inv_cell_ = 0.0;
  double low_[3] = {0.0, 0.0, 0.0};  // corner of the grid's first cell (m)
  int64_t dims_[3] = {0, 0, 0};
  std::vector<int> begin_;   // per cell (x-major) + 1: its first point in xyz_ / index_
  std::vector<double> xyz_;  // the points ordered by cell, 3 per point
  std::vector<int> index_;   // their indices in the input
};

}  // namespace artex
