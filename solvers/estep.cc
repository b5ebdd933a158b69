#include "solvers/estep.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <nanoflann.hpp>
#include <new>
#include <sstream>
#include <utility>

#include "models/default_init_allocator.h"
#include "models/error.h"
#include "models/numeric.h"
#include "solvers/estep_pairs.h"

namespace artex {

using estep_internal::CheckPosed;
using estep_internal::CheckScan;
using estep_internal::Finish;
using estep_internal::ForRange;
using estep_internal::kPackedStride;
using estep_internal::ResizeTargets;
using estep_internal::VertexQuery;
using estep_internal::VertexSums;
using estep_internal::WeighVertex;

const char* EStepModeName(EStepMode mode) {
  switch (mode) {
    case EStepMode::kDense:
      return "dense";
    case EStepMode::kRadius:
      return "radius";
    case EStepMode::kKNearest:
      return "knn";
  }
  return "unknown";
}

bool EStepOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  std::string inner;
  if (!weights.IsValid(&inner)) {
    msg << "weights." << inner;
  } else if (k < 1) {
    msg << "k: expected >= 1, found " << k;
  } else if (!(std::isfinite(voxel_fraction) && voxel_fraction >= 0.0 && voxel_fraction <= 1.0)) {
    msg << "voxel_fraction: expected a value in [0, 1], found " << voxel_fraction;
  } else if (!(std::isfinite(candidate_margin) && candidate_margin >= 0.0)) {
    msg << "candidate_margin: expected a finite value >= 0 (m), found " << candidate_margin;
  } else if (!(std::isfinite(voxel_cell) && voxel_cell >= 0.0)) {
    msg << "voxel_cell: expected a finite value >= 0 (m; 0: radius * voxel_fraction), found "
        << voxel_cell;
  } else if (!(std::isfinite(list_radius) && list_radius >= 0.0)) {
    msg << "list_radius: expected a finite value >= 0 (m; 0: lists per radius), found "
        << list_radius;
  } else if (kdtree_leaf_size < 1) {
    msg << "kdtree_leaf_size: expected >= 1, found " << kdtree_leaf_size;
  } else if (grain_size < 1) {
    msg << "grain_size: expected >= 1, found " << grain_size;
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

// ---------------------------------------------------------------------------------------------
// Shared accumulation

namespace {

// Allocator on cache-line boundaries: a packed point (8 doubles) is then one cache line.
template <typename T>
struct CacheLineAllocator {
  using value_type = T;
  static constexpr std::align_val_t kAlignment{64};
  CacheLineAllocator() = default;
  template <typename U>
  CacheLineAllocator(const CacheLineAllocator<U>&) {}  // NOLINT(runtime/explicit)
  T* allocate(std::size_t n) { return static_cast<T*>(::operator new(n * sizeof(T), kAlignment)); }
  void deallocate(T* p, std::size_t) { ::operator delete(p, kAlignment); }
  template <typename U>
  bool operator==(const CacheLineAllocator<U>&) const {
    return true;
  }
  template <typename U>
  bool operator!=(const CacheLineAllocator<U>&) const {
    return false;
  }
};

// Candidate indices (cloud rows); resize() leaves new entries unwritten (the gathers size
// their output, then fill it).
using IndexBuffer = std::vector<int, DefaultInitAllocator<int>>;

// Integer grid coordinate of a scaled coordinate, offset to fit 21 bits (clamped).
inline int64_t GridCoordinate(double scaled) {
  constexpr int64_t kOffset = 1 << 20;
  constexpr double kRange = 1u << 22;  // beyond: clamped whatever the rounding
  // NaN lands on the lower clamp.
  if (!(std::abs(scaled) < kRange)) return scaled > 0.0 ? (int64_t{1} << 21) - 1 : 0;
  return std::clamp<int64_t>(FloorToInt64(scaled) + kOffset, 0, (int64_t{1} << 21) - 1);
}

// Sorts (key, index) pairs whose indices ascend in input order exactly as std::sort would
// (by key, ties by index): a stable least-significant-digit radix sort over the key bits
// that differ between the pairs.
void SortByKey(std::vector<std::pair<uint64_t, int>>* pairs) {
  const size_t n = pairs->size();
  if (n < 1024) {
    std::sort(pairs->begin(), pairs->end());
    return;
  }
  uint64_t differ = 0;
  const uint64_t first = (*pairs)[0].first;
  for (const auto& p : *pairs) differ |= p.first ^ first;
  if (differ == 0) return;  // one key: already in index order
  const int bits = 64 - __builtin_clzll(differ);
  constexpr int kDigit = 11;
  constexpr size_t kBuckets = size_t{1} << kDigit;
  constexpr uint64_t kMask = kBuckets - 1;
  const int passes = (bits + kDigit - 1) / kDigit;
  // Every pass's histogram in one read of the keys (a digit's counts do not depend on the
  // order the earlier passes left).
  std::vector<size_t> start(kBuckets * passes, 0);
  for (const auto& p : *pairs) {
    for (int pass = 0; pass < passes; ++pass) {
      ++start[kBuckets * pass + ((p.first >> (kDigit * pass)) & kMask)];
    }
  }
  std::vector<std::pair<uint64_t, int>> buffer(n);
  for (int pass = 0; pass < passes; ++pass) {
    const int shift = kDigit * pass;
    size_t* begin = start.data() + kBuckets * pass;
    size_t sum = 0;
    for (size_t b = 0; b < kBuckets; ++b) {
      const size_t count = begin[b];
      begin[b] = sum;
      sum += count;
    }
    for (const auto& p : *pairs) buffer[begin[(p.first >> shift) & kMask]++] = p;
    pairs->swap(buffer);
  }
}

// Morton (Z-curve) code of three 21-bit grid coordinates (out of range: clamped).
inline uint64_t MortonCode(int64_t x, int64_t y, int64_t z) {
  const auto spread = [](int64_t value) {  // 21 bits -> every third bit
    uint64_t v = static_cast<uint64_t>(std::clamp<int64_t>(value, 0, (int64_t{1} << 21) - 1));
    v = (v | v << 32) & 0x1f00000000ffffULL;
    v = (v | v << 16) & 0x1f0000ff0000ffULL;
    v = (v | v << 8) & 0x100f00f00f00f00fULL;
    v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
    v = (v | v << 2) & 0x1249249249249249ULL;
    return v;
  };
  return spread(x) << 2 | spread(y) << 1 | spread(z);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Truncated E-step

struct EStep::Cloud {
  Eigen::MatrixX3d points, normals, colors;
  Eigen::VectorXd color_valid;  // 1 / 0
  Eigen::VectorXd count;        // multiplicity (1 for the full scan)
  std::unique_ptr<PointCloudIndex> index;
  // Row-major copies for the pair loops: kPacked values per point (x y z nx ny nz count -)
  // and 4 per point (r g b valid) when the cloud has colours.
  static constexpr int kPacked = kPackedStride;
  std::vector<double, CacheLineAllocator<double>> packed;
  std::vector<double> packed_colors;
  // Uniform grid for the candidate gathers (instead of the kd-tree): cubic cells of side
  // grid_cell, the points ordered by cell; cell_keys (ascending Morton codes of the occupied
  // cells) and cell_begin (+ 1) index them.
  double grid_cell = 0.0;
  std::vector<uint64_t> cell_keys;
  std::vector<int> cell_begin;
  // Dense lookup over the occupied cells' bounding box (grid coordinates cell_low ..
  // cell_low + cell_dims - 1): the cell's number in cell_keys, -1 when empty. Empty (and the
  // binary search over cell_keys used) when the box would hold too many cells.
  int64_t cell_low[3] = {0, 0, 0};
  int64_t cell_dims[3] = {0, 0, 0};
  std::vector<int> cell_lookup;

  // Builds cell_lookup from the cells' grid coordinates (3 per cell, as cell_keys).
  void BuildCellLookup(const std::vector<int64_t>& coords) {
    cell_lookup.clear();
    const size_t cells = cell_keys.size();
    if (cells == 0) return;
    int64_t high[3];
    for (int d = 0; d < 3; ++d) cell_low[d] = high[d] = coords[d];
    for (size_t c = 0; c < cells; ++c) {
      for (int d = 0; d < 3; ++d) {
        cell_low[d] = std::min(cell_low[d], coords[3 * c + d]);
        high[d] = std::max(high[d], coords[3 * c + d]);
      }
    }
    // A cap against outliers far from the subject: at most 64 lookup entries per cell (and
    // at least 2^16). The grid coordinates' clamped border stays outside the box, so that the
    // lookup sees exactly the cells the Morton search finds.
    const double limit = std::max<double>(65536.0, 64.0 * static_cast<double>(cells));
    double size = 1.0;
    for (int d = 0; d < 3; ++d) {
      cell_dims[d] = high[d] - cell_low[d] + 1;
      size *= static_cast<double>(cell_dims[d]);
      if (cell_low[d] <= 0 || high[d] >= (int64_t{1} << 21) - 1) size = limit + 1.0;
    }
    if (size > limit) {
      for (int d = 0; d < 3; ++d) cell_dims[d] = 0;
      return;
    }
    cell_lookup.assign(static_cast<size_t>(size), -1);
    for (size_t c = 0; c < cells; ++c) {
      cell_lookup[static_cast<size_t>(
          ((coords[3 * c] - cell_low[0]) * cell_dims[1] + coords[3 * c + 1] - cell_low[1]) *
              cell_dims[2] +
          coords[3 * c + 2] - cell_low[2])] = static_cast<int>(c);
    }
  }

  // The number of the cell at grid coordinates (x, y, z) in cell_keys, -1 when empty.
  int FindCell(int64_t x, int64_t y, int64_t z) const {
    if (!cell_lookup.empty()) {
      x -= cell_low[0];
      y -= cell_low[1];
      z -= cell_low[2];
      if (x < 0 || y < 0 || z < 0 || x >= cell_dims[0] || y >= cell_dims[1] || z >= cell_dims[2]) {
        return -1;
      }
      return cell_lookup[static_cast<size_t>((x * cell_dims[1] + y) * cell_dims[2] + z)];
    }
    const uint64_t key = MortonCode(x, y, z);
    const auto it = std::lower_bound(cell_keys.begin(), cell_keys.end(), key);
    if (it == cell_keys.end() || *it != key) return -1;
    return static_cast<int>(it - cell_keys.begin());
  }

  // Blocks of kBlock consecutive points of a cell (its last block may be shorter) with their
  // bounding boxes, so that a gather tests whole blocks against its sphere.
  static constexpr int kBlock = 8;
  static constexpr double kBoxSlack = 1e-9;
  std::vector<int> cell_block;    // per cell + 1: its first block
  std::vector<double> block_box;  // 6 per block: low x y z, high x y z

  void BuildBlocks() {
    const int cells = static_cast<int>(cell_keys.size());
    cell_block.assign(1, 0);
    block_box.clear();
    for (int cell = 0; cell < cells; ++cell) {
      for (int s0 = cell_begin[cell]; s0 < cell_begin[cell + 1]; s0 += kBlock) {
        const int s1 = std::min(s0 + kBlock, cell_begin[cell + 1]);
        double box[6];
        for (int d = 0; d < 3; ++d) box[d] = box[3 + d] = packed[kPacked * s0 + d];
        for (int s = s0 + 1; s < s1; ++s) {
          for (int d = 0; d < 3; ++d) {
            box[d] = std::min(box[d], packed[kPacked * s + d]);
            box[3 + d] = std::max(box[3 + d], packed[kPacked * s + d]);
          }
        }
        block_box.insert(block_box.end(), box, box + 6);
      }
      cell_block.push_back(static_cast<int>(block_box.size() / 6));
    }
  }

  // Appends the indices of the points with |p - x| < radius (radius <= grid_cell): those lie
  // in the query's cell and its 26 neighbours; cells farther than the radius are skipped.
  void GridRadius(const double* x, double radius, IndexBuffer* out) const {
    const double inv = 1.0 / grid_cell;
    int64_t c[3];
    double below[3], above[3];  // distance from x to its cell's lower / upper faces
    for (int d = 0; d < 3; ++d) {
      const double scaled = x[d] * inv;
      c[d] = GridCoordinate(scaled);
      below[d] = (scaled - std::floor(scaled)) * grid_cell;
      above[d] = grid_cell - below[d];
    }
    const double r2 = radius * radius;
    const auto gap2 = [&](int d, int64_t offset) {
      const double g = offset < 0 ? below[d] : (offset > 0 ? above[d] : 0.0);
      return g * g;
    };
    for (int64_t dx = -1; dx <= 1; ++dx) {
      for (int64_t dy = -1; dy <= 1; ++dy) {
        for (int64_t dz = -1; dz <= 1; ++dz) {
          if (gap2(0, dx) + gap2(1, dy) + gap2(2, dz) >= r2) continue;
          const int cell = FindCell(c[0] + dx, c[1] + dy, c[2] + dz);
          if (cell < 0) continue;
          const int first = cell_begin[cell], last = cell_begin[cell + 1];
          for (int b = cell_block[cell]; b < cell_block[cell + 1]; ++b) {
            const int s0 = first + kBlock * (b - cell_block[cell]);
            const int s1 = std::min(s0 + kBlock, last);
            // The block's box against the sphere, with a relative slack far above the
            // rounding of the distances, so that every point of a block skipped (taken whole)
            // would fail (pass) the test below.
            const double* box = block_box.data() + 6 * b;
            double near2 = 0.0, far2 = 0.0;
            for (int d = 0; d < 3; ++d) {
              const double to_low = x[d] - box[d], to_high = box[3 + d] - x[d];
              const double g = std::max(0.0, std::max(-to_low, -to_high));
              const double f = std::max(to_low, to_high);
              near2 += g * g;
              far2 += f * f;
            }
            if (near2 > r2 * (1.0 + kBoxSlack)) continue;
            const size_t n = out->size();
            out->resize(n + static_cast<size_t>(s1 - s0));
            int* o = out->data() + n;
            if (far2 < r2 * (1.0 - kBoxSlack)) {
              for (int s = s0; s < s1; ++s) *o++ = s;
              continue;
            }
            for (int s = s0; s < s1; ++s) {
              const double* p = packed.data() + kPacked * s;
              const double e0 = p[0] - x[0], e1 = p[1] - x[1], e2 = p[2] - x[2];
              *o = s;
              o += e0 * e0 + e1 * e1 + e2 * e2 < r2;
            }
            out->resize(static_cast<size_t>(o - out->data()));
          }
        }
      }
    }
  }

  void Pack() {
    const Eigen::Index m = points.rows();
    packed.assign(static_cast<size_t>(kPacked * m), 0.0);
    for (Eigen::Index i = 0; i < m; ++i) {
      double* q = packed.data() + kPacked * i;
      for (int d = 0; d < 3; ++d) {
        q[d] = points(i, d);
        q[3 + d] = normals(i, d);
      }
      q[6] = count[i];
    }
    if (grid_cell > 0.0) BuildBlocks();
    packed_colors.clear();
    if (colors.rows() == m) {
      packed_colors.resize(static_cast<size_t>(4 * m));
      for (Eigen::Index i = 0; i < m; ++i) {
        for (int d = 0; d < 3; ++d) packed_colors[4 * i + d] = colors(i, d);
        packed_colors[4 * i + 3] = color_valid[i];
      }
    }
  }
};

// Candidate lists of one radius, per block of grain_size template vertices (CSR).
struct EStep::Candidates {
  struct Block {
    bool valid = false;
    std::vector<double> anchor;  // 3 per vertex: its position when gathered
    std::vector<int> offset;     // per vertex of the block, + 1
    IndexBuffer index;           // cloud indices within gather radius + margin of the anchor
  };
  int t_count = -1;
  std::vector<Block> blocks;
};

EStep::EStep(const Scan& scan, const EStepOptions& options) : scan_(scan), options_(options) {
  std::string error;
  if (!options.IsValid(&error)) throw Error("E-step options: " + error);
  CheckScan(scan, "E-step");
  full_ = std::make_unique<Cloud>();
}

const EStep::Cloud& EStep::FullCloud() const {
  // Built on first use: the radius E-step's voxel clouds read the scan itself.
  std::call_once(full_index_once_, [this] {
    const int n = scan_.size();
    full_->points = scan_.points;
    full_->normals = scan_.normals;
    if (scan_.colors.rows() == n) {
      full_->colors = scan_.colors;
      full_->color_valid = Eigen::VectorXd::Ones(n);
      for (int s = 0; s < n && !scan_.color_valid.empty(); ++s) {
        full_->color_valid[s] = scan_.color_valid[s] ? 1.0 : 0.0;
      }
    }
    full_->count = Eigen::VectorXd::Ones(n);
    full_->index = std::make_unique<PointCloudIndex>(full_->points, options_.kdtree_leaf_size);
    full_->Pack();
  });
  return *full_;
}

EStep::~EStep() = default;

double EStep::GatherRadius(double radius) const {
  return options_.list_radius >= radius ? options_.list_radius : radius;
}

const EStep::Cloud& EStep::CloudForRadius(double radius, double gather_radius,
                                          std::pair<double, double>* cloud_key) {
  double cell = radius * options_.voxel_fraction;
  if (options_.voxel_cell > 0.0 && cell > 0.0) cell = options_.voxel_cell;
  if (options_.mode != EStepMode::kRadius || !(cell > 0.0)) {
    if (cloud_key) *cloud_key = {0.0, gather_radius};
    return FullCloud();
  }
  const std::pair<double, double> key(cell, gather_radius);
  if (cloud_key) *cloud_key = key;
  auto it = subsampled_.find(key);
  if (it != subsampled_.end()) return *it->second;
  // Voxel grid: mean position, summed then normalised normal, mean valid colour, count. Cells
  // are numbered in Morton (Z-curve) order of their grid coordinates, so that cells close in
  // space are close in memory (the pair loops gather them per template vertex).
  const int n = scan_.size();
  const bool has_color = scan_.colors.rows() == n;
  std::vector<std::pair<uint64_t, int>> keyed(n);
  const double inv = 1.0 / cell;
  for (int s = 0; s < n; ++s) {
    keyed[s] = {MortonCode(GridCoordinate(scan_.points(s, 0) * inv),
                           GridCoordinate(scan_.points(s, 1) * inv),
                           GridCoordinate(scan_.points(s, 2) * inv)),
                s};
  }
  SortByKey(&keyed);
  int m = 0;
  for (int i = 0; i < n; ++i) m += (i == 0 || keyed[i].first != keyed[i - 1].first);
  auto cloud = std::make_unique<Cloud>();
  cloud->points.setZero(m, 3);
  cloud->normals.setZero(m, 3);
  cloud->count.setZero(m);
  Eigen::VectorXd color_count;
  if (has_color) {
    cloud->colors.setZero(m, 3);
    color_count.setZero(m);
  }
  for (int i = 0, c = -1; i < n; ++i) {
    if (i == 0 || keyed[i].first != keyed[i - 1].first) ++c;
    const int s = keyed[i].second;
    for (int d = 0; d < 3; ++d) {
      cloud->points(c, d) += scan_.points(s, d);
      cloud->normals(c, d) += scan_.normals(s, d);
    }
    cloud->count[c] += 1.0;
    if (has_color && (scan_.color_valid.empty() || scan_.color_valid[s])) {
      for (int d = 0; d < 3; ++d) cloud->colors(c, d) += scan_.colors(s, d);
      color_count[c] += 1.0;
    }
  }
  if (has_color) cloud->color_valid = (color_count.array() > 0.0).cast<double>();
  for (int c = 0; c < m; ++c) {
    cloud->points.row(c) /= cloud->count[c];
    const double norm = cloud->normals.row(c).norm();
    if (norm > 0.0) cloud->normals.row(c) /= norm;
    if (has_color && color_count[c] > 0.0) cloud->colors.row(c) /= color_count[c];
  }
  if (options_.candidate_margin > 0.0) {
    // Candidate lists: gathers within gather_radius + margin on a grid of that cell size. The
    // cells are reordered by grid cell (stable: Morton order within a cell).
    const double grid = gather_radius + options_.candidate_margin;
    const double inv_grid = 1.0 / grid;
    std::vector<std::pair<uint64_t, int>> by_cell(m);
    for (int c = 0; c < m; ++c) {
      by_cell[c] = {MortonCode(GridCoordinate(cloud->points(c, 0) * inv_grid),
                               GridCoordinate(cloud->points(c, 1) * inv_grid),
                               GridCoordinate(cloud->points(c, 2) * inv_grid)),
                    c};
    }
    SortByKey(&by_cell);  // ties by original (Morton) index
    Cloud sorted;
    std::vector<int64_t> cell_coords;  // 3 per occupied cell
    sorted.points.resize(m, 3);
    sorted.normals.resize(m, 3);
    sorted.count.resize(m);
    if (has_color) {
      sorted.colors.resize(m, 3);
      sorted.color_valid.resize(m);
    }
    for (int i = 0; i < m; ++i) {
      const int c = by_cell[i].second;
      sorted.points.row(i) = cloud->points.row(c);
      sorted.normals.row(i) = cloud->normals.row(c);
      sorted.count[i] = cloud->count[c];
      if (has_color) {
        sorted.colors.row(i) = cloud->colors.row(c);
        sorted.color_valid[i] = cloud->color_valid[c];
      }
      if (i == 0 || by_cell[i].first != by_cell[i - 1].first) {
        sorted.cell_keys.push_back(by_cell[i].first);
        sorted.cell_begin.push_back(i);
        for (int d = 0; d < 3; ++d) {
          cell_coords.push_back(GridCoordinate(sorted.points(i, d) * inv_grid));
        }
      }
    }
    sorted.cell_begin.push_back(m);
    sorted.grid_cell = grid;
    sorted.BuildCellLookup(cell_coords);
    *cloud = std::move(sorted);
  } else {
    cloud->index = std::make_unique<PointCloudIndex>(cloud->points, options_.kdtree_leaf_size);
  }
  cloud->Pack();
  const Cloud& result = *cloud;
  subsampled_.emplace(key, std::move(cloud));
  return result;
}

void EStep::Compute(const PosedTemplateView& posed, double radius, CorrespondenceTargets* targets) {
  CheckPosed(posed, "E-step");
  const int t_count = static_cast<int>(posed.vertices->rows());
  if (options_.mode == EStepMode::kDense) {
    DenseEStep(scan_, posed, options_.weights, targets, options_.parallel);
    return;
  }
  if (options_.mode == EStepMode::kRadius && !(std::isfinite(radius) && radius > 0.0)) {
    std::ostringstream msg;
    msg << "E-step: expected a finite search radius > 0 (m), found " << radius;
    throw Error(msg.str());
  }
  ResizeTargets(t_count, targets);
  const double gather = GatherRadius(radius);
  std::pair<double, double> cloud_key;
  const Cloud& cloud = CloudForRadius(radius, gather, &cloud_key);
  const int m = static_cast<int>(cloud.points.rows());
  if (m == 0 || t_count == 0) return;
  const OneToManyOptions& w = options_.weights;
  const bool color = w.use_color && posed.colors != nullptr && !cloud.packed_colors.empty();
  const bool normalize = w.normalize_per_scan_point;
  const int grain = options_.grain_size;
  const int num_chunks = (t_count + grain - 1) / grain;
  const bool knn = options_.mode == EStepMode::kKNearest;

  // Candidate lists (radius mode with a margin): one per radius, blocks of `grain` vertices.
  Candidates* candidates = nullptr;
  const double margin = options_.candidate_margin;
  if (!knn && margin > 0.0) {
    std::unique_ptr<Candidates>& slot = candidates_[cloud_key];
    if (!slot) slot = std::make_unique<Candidates>();
    if (slot->t_count != t_count) {
      slot->t_count = t_count;
      slot->blocks.assign(num_chunks, Candidates::Block());
    }
    candidates = slot.get();
  }

  // Pass 1: per chunk of template vertices, either the sums directly (no normalisation) or
  // the (s, p_st) pairs in CSR form (normalisation needs sum_t p_st first).
  struct ChunkPairs {
    std::vector<int> offset;  // per vertex of the chunk, + 1
    std::vector<int> s;
    std::vector<double> p;
  };
  std::vector<ChunkPairs> chunks(normalize ? num_chunks : 0);
  std::vector<double> constants(num_chunks, 0.0);
  std::vector<long long> pairs(num_chunks, 0);
  std::vector<long long> queries(num_chunks, 0), visited(num_chunks, 0);
  const double* packed = cloud.packed.data();
  const double* packed_colors = color ? cloud.packed_colors.data() : nullptr;
  constexpr int kP = Cloud::kPacked;
  ForRange(num_chunks, 1, options_.parallel, [&](int chunk_begin, int chunk_end) {
    std::vector<std::pair<int, double>> found;
    std::vector<int> found_index;
    std::vector<double> found_d2;
    std::vector<int> knn_index(knn ? options_.k : 0);
    std::vector<double> knn_d2(knn ? options_.k : 0);
    Candidates::Block fresh;
    for (int chunk = chunk_begin; chunk < chunk_end; ++chunk) {
      const int t0 = chunk * grain, t1 = std::min(t_count, t0 + grain);
      ChunkPairs* out = normalize ? &chunks[chunk] : nullptr;
      if (out) {
        out->offset.assign(1, 0);
        out->s.clear();
        out->p.clear();
      }
      Candidates::Block* block = candidates ? &candidates->blocks[chunk] : nullptr;
      if (block) {
        // Gather again the vertices that left their margin (all, the first time); the others
        // keep their lists. Lists of a wider gather radius leave this radius a wider margin.
        const double keep = gather > radius ? gather + margin - radius : margin;
        bool any = !block->valid;
        std::vector<char> moved(t1 - t0, block->valid ? 0 : 1);
        for (int t = t0; t < t1 && block->valid; ++t) {
          const double* a = block->anchor.data() + 3 * (t - t0);
          const double dx = (*posed.vertices)(t, 0) - a[0], dy = (*posed.vertices)(t, 1) - a[1],
                       dz = (*posed.vertices)(t, 2) - a[2];
          moved[t - t0] = dx * dx + dy * dy + dz * dz > keep * keep;
          any = any || moved[t - t0];
        }
        if (any) {
          fresh.anchor.resize(3 * (t1 - t0));
          fresh.offset.assign(1, 0);
          fresh.index.clear();
          // About the lists' size (the old ones, or ~64 candidates a vertex the first time),
          // so that the gathers rarely grow the buffer.
          fresh.index.reserve(std::max(block->index.size() + block->index.size() / 8,
                                       static_cast<size_t>(64 * (t1 - t0))));
          for (int t = t0; t < t1; ++t) {
            const int i = t - t0;
            if (moved[i]) {
              const Eigen::Vector3d x = posed.vertices->row(t).transpose();
              for (int d = 0; d < 3; ++d) fresh.anchor[3 * i + d] = x[d];
              if (cloud.grid_cell > 0.0) {
                cloud.GridRadius(x.data(), gather + margin, &fresh.index);
              } else {
                cloud.index->Radius(x, gather + margin, &found);
                for (const auto& entry : found) fresh.index.push_back(entry.first);
              }
              ++queries[chunk];
            } else {
              for (int d = 0; d < 3; ++d) fresh.anchor[3 * i + d] = block->anchor[3 * i + d];
              fresh.index.insert(fresh.index.end(), block->index.begin() + block->offset[i],
                                 block->index.begin() + block->offset[i + 1]);
            }
            fresh.offset.push_back(static_cast<int>(fresh.index.size()));
          }
          fresh.valid = true;
          std::swap(*block, fresh);
        }
      }
      for (int t = t0; t < t1; ++t) {
        VertexQuery q;
        for (int d = 0; d < 3; ++d) {
          q.x[d] = (*posed.vertices)(t, d);
          q.n[d] = (*posed.normals)(t, d);
          q.c[d] = color ? (*posed.colors)(t, d) : 0.0;
        }
        q.radius2 = radius * radius;
        q.epsilon = w.epsilon;
        q.lambda_color = w.lambda_color;
        VertexSums sums;
        std::vector<int>* store_s = out ? &out->s : nullptr;
        std::vector<double>* store_p = out ? &out->p : nullptr;
        if (block) {
          const int begin = block->offset[t - t0], end = block->offset[t - t0 + 1];
          visited[chunk] += end - begin;
          WeighVertex(color, true, q, packed, packed_colors, block->index.data() + begin,
                      end - begin, nullptr, &sums, store_s, store_p);
        } else {
          const Eigen::Vector3d x(q.x[0], q.x[1], q.x[2]);
          ++queries[chunk];
          int got = 0;
          const int* index = nullptr;
          const double* d2 = nullptr;
          if (knn) {
            got = cloud.index->KNearest(x, options_.k, knn_index.data(), knn_d2.data());
            index = knn_index.data();
            d2 = knn_d2.data();
          } else {
            cloud.index->Radius(x, radius, &found);
            got = static_cast<int>(found.size());
            found_index.resize(got);
            found_d2.resize(got);
            for (int i = 0; i < got; ++i) {
              found_index[i] = found[i].first;
              found_d2[i] = found[i].second;
            }
            index = found_index.data();
            d2 = found_d2.data();
          }
          WeighVertex(color, false, q, packed, packed_colors, index, got, d2, &sums, store_s,
                      store_p);
        }
        if (out) {
          out->offset.push_back(static_cast<int>(out->s.size()));
        } else {
          constants[chunk] += Finish(sums, Eigen::Vector3d(q.x[0], q.x[1], q.x[2]), t, targets);
          pairs[chunk] += sums.pairs;
        }
      }
    }
  });

  if (normalize) {
    // Per-scan-point normalisation: p_st / sum_t p_st over the pairs found (a cell of
    // multiplicity c stands for c points with the same weights, so it divides the same way).
    Eigen::VectorXd sum = Eigen::VectorXd::Zero(m);
    for (const ChunkPairs& chunk : chunks) {
      for (size_t i = 0; i < chunk.s.size(); ++i) sum[chunk.s[i]] += chunk.p[i];
    }
    // sum counts every member of a cell: per member the sum is sum / count.
    const Eigen::VectorXd inv_sum =
        (sum.array() > 0.0).select(cloud.count.array() / sum.array(), 0.0);
    // Pass 2: P_t, mu_t, c_t.
    ForRange(num_chunks, 1, options_.parallel, [&](int chunk_begin, int chunk_end) {
      for (int chunk = chunk_begin; chunk < chunk_end; ++chunk) {
        const ChunkPairs& in = chunks[chunk];
        const int t0 = chunk * grain, t1 = std::min(t_count, t0 + grain);
        for (int t = t0; t < t1; ++t) {
          const Eigen::Vector3d x = posed.vertices->row(t).transpose();
          VertexSums sums;
          for (int i = in.offset[t - t0]; i < in.offset[t - t0 + 1]; ++i) {
            const int s = in.s[i];
            const double p = in.p[i] * inv_sum[s];
            const double* q = packed + kP * s;
            const Eigen::Vector3d d(q[0] - x[0], q[1] - x[1], q[2] - x[2]);
            sums.Add(p, d, d.squaredNorm());
          }
          constants[chunk] += Finish(sums, x, t, targets);
          pairs[chunk] += sums.pairs;
        }
      }
    });
  }
  for (int chunk = 0; chunk < num_chunks; ++chunk) {
    targets->constant += constants[chunk];
    targets->num_pairs += pairs[chunk];
    neighbor_queries_ += queries[chunk];
    candidates_visited_ += visited[chunk];
  }
}

void EStep::FindNearest(const PosedTemplateView& posed, const OneToOneOptions& options,
                        NearestTargets* targets) const {
  CheckPosed(posed, "nearest-neighbour search");
  std::string error;
  if (!options.IsValid(&error)) throw Error("one-to-one options: " + error);
  const int t_count = static_cast<int>(posed.vertices->rows());
  targets->weight.setZero(t_count);
  targets->point.setZero(t_count, 3);
  targets->normal.setZero(t_count, 3);
  targets->index.setConstant(t_count, -1);
  const double max_d2 = options.max_distance * options.max_distance;
  const Cloud& full = FullCloud();
  ForRange(t_count, options_.grain_size, options_.parallel, [&](int begin, int end) {
    for (int t = begin; t < end; ++t) {
      double d2 = 0.0;
      const int s = full.index->Nearest(posed.vertices->row(t).transpose(), &d2);
      if (s < 0 || d2 > max_d2) continue;
      if (scan_.normals.row(s).dot(posed.normals->row(t)) < options.min_normal_dot) continue;
      targets->weight[t] = 1.0;
      targets->point.row(t) = scan_.points.row(s);
      targets->normal.row(t) = scan_.normals.row(s);
      targets->index[t] = s;
    }
  });
  targets->num_matched = static_cast<int>((targets->weight.array() > 0.0).count());
}

}  // namespace artex
