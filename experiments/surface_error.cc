#include "experiments/surface_error.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "solvers/nearest_grid.h"

namespace artex {

void SurfaceErrors(const Eigen::MatrixX3d& tracked, const Eigen::MatrixX3d& truth,
                   const Eigen::MatrixX3d& truth_normals, double* mean, double* max,
                   std::vector<int>* nearest) {
  const NearestGrid grid(truth, NearestGrid::AutoCell(truth));
  const Eigen::Index count = tracked.rows();
  const bool guessed = nearest != nullptr && nearest->size() == static_cast<std::size_t>(count);
  if (nearest != nullptr && !guessed) nearest->assign(count, -1);
  double sum = 0.0, worst = 0.0;
  for (Eigen::Index t = 0; t < count; ++t) {
    const Eigen::Vector3d p = tracked.row(t);
    const int guess = guessed ? (*nearest)[t] : -1;
    const double bound2 = guess >= 0 && guess < truth.rows()
                              ? BoundKeeping(p, truth.row(guess).transpose())
                              : std::numeric_limits<double>::infinity();
    double d2 = 0.0;
    const int index = grid.NearestWithin(p, bound2, &d2);
    if (nearest != nullptr) (*nearest)[t] = index;
    if (index < 0) {
      if (nearest != nullptr) std::fill(nearest->begin() + t, nearest->end(), -1);
      break;
    }
    const Eigen::Vector3d q = truth.row(index);
    const Eigen::Vector3d n = truth_normals.row(index);
    const double plane = n.squaredNorm() > 0.5 ? std::abs(n.dot(p - q)) : std::sqrt(d2);
    const double d = std::min(std::sqrt(d2), plane);
    sum += d;
    worst = std::max(worst, d);
  }
  *mean = count ? sum / count : 0.0;
  *max = worst;
}

}  // namespace artex
