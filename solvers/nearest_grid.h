// NearestGrid: the nearest of a point set to a query within a bound, on a uniform grid of cubic
// cells. Built in one counting sort (a tenth of a kd-tree's build over a template's 12k
// vertices), exact like PointCloudIndex::NearestWithin, and fast while the bound spans few
// cells: a query visits the cells within its bound, shell by shell from its own, so its cost
// grows with (bound / cell)^3. For searches that start close, such as the scale sample's ICP
// from the fitted pose (docs/fitting-speed.md); the kd-tree serves far ones.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace artex {

class NearestGrid {
 public:
  // Throws artex::Error for a cell that is not finite and > 0, non-finite points, or a grid
  // over the points' bounding box of more than kMaxCells cells.
  NearestGrid(const Eigen::MatrixX3d& points, double cell);

  static constexpr int64_t kMaxCells = int64_t{1} << 24;

  int size() const { return static_cast<int>(index_.size()); }
  // The index of the nearest point whose squared distance is below `bound2` (-1 when none:
  // distance2 +inf) and that squared distance, computed as PointCloudIndex computes it (so
  // the same point and the same bits; of equal distances either may be returned).
  int NearestWithin(const Eigen::Vector3d& query, double bound2, double* distance2) const;

 private:
  double cell_ = 0.0, inv_cell_ = 0.0;
  double low_[3] = {0.0, 0.0, 0.0};  // corner of the grid's first cell (m)
  int64_t dims_[3] = {0, 0, 0};
  std::vector<int> begin_;   // per cell (x-major) + 1: its first point in xyz_ / index_
  std::vector<double> xyz_;  // the points ordered by cell, 3 per point
  std::vector<int> index_;   // their indices in the input
};

}  // namespace artex
