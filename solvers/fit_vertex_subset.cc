#include "solvers/fit_vertex_subset.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <tuple>
#include <vector>

namespace artex {

std::vector<int> VoxelVertexSubset(const Eigen::MatrixX3d& vertices, int count) {
  const int v = static_cast<int>(vertices.rows());
  if (v == 0 || count <= 0) return {};
  const Eigen::RowVector3d low = vertices.colwise().minCoeff();
  const double extent = (vertices.colwise().maxCoeff() - low).maxCoeff();
  if (!(extent > 0.0)) return {0};  // every vertex at one point: one cell (or no finite extent)
  // Vertex i's cell coordinates for a cell size (>= 0: low is the minimum); the counts below
  // and the chosen grid's cells use these same ones.
  const auto cell_coords = [&](int i, double cell, int64_t* coords) {
    for (int d = 0; d < 3; ++d) {
      coords[d] = static_cast<int64_t>(std::floor((vertices(i, d) - low[d]) / cell));
    }
  };
  const auto cell_key = [&](int i, double cell, int64_t* coords) {  // Z-curve order
    cell_coords(i, cell, coords);
    uint64_t key = 0;
    for (int bit = 20; bit >= 0; --bit) {
      for (int d = 0; d < 3; ++d) key = key << 1 | ((static_cast<uint64_t>(coords[d]) >> bit) & 1);
    }
    return key;
  };
  // Occupied cells of a cell size, counted exactly in an open-addressing set of the cells'
  // packed coordinates (21 bits each; the smallest cell, 1e-4 of the extent, needs 14). The
  // bisection counts 30 cell sizes; sorting Z-curve keys for each took ~25 ms per call.
  int table_bits = 4;
  while ((1 << table_bits) < 2 * std::max(v, 1)) ++table_bits;
  std::vector<uint64_t> table(size_t{1} << table_bits);
  const uint64_t mask = (uint64_t{1} << table_bits) - 1;
  constexpr uint64_t kEmpty = ~uint64_t{0};  // no packed key has all 64 bits set
  const auto occupied = [&](double cell) {
    std::fill(table.begin(), table.end(), kEmpty);
    int cells = 0;
    int64_t coords[3];
    for (int i = 0; i < v; ++i) {
      cell_coords(i, cell, coords);
      uint64_t key = 0;
      for (int d = 0; d < 3; ++d) key |= (static_cast<uint64_t>(coords[d]) & 0x1fffff) << (21 * d);
      uint64_t slot = (key * 0x9e3779b97f4a7c15ULL) >> (64 - table_bits);
      while (table[slot] != kEmpty && table[slot] != key) slot = (slot + 1) & mask;
      if (table[slot] == kEmpty) {
        table[slot] = key;
        ++cells;
      }
    }
    return cells;
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
