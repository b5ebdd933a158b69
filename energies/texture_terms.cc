#include "energies/texture_terms.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <queue>
#include <sstream>
#include <utility>

namespace artex {

bool TextureTermOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (!(beta >= 0.0 && beta <= 1.0))
    msg << "texture.beta: expected [0, 1], found " << beta;
  else if (!(t_max > 0.0))
    msg << "texture.t_max: expected > 0, found " << t_max;
  else if (!(alpha >= 0.0 && alpha <= 1.0))
    msg << "texture.alpha: expected [0, 1], found " << alpha;
  else if (!(lambda >= 0.0) || !std::isfinite(lambda))
    msg << "texture.lambda: expected a finite value >= 0, found " << lambda;
  else if (!(seam_distance_scale > 0.0))
    msg << "texture.seam_distance_scale: expected > 0, found " << seam_distance_scale;
  else if (!(min_quality >= 0.0 && min_quality < 1.0))
    msg << "texture.min_quality: expected [0, 1), found " << min_quality;
  else if (!(switch_cost >= 0.0) || !std::isfinite(switch_cost))
    msg << "texture.switch_cost: expected a finite value >= 0, found " << switch_cost;
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

double TriangleQuality(const Eigen::Vector3d& normal, const Eigen::Vector3d& view_direction) {
  return std::max(0.0, -normal.dot(view_direction));
}

std::vector<double> MeshDistanceField(const Eigen::MatrixX3d& vertices,
                                      const Eigen::MatrixX3i& triangles,
                                      const std::vector<int>& sources) {
  if (sources.empty())
    return std::vector<double>(vertices.rows(), std::numeric_limits<double>::infinity());
  return MeshGeodesics(vertices, triangles).DistanceField(sources);
}

MeshGeodesics::MeshGeodesics(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles) {
  const int n = static_cast<int>(vertices.rows());
  // Vertex adjacency (CSR) from the triangles, duplicates removed.
  std::vector<int> degree(n + 1, 0);
  for (int f = 0; f < triangles.rows(); ++f)
    for (int c = 0; c < 3; ++c) degree[triangles(f, c) + 1] += 2;
  for (int i = 0; i < n; ++i) degree[i + 1] += degree[i];
  std::vector<int> adjacency(degree[n]);
  std::vector<int> fill(degree.begin(), degree.end() - 1);
  for (int f = 0; f < triangles.rows(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const int a = triangles(f, c);
      adjacency[fill[a]++] = triangles(f, (c + 1) % 3);
      adjacency[fill[a]++] = triangles(f, (c + 2) % 3);
    }
  }
  offsets_.assign(n + 1, 0);
  neighbours_.reserve(adjacency.size() / 2);
  for (int v = 0; v < n; ++v) {
    std::sort(adjacency.begin() + degree[v], adjacency.begin() + degree[v + 1]);
    const auto end = std::unique(adjacency.begin() + degree[v], adjacency.begin() + degree[v + 1]);
    for (auto it = adjacency.begin() + degree[v]; it != end; ++it) {
      neighbours_.push_back(*it);
      lengths_.push_back((vertices.row(*it) - vertices.row(v)).norm());
      max_edge_length_ = std::max(max_edge_length_, lengths_.back());
      min_edge_length_ = std::min(min_edge_length_, lengths_.back());
    }
    offsets_[v + 1] = static_cast<int>(neighbours_.size());
  }
}

std::vector<double> MeshGeodesics::DistanceField(const std::vector<int>& sources,
                                                 double max_distance) const {
  // Bounded searches run over buckets of distance (Dial's algorithm) of width half the shortest
  // edge: a relaxation then moves at least one bucket on even with rounding, so every vertex of
  // the lowest non-empty bucket has its final distance, and each distance is the same minimum
  // over the neighbours' final distances plus the edge lengths as Dijkstra's (bit for bit).
  // Relaxations reach at most max_edge / width + 1 buckets ahead: a ring of buckets suffices.
  constexpr double kMaxBuckets = 1 << 22;  // else (very short edges, far bounds) the heap
  constexpr double kMaxRing = 4096;
  const double width = 0.5 * min_edge_length_;
  if (!(width > 0.0) || !(max_distance / width < kMaxBuckets) ||
      !(max_edge_length_ / width + 2.0 < kMaxRing))
    return HeapDistanceField(sources, max_distance);
  const int n = num_vertices();
  std::vector<double> dist(n, std::numeric_limits<double>::infinity());
  const int ring_size = static_cast<int>(max_edge_length_ / width) + 2;
  std::vector<std::vector<int>> ring(ring_size);
  std::vector<uint8_t> done(n, 0);
  std::size_t pending = 0;
  for (int s : sources) {
    if (s >= 0 && s < n && dist[s] > 0.0) {
      dist[s] = 0.0;
      ring[0].push_back(s);
      ++pending;
    }
  }
  for (std::int64_t bucket = 0; pending > 0; ++bucket) {
    // Relaxations from this bucket land in later ones: the list does not change while read.
    std::vector<int>& list = ring[bucket % ring_size];
    pending -= list.size();
    for (const int v : list) {
      if (done[v]) continue;  // reached again at a larger distance
      done[v] = 1;
      const double d = dist[v];
      for (int k = offsets_[v]; k < offsets_[v + 1]; ++k) {
        const int u = neighbours_[k];
        const double nd = d + lengths_[k];
        if (nd < dist[u] && nd <= max_distance) {
          dist[u] = nd;
          ring[static_cast<std::int64_t>(nd / width) % ring_size].push_back(u);
          ++pending;
        }
      }
    }
    list.clear();
  }
  return dist;
}

std::vector<double> MeshGeodesics::HeapDistanceField(const std::vector<int>& sources,
                                                     double max_distance) const {
  const int n = num_vertices();
  std::vector<double> dist(n, std::numeric_limits<double>::infinity());
  using Item = std::pair<double, int>;
  std::vector<Item> heap;
  heap.reserve(static_cast<std::size_t>(n));
  const auto later = std::greater<Item>();
  for (int s : sources) {
    if (s >= 0 && s < n && dist[s] > 0.0) {
      dist[s] = 0.0;
      heap.push_back({0.0, s});
    }
  }
  std::make_heap(heap.begin(), heap.end(), later);
  while (!heap.empty()) {
    std::pop_heap(heap.begin(), heap.end(), later);
    const auto [d, v] = heap.back();
    heap.pop_back();
    if (d > dist[v]) continue;
    for (int k = offsets_[v]; k < offsets_[v + 1]; ++k) {
      const int u = neighbours_[k];
      const double nd = d + lengths_[k];
      if (nd < dist[u] && nd <= max_distance) {
        dist[u] = nd;
        heap.push_back({nd, u});
        std::push_heap(heap.begin(), heap.end(), later);
      }
    }
  }
  return dist;
}

}  // namespace artex
