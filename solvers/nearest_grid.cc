#include "solvers/nearest_grid.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "models/error.h"
#include "models/numeric.h"

namespace artex {

namespace {
// The cells' distance bounds are shrunk by far more than their rounding, so that no cell is
// skipped that holds a point nearer than the best found.
constexpr double kSlack = 1.0 - 1e-9;
}  // namespace

double NearestGrid::AutoCell(const Eigen::MatrixX3d& points) {
  const Eigen::Index n = points.rows();
  if (n == 0) return 1.0;
  const Eigen::Vector3d extent =
      (points.colwise().maxCoeff() - points.colwise().minCoeff()).transpose().cwiseMax(1e-9);
  return std::max(std::cbrt(extent.prod() / static_cast<double>(n)), extent.maxCoeff() / 128.0);
}

NearestGrid::NearestGrid(const Eigen::MatrixX3d& points, double cell)
    : cell_(cell), inv_cell_(1.0 / cell) {
  if (!(std::isfinite(cell) && cell > 0.0)) {
    std::ostringstream msg;
    msg << "nearest grid: cell: expected a finite value > 0 (m), found " << cell;
    throw Error(msg.str());
  }
  const Eigen::Index n = points.rows();
  if (n == 0) return;
  if (!points.allFinite()) throw Error("nearest grid: points: expected finite coordinates");
  const Eigen::RowVector3d low = points.colwise().minCoeff();
  const Eigen::RowVector3d high = points.colwise().maxCoeff();
  double cells = 1.0;
  for (int d = 0; d < 3; ++d) {
    low_[d] = low[d];
    cells *= std::floor((high[d] - low[d]) * inv_cell_) + 1.0;
  }
  if (!(cells <= static_cast<double>(kMaxCells))) {
    std::ostringstream msg;
    msg << "nearest grid: cell: " << cell << " m makes " << cells
        << " cells over the points' bounding box, expected at most " << kMaxCells;
    throw Error(msg.str());
  }
  for (int d = 0; d < 3; ++d) dims_[d] = FloorToInt64((high[d] - low[d]) * inv_cell_) + 1;
  // Counting sort of the points by cell.
  std::vector<int> cell_of(n);
  begin_.assign(static_cast<size_t>(cells) + 1, 0);
  for (Eigen::Index i = 0; i < n; ++i) {
    int64_t c[3];
    for (int d = 0; d < 3; ++d) {
      c[d] = std::min(dims_[d] - 1, FloorToInt64((points(i, d) - low_[d]) * inv_cell_));
    }
    cell_of[i] = static_cast<int>((c[0] * dims_[1] + c[1]) * dims_[2] + c[2]);
    ++begin_[cell_of[i] + 1];
  }
  for (size_t c = 1; c < begin_.size(); ++c) begin_[c] += begin_[c - 1];
  std::vector<int> next(begin_.begin(), begin_.end() - 1);
  xyz_.resize(3 * n);
  index_.resize(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const int slot = next[cell_of[i]]++;
    for (int d = 0; d < 3; ++d) xyz_[3 * slot + d] = points(i, d);
    index_[slot] = static_cast<int>(i);
  }
}

int NearestGrid::NearestWithin(const Eigen::Vector3d& query, double bound2,
                               double* distance2) const {
  double best = bound2;
  int best_slot = -1;
  if (!index_.empty() && bound2 > 0.0 && query.allFinite()) {
    // The query in cell units, its cell (clamped next to the grid when outside: the shells
    // below still reach every cell) and the cells its bound reaches.
    const double reach = std::sqrt(bound2) * inv_cell_;
    double offset[3];
    int64_t home[3], lo[3], hi[3];
    bool reaches = true;
    for (int d = 0; d < 3; ++d) {
      offset[d] = (query[d] - low_[d]) * inv_cell_;
      const double limit = static_cast<double>(dims_[d]) + 2.0;
      const double clamped = std::clamp(offset[d], -2.0, limit);
      const double span = std::min(reach, limit + 2.0);
      home[d] = FloorToInt64(clamped);
      lo[d] = std::max<int64_t>(0, FloorToInt64(clamped - span));
      hi[d] = std::min<int64_t>(dims_[d] - 1, FloorToInt64(clamped + span));
      reaches = reaches && lo[d] <= hi[d];
    }
    const double cell2 = cell_ * cell_;
    // Squared distance (cells^2) along axis d from the query to the cells first .. last.
    const auto gap2 = [&](int d, int64_t first, int64_t last) {
      const double g = std::max({0.0, static_cast<double>(first) - offset[d],
                                 offset[d] - static_cast<double>(last + 1)});
      return g * g;
    };
    // The points of cell (x, y, z), whose squared distance along x and y is gap_xy (cells^2).
    const auto visit = [&](int64_t row, double gap_xy, int64_t z) {
      const int cell = static_cast<int>(row + z);
      const int first = begin_[cell], last = begin_[cell + 1];
      if (first == last) return;
      if ((gap_xy + gap2(2, z, z)) * cell2 * kSlack >= best) return;
      for (int s = first; s < last; ++s) {
        const double* p = xyz_.data() + 3 * s;
        double dist = 0.0;
        for (int d = 0; d < 3; ++d) {
          const double diff = query[d] - p[d];
          dist += diff * diff;
        }
        if (dist <= best) {  // rarely: a nearer point, or a tie (the lower index wins)
          if (dist < best || (best_slot >= 0 && index_[s] < index_[best_slot])) {
            best = dist;
            best_slot = s;
          }
        }
      }
    };
    // A lower bound on the squared distance (cells^2) to every reached cell at least k cells
    // from home along some axis: along that axis at least to the nearest such cell, along the
    // others to the reached range. Nondecreasing in k; +inf when no such cell remains.
    double range2[3];
    for (int d = 0; d < 3; ++d) range2[d] = gap2(d, lo[d], hi[d]);
    const auto beyond2 = [&](int64_t k) {
      double bound = std::numeric_limits<double>::infinity();
      for (int d = 0; d < 3; ++d) {
        const double others = range2[(d + 1) % 3] + range2[(d + 2) % 3];
        if (home[d] + k <= hi[d]) {
          const int64_t c = std::max(home[d] + k, lo[d]);
          bound = std::min(bound, gap2(d, c, c) + others);
        }
        if (home[d] - k >= lo[d]) {
          const int64_t c = std::min(home[d] - k, hi[d]);
          bound = std::min(bound, gap2(d, c, c) + others);
        }
      }
      return bound;
    };
    // Shells of cells around home, nearest first: shell k holds the cells whose largest
    // coordinate difference from home is k.
    for (int64_t k = 0; reaches; ++k) {
      if (k >= 1 && beyond2(k) * cell2 * kSlack >= best) break;
      const int64_t x0 = std::max(lo[0], home[0] - k), x1 = std::min(hi[0], home[0] + k);
      const int64_t y0 = std::max(lo[1], home[1] - k), y1 = std::min(hi[1], home[1] + k);
      const int64_t z0 = std::max(lo[2], home[2] - k), z1 = std::min(hi[2], home[2] + k);
      for (int64_t x = x0; x <= x1; ++x) {
        const bool x_edge = x == home[0] - k || x == home[0] + k;
        const double gap_x = gap2(0, x, x);
        for (int64_t y = y0; y <= y1; ++y) {
          const int64_t row = (x * dims_[1] + y) * dims_[2];
          const double gap_xy = gap_x + gap2(1, y, y);
          if (gap_xy * cell2 * kSlack >= best) continue;
          if (x_edge || y == home[1] - k || y == home[1] + k) {
            for (int64_t z = z0; z <= z1; ++z) visit(row, gap_xy, z);
          } else if (z0 <= z1) {  // the two ends of the column, where they lie in the grid
            if (home[2] - k == z0) visit(row, gap_xy, z0);
            if (home[2] + k == z1) visit(row, gap_xy, z1);
          }
        }
      }
    }
  }
  if (distance2) *distance2 = best_slot >= 0 ? best : std::numeric_limits<double>::infinity();
  return best_slot >= 0 ? index_[best_slot] : -1;
}

}  // namespace artex
