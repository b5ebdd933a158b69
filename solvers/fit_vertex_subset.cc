#include "solvers/fit_vertex_subset.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <tuple>

namespace artex {

std::vector<int> VoxelVertexSubset(const Eigen::MatrixX3d& vertices, int count) {
  const int v = static_cast<int>(vertices.rows());
  const Eigen::RowVector3d low = vertices.colwise().minCoeff();
  const double extent = (vertices.colwise().maxCoeff() - low).maxCoeff();
  const auto cell_key = [&](int i, double cell, int64_t* coords) {
    for (int d = 0; d < 3; ++d) {
      coords[d] = static_cast<int64_t>(std::floor((vertices(i, d) - low[d]) / cell));
    }
    uint64_t key = 0;
    for (int bit = 20; bit >= 0; --bit) {
      for (int d = 0; d < 3; ++d) key = key << 1 | ((static_cast<uint64_t>(coords[d]) >> bit) & 1);
    }
    return key;
  };
  const auto occupied = [&](double cell) {
    std::vector<uint64_t> keys(v);
    int64_t coords[3];
    for (int i = 0; i < v; ++i) keys[i] = cell_key(i, cell, coords);
    std::sort(keys.begin(), keys.end());
    return static_cast<int>(std::unique(keys.begin(), keys.end()) - keys.begin());
  };
  double lo = extent * 1e-4, hi = extent;  // occupied(hi) = 1 <= count
  for (int it = 0; it < 30; ++it) {        // cell size to ~1e-9 of the extent
    const double mid = 0.5 * (lo + hi);
    (occupied(mid) > count ? lo : hi) = mid;
  }
  const double cell = hi;
  std::vector<std::tuple<uint64_t, double, int>> ranked(v);
  int64_t coords[3];
  for (int i = 0; i < v; ++i) {
    const uint64_t key = cell_key(i, cell, coords);
    double d2 = 0.0;
    for (int d = 0; d < 3; ++d) {
      const double centre = low[d] + (coords[d] + 0.5) * cell;
      d2 += (vertices(i, d) - centre) * (vertices(i, d) - centre);
    }
    ranked[i] = {key, d2, i};
  }
  std::sort(ranked.begin(), ranked.end());
  std::vector<int> subset;
  for (int i = 0; i < v; ++i) {
    if (i == 0 || std::get<0>(ranked[i]) != std::get<0>(ranked[i - 1])) {
      subset.push_back(std::get<2>(ranked[i]));
    }
  }
  return subset;
}

}  // namespace artex
