// The image pool stage of on-the-fly texturing (docs/design.md "Texture", paper sec. 4) on realistic
// inputs: the default template posed by a walk (GenerateMotion + Skinning) and seen by the
// virtual Kinect's colour camera (800 x 1016), as in texture_bench.
//
// BM_PoolAddPrune/surface_aware: the pool is warmed up with kWarmupFrames frames, then every
//   iteration adds the next frame's image (ImagePool::Add: visibility z-buffer, crop, vertex and
//   edge colours) and prunes (ImagePool::Prune). Counters: medians over the timed frames of the
//   wall and process CPU time (all threads) of Add, of Prune and of both; the pool size; and a
//   hash of every added entry's visibility, z-buffer, crop, colours and of the dropped frames
//   (equal hashes: identical results).
// Median figures: --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <vector>

#include "bench/walk_sequence.h"
#include "texture/image_pool.h"

namespace artex {
namespace {

constexpr int kWarmupFrames = 10;
constexpr int kTimedFrames = 30;

using bench::Median;
using bench::ProcessCpuSeconds;
using Sequence = bench::WalkSequence;

const Sequence& Walk() { return bench::Walk(kWarmupFrames + kTimedFrames); }

// FNV-1a over raw bytes.
void Hash(const void* data, std::size_t bytes, uint64_t* hash) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < bytes; ++i) *hash = (*hash ^ p[i]) * 1099511628211ull;
}

void HashEntry(const PoolEntry& e, uint64_t* hash) {
  Hash(e.visibility.visible.data(), e.visibility.visible.size(), hash);
  Hash(e.visibility.quality.data(), e.visibility.quality.size() * sizeof(float), hash);
  Hash(e.surface.depth.data(), e.surface.depth.size() * sizeof(float), hash);
  Hash(e.offset.data(), sizeof(int) * 2, hash);
  const int size[2] = {e.image.cols, e.image.rows};
  Hash(size, sizeof(size), hash);
  // NaN payloads may differ between equal results: hash NaN as one value.
  const auto hash_colors = [hash](const ColorRows& c) {
    for (Eigen::Index i = 0; i < c.size(); ++i) {
      const float x = std::isnan(c.data()[i]) ? -1.0f : c.data()[i];
      Hash(&x, sizeof(x), hash);
    }
  };
  hash_colors(e.vertex_colors);
  Hash(e.edge_colors.data(), e.edge_colors.size() * sizeof(std::uint16_t), hash);
}

void BM_PoolAddPrune(benchmark::State& state) {
  const Sequence& seq = Walk();
  const TextureMesh mesh = TextureMesh::Build(seq.body.triangles);
  ImagePoolOptions pool_options;
  if (state.range(0) == 0) {  // plain bilinear sampling, as without the z-buffer
    pool_options.surface_aware_sampling = false;
    pool_options.vertex_colors_need_full_ring = false;
  }
  ImagePool pool(&mesh, pool_options, VisibilityOptions());
  for (int f = 0; f < kWarmupFrames; ++f) {
    pool.Add(f, seq.color[f], seq.camera, seq.posed[f]);
    pool.Prune();
  }
  std::vector<double> add_wall, add_cpu, prune_wall, prune_cpu, wall, cpu, pool_size;
  uint64_t hash = 1469598103934665603ull;
  int frame = kWarmupFrames;
  for (auto _ : state) {
    const double cpu0 = ProcessCpuSeconds();
    const auto t0 = std::chrono::steady_clock::now();
    const int slot = pool.Add(frame, seq.color[frame], seq.camera, seq.posed[frame]);
    const double cpu1 = ProcessCpuSeconds();
    const auto t1 = std::chrono::steady_clock::now();
    HashEntry(pool.entry(slot), &hash);  // outside the timed spans
    const double cpu1b = ProcessCpuSeconds();
    const auto t1b = std::chrono::steady_clock::now();
    const std::vector<int> dropped = pool.Prune();
    const double cpu2 = ProcessCpuSeconds();
    const auto t2 = std::chrono::steady_clock::now();
    add_wall.push_back(std::chrono::duration<double>(t1 - t0).count());
    prune_wall.push_back(std::chrono::duration<double>(t2 - t1b).count());
    wall.push_back(add_wall.back() + prune_wall.back());
    add_cpu.push_back(cpu1 - cpu0);
    prune_cpu.push_back(cpu2 - cpu1b);
    cpu.push_back(add_cpu.back() + prune_cpu.back());
    pool_size.push_back(pool.size());
    Hash(dropped.data(), dropped.size() * sizeof(int), &hash);
    ++frame;
  }
  state.counters["median_ms"] = 1e3 * Median(wall);
  state.counters["median_cpu_ms"] = 1e3 * Median(cpu);
  state.counters["add_ms"] = 1e3 * Median(add_wall);
  state.counters["add_cpu_ms"] = 1e3 * Median(add_cpu);
  state.counters["prune_ms"] = 1e3 * Median(prune_wall);
  state.counters["prune_cpu_ms"] = 1e3 * Median(prune_cpu);
  state.counters["pool_size"] = Median(pool_size);
  // Identifies the entries and pruning decisions (equal hashes: identical results).
  state.counters["result_hash"] = static_cast<double>(hash % 1000000007ull);
}
BENCHMARK(BM_PoolAddPrune)
    ->ArgName("surface_aware")
    ->Arg(1)
    ->Arg(0)
    ->Iterations(kTimedFrames)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace artex
