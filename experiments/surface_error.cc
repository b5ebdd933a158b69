#include "experiments/surface_error.h"

#include <algorithm>
#include <cmath>

#include "solvers/nearest_grid.h"

namespace artex {

void SurfaceErrors(const Eigen::MatrixX3d& tracked, const Eigen::MatrixX3d& truth,
                   const Eigen::MatrixX3d& truth_normals, double* mean, double* max) {
  const NearestGrid grid(truth, NearestGrid::AutoCell(truth));
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
