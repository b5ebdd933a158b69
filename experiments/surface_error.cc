#include "experiments/surface_error.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace artex {

NearestPointGrid::NearestPointGrid(const Eigen::MatrixX3d& points) : points_(points) {
  const int n = static_cast<int>(points.rows());
  if (n == 0) return;
  const Eigen::Vector3d lo = points.colwise().minCoeff().transpose();
  const Eigen::Vector3d hi = points.colwise().maxCoeff().transpose();
  const Eigen::Vector3d extent = (hi - lo).cwiseMax(1e-9);
  // About one cell per point over the bounding box (surfaces leave most cells empty, so an
  // occupied cell holds a few points), at most 128 cells per axis.
  cell_ = std::cbrt(extent.prod() / n);
  cell_ = std::max(cell_, extent.maxCoeff() / 128.0);
  origin_ = lo;
  for (int a = 0; a < 3; ++a)
    dims_[a] = std::max(1, std::min(128, static_cast<int>(std::floor(extent[a] / cell_)) + 1));
  const std::size_t cells = static_cast<std::size_t>(dims_[0]) * dims_[1] * dims_[2];
  std::vector<int> cell_of(n);
  cell_begin_.assign(cells + 1, 0);
  for (int i = 0; i < n; ++i) {
    const int c = Cell(points(i, 0), 0) +
                  dims_[0] * (Cell(points(i, 1), 1) + dims_[1] * Cell(points(i, 2), 2));
    cell_of[i] = c;
    ++cell_begin_[c + 1];
  }
  for (std::size_t c = 0; c < cells; ++c) cell_begin_[c + 1] += cell_begin_[c];
  std::vector<int> fill(cell_begin_.begin(), cell_begin_.end() - 1);
  order_.resize(n);
  sorted_.resize(3 * static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    const int k = fill[cell_of[i]]++;
    order_[k] = i;
    for (int a = 0; a < 3; ++a) sorted_[3 * static_cast<std::size_t>(k) + a] = points(i, a);
  }
}

int NearestPointGrid::Cell(double x, int axis) const {
  const double c = std::floor((x - origin_[axis]) / cell_);
  if (!(c > 0.0)) return 0;  // also NaN
  return c >= dims_[axis] - 1 ? dims_[axis] - 1 : static_cast<int>(c);
}

void NearestPointGrid::Visit(int cell, const Eigen::Vector3d& p, double* best,
                             int* best_index) const {
  for (int k = cell_begin_[cell]; k < cell_begin_[cell + 1]; ++k) {
    const double* q = &sorted_[3 * static_cast<std::size_t>(k)];
    const double dx = p[0] - q[0], dy = p[1] - q[1], dz = p[2] - q[2];
    const double d2 = dx * dx + dy * dy + dz * dz;
    if (d2 < *best || (d2 == *best && order_[k] < *best_index)) {
      *best = d2;
      *best_index = order_[k];
    }
  }
}

int NearestPointGrid::Nearest(const Eigen::Vector3d& p, double* squared_distance) const {
  if (order_.empty()) return -1;
  int center[3];
  for (int a = 0; a < 3; ++a) center[a] = Cell(p[a], a);
  double best = std::numeric_limits<double>::infinity();
  int best_index = -1;
  // Shells of cells at Chebyshev distance r = 0, 1, ... from p's cell until a point is found.
  int r = 0;
  for (;; ++r) {
    int lo[3], hi[3];
    bool whole = true;
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::max(0, center[a] - r);
      hi[a] = std::min(dims_[a] - 1, center[a] + r);
      whole = whole && lo[a] == 0 && hi[a] == dims_[a] - 1;
    }
    for (int z = lo[2]; z <= hi[2]; ++z) {
      for (int y = lo[1]; y <= hi[1]; ++y) {
        const bool yz_shell = std::abs(z - center[2]) == r || std::abs(y - center[1]) == r;
        const int row = dims_[0] * (y + dims_[1] * z);
        for (int x = lo[0]; x <= hi[0]; ++x) {
          if (yz_shell || std::abs(x - center[0]) == r) Visit(row + x, p, &best, &best_index);
        }
      }
    }
    if (best_index >= 0 || whole) break;
  }
  // Any nearer point lies within the found distance of p: the cells overlapping that box
  // (widened by a relative 1e-9 against rounding) and not visited above.
  const double radius = std::sqrt(best) * (1.0 + 1e-9) + 1e-12;
  int lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = Cell(p[a] - radius, a);
    hi[a] = Cell(p[a] + radius, a);
  }
  for (int z = lo[2]; z <= hi[2]; ++z) {
    const bool z_near = std::abs(z - center[2]) <= r;
    for (int y = lo[1]; y <= hi[1]; ++y) {
      const bool yz_near = z_near && std::abs(y - center[1]) <= r;
      const int row = dims_[0] * (y + dims_[1] * z);
      for (int x = lo[0]; x <= hi[0]; ++x) {
        if (yz_near && std::abs(x - center[0]) <= r) continue;  // visited
        Visit(row + x, p, &best, &best_index);
      }
    }
  }
  *squared_distance = best;
  return best_index;
}

void SurfaceErrors(const Eigen::MatrixX3d& tracked, const Eigen::MatrixX3d& truth,
                   const Eigen::MatrixX3d& truth_normals, double* mean, double* max) {
  const NearestPointGrid grid(truth);
  double sum = 0.0, worst = 0.0;
  for (Eigen::Index t = 0; t < tracked.rows(); ++t) {
    const Eigen::Vector3d p = tracked.row(t);
    double d2 = 0.0;
    const int index = grid.Nearest(p, &d2);
    if (index < 0) break;
    const Eigen::Vector3d q = truth.row(index);
    const Eigen::Vector3d n = truth_normals.row(index);
    const double plane = n.squaredNorm() > 0.5 ? std::abs(n.dot(p - q)) : std::sqrt(d2);
    const double d = std::min(std::sqrt(d2), plane);
    sum += d;
    worst = std::max(worst, d);
  }
  *mean = tracked.rows() ? sum / tracked.rows() : 0.0;
  *max = worst;
}

}  // namespace artex
