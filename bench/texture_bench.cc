// On-the-fly texturing (docs/design.md "Texture", paper sec. 4) on realistic inputs: the default
// template (GenerateTemplate(), ~12.5k vertices, ~25k triangles) posed by a walk
// (GenerateMotion + Skinning), seen by the virtual Kinect's colour camera (800 x 1016, 2.5 m in
// front; procedural subject texture, Lambert shading, exposure drift, sensor noise, floor and
// wall behind), textured into a 2048^2 atlas.
//
// BM_AddFrame/<switch cost>/<surface aware>/<sweeps>: the texturer is warmed up with
//   kWarmupFrames frames, then every iteration is one incremental AddFrame (visibility, pool, MRF
//   with warm start, resampling of the changed triangles, levelling) on the next frame.
//   Counters: medians over the timed frames of the wall time, of the process CPU time (all
//   threads) and of each stage (stages after the MRF run concurrently); changed triangles
//   (median, max; how many moved to the newest image or lost theirs to pruning), seam edges per
//   frame, and the energy the configured sweeps leave.
// BM_ViewSelection/<solver>: the MRF of one frame (pool after kWarmupFrames + 1 images, warm start
//   and Psi from the previous frame's labelling) built and solved by SelectViews with each
//   solver: energy, TRW-S lower bound, iterations, solve time.
// BM_ExpansionSweeps/<n>: the same with alpha-expansion limited to n sweeps.
// BM_CandidateLimit/<max_candidates>/<max_sweeps>: the same with at most max_candidates images
//   per triangle (0: all); energies compare across the limits.
// BM_LevelSeams: seam levelling of one labelling.
// BM_ComposeAtlas: Texturer::Atlas, the texture as a 2D image (seams levelled already).
// BM_LevelFactor/ldlt_factor:<0|1>: levelling's factorisation and solve, SimplicialLDLT's or
//   the leveller's own (the same arithmetic).
// Median figures: --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>
#include <time.h>

#include <Eigen/OrderingMethods>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

#include "bench/walk_sequence.h"
#include "energies/texture_terms.h"
#include "solvers/seam_levelling.h"
#include "texture/texturer.h"

namespace artex {
namespace {

constexpr int kWarmupFrames = 10;
constexpr int kTimedFrames = 30;
constexpr int kAtlasSize = 2048;

using bench::Median;
using bench::ProcessCpuSeconds;
using Sequence = bench::WalkSequence;

const Sequence& Walk() { return bench::Walk(kWarmupFrames + kTimedFrames + 1); }

TexturingOptions BenchOptions() {
  TexturingOptions o;
  o.atlas_size = kAtlasSize;
  return o;
}

void BM_AddFrame(benchmark::State& state) {
  const Sequence& seq = Walk();
  TexturingOptions options = BenchOptions();
  options.selection.terms.switch_cost = 1e-3 * static_cast<double>(state.range(0));
  if (state.range(1) == 0) {  // plain bilinear sampling, as without the z-buffer
    options.pool.surface_aware_sampling = false;
    options.pool.vertex_colors_need_full_ring = false;
  }
  if (state.range(2) > 0) options.mrf.max_iterations = static_cast<int>(state.range(2));
  Texturer texturer(seq.body, options);
  for (int f = 0; f < kWarmupFrames; ++f)
    texturer.AddFrame(f, seq.color[f], seq.camera, seq.posed[f]);
  // The same view-selection problem solved to convergence (outside the timing): how much energy
  // the configured number of sweeps leaves per frame.
  MrfSolverOptions converged_options = options.mrf;
  converged_options.max_iterations = 50;
  const std::unique_ptr<MrfSolver> converged = MrfSolver::Create(converged_options);
  std::vector<double> wall, cpu, pool, mrf, sampling, levelling, changed, seams, pool_size;
  std::vector<double> to_newest, from_dropped, textured, energy_gap;
  uint64_t labels_hash = 1469598103934665603ull;  // FNV-1a over every frame's labels
  int frame = kWarmupFrames;
  for (auto _ : state) {
    const std::vector<int> before = texturer.triangle_frames();
    const std::vector<double> seam_distance_before = texturer.seam_distance();
    const double cpu0 = ProcessCpuSeconds();
    const auto t0 = std::chrono::steady_clock::now();
    const TextureFrameSummary s =
        texturer.AddFrame(frame, seq.color[frame], seq.camera, seq.posed[frame]);
    wall.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    cpu.push_back(ProcessCpuSeconds() - cpu0);
    pool.push_back(s.seconds_pool);
    mrf.push_back(s.seconds_mrf);
    sampling.push_back(s.seconds_sampling);
    levelling.push_back(s.seconds_levelling);
    changed.push_back(s.changed_triangles);
    seams.push_back(s.seam_edges);
    pool_size.push_back(s.pool_size);
    textured.push_back(s.textured_triangles);
    // Why triangles changed: they moved to the newest image, or their image left the pool.
    int newest = 0, dropped = 0;
    for (int f : texturer.last_changed_triangles()) {
      newest += texturer.triangle_frames()[f] == frame;
      dropped += before[f] >= 0 && texturer.pool().SlotOfFrame(before[f]) < 0;
    }
    for (int l : texturer.triangle_frames())
      labels_hash = (labels_hash ^ static_cast<uint64_t>(l + 1)) * 1099511628211ull;
    to_newest.push_back(newest);
    from_dropped.push_back(dropped);
    state.PauseTiming();
    ViewSelectionInput input;
    input.mesh = &texturer.mesh();
    input.pool = &texturer.pool();  // pruned before the selection, so the pool it used
    input.current_frame = frame;
    input.previous_frames = before;
    input.seam_distance = seam_distance_before;
    input.edge_weight = texturer.edge_weight();
    const double best = SelectViews(input, options.selection, converged.get()).mrf.energy;
    energy_gap.push_back((s.energy - best) / std::abs(best));
    state.ResumeTiming();
    ++frame;
  }
  state.counters["median_ms"] = 1e3 * Median(wall);
  state.counters["median_cpu_ms"] = 1e3 * Median(cpu);
  state.counters["pool_ms"] = 1e3 * Median(pool);
  state.counters["mrf_ms"] = 1e3 * Median(mrf);
  state.counters["sampling_ms"] = 1e3 * Median(sampling);
  state.counters["levelling_ms"] = 1e3 * Median(levelling);
  state.counters["changed_tris"] = Median(changed);
  state.counters["changed_max"] = *std::max_element(changed.begin(), changed.end());
  state.counters["max_ms"] = 1e3 * *std::max_element(wall.begin(), wall.end());
  state.counters["seam_edges"] = Median(seams);
  state.counters["pool_size"] = Median(pool_size);
  state.counters["textured_tris"] = Median(textured);
  state.counters["changed_to_newest"] = Median(to_newest);
  state.counters["changed_from_dropped"] = Median(from_dropped);
  state.counters["energy_gap"] = Median(energy_gap);
  state.counters["energy_gap_max"] = *std::max_element(energy_gap.begin(), energy_gap.end());
  // Identifies the sequence of labellings (equal hashes: identical view selection).
  state.counters["labels_hash"] = static_cast<double>(labels_hash % 1000000007ull);
}
// Arguments: TextureTermOptions::switch_cost in thousandths (0: the paper's energy; 20: the
// default); surface-aware sampling (1: default, 0: plain bilinear sampling and vertex colours
// wherever a triangle around the vertex is visible); alpha-expansion sweeps per frame (0: the
// default, one; 50: converge every frame). energy_gap: median (max) over the frames of (E - E*) /
// E*, E* the energy of the same frame's problem solved to convergence from the same warm start.
BENCHMARK(BM_AddFrame)
    ->ArgNames({"switch_cost_x1000", "surface_aware", "sweeps"})
    ->Args({0, 1, 0})
    ->Args({0, 1, 50})
    ->Args({0, 0, 0})
    ->Args({20, 1, 0})
    ->Iterations(kTimedFrames)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// The view-selection input of frame kWarmupFrames + 1 for any solver.
struct SelectionSetup {
  std::unique_ptr<TextureMesh> mesh;
  std::unique_ptr<ImagePool> pool;
  ViewSelectionInput input;
};

const SelectionSetup& Selection() {
  static const SelectionSetup setup = [] {
    const Sequence& seq = Walk();
    const TexturingOptions options = BenchOptions();
    Texturer texturer(seq.body, options);
    for (int f = 0; f < kWarmupFrames; ++f)
      texturer.AddFrame(f, seq.color[f], seq.camera, seq.posed[f]);
    SelectionSetup s;
    s.mesh = std::make_unique<TextureMesh>(texturer.mesh());
    s.pool = std::make_unique<ImagePool>(s.mesh.get(), options.pool, options.visibility);
    for (int f = 0; f <= kWarmupFrames; ++f) {
      s.pool->Add(f, seq.color[f], seq.camera, seq.posed[f]);
      s.pool->Prune();
    }
    s.input.mesh = s.mesh.get();
    s.input.pool = s.pool.get();
    s.input.current_frame = kWarmupFrames;
    s.input.previous_frames = texturer.triangle_frames();
    s.input.seam_distance = texturer.seam_distance();
    s.input.edge_weight = texturer.edge_weight();
    return s;
  }();
  return setup;
}

// SelectViews on the Selection() input with a solver made from `mrf`, once per iteration: the
// last result, and the median solve time (s) in *solve_seconds. Sets the counter build_ms: the
// median of the rest of SelectViews' time (candidates, tables, the MRF problem).
ViewSelectionResult TimeSelection(
    benchmark::State& state, const MrfSolverOptions& mrf, double* solve_seconds,
    const ViewSelectionOptions& selection = BenchOptions().selection) {
  const SelectionSetup& setup = Selection();
  const std::unique_ptr<MrfSolver> solver = MrfSolver::Create(mrf);
  ViewSelectionResult result;
  std::vector<double> seconds, build_seconds;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    result = SelectViews(setup.input, selection, solver.get());
    const double total =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    seconds.push_back(result.mrf.seconds);
    build_seconds.push_back(total - result.mrf.seconds);
  }
  *solve_seconds = Median(seconds);
  state.counters["build_ms"] = 1e3 * Median(build_seconds);
  return result;
}

void BM_ViewSelection(benchmark::State& state) {
  const SelectionSetup& setup = Selection();
  MrfSolverOptions mrf = BenchOptions().mrf;
  mrf.type = static_cast<MrfSolverType>(state.range(0));
  mrf.max_iterations = 50;  // every solver to convergence (texturing's default is one sweep)
  state.SetLabel(MrfSolverTypeToString(mrf.type));
  double solve_seconds = 0.0;
  const ViewSelectionResult result = TimeSelection(state, mrf, &solve_seconds);
  int changed = 0;
  for (std::size_t f = 0; f < result.frames.size(); ++f)
    changed += result.frames[f] != setup.input.previous_frames[f];
  state.counters["energy"] = result.mrf.energy;
  state.counters["initial_energy"] = result.mrf.initial_energy;
  state.counters["lower_bound"] =
      std::isfinite(result.mrf.lower_bound) ? result.mrf.lower_bound : 0.0;
  state.counters["iterations"] = result.mrf.iterations;
  state.counters["solve_ms"] = 1e3 * solve_seconds;
  state.counters["changed_tris"] = changed;
  state.counters["candidates"] = result.num_candidates;
}
BENCHMARK(BM_ViewSelection)
    ->DenseRange(0, 3)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.5);

// Alpha-expansion on the same problem with at most state.range(0) sweeps.
void BM_ExpansionSweeps(benchmark::State& state) {
  MrfSolverOptions mrf = BenchOptions().mrf;
  mrf.max_iterations = static_cast<int>(state.range(0));
  double solve_seconds = 0.0;
  const ViewSelectionResult result = TimeSelection(state, mrf, &solve_seconds);
  state.counters["energy"] = result.mrf.energy;
  state.counters["initial_energy"] = result.mrf.initial_energy;
  state.counters["solve_ms"] = 1e3 * solve_seconds;
}
BENCHMARK(BM_ExpansionSweeps)
    ->ArgName("max_sweeps")
    ->Arg(1)
    ->Arg(2)
    ->Arg(50)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.5);

// The same problem with at most state.range(0) candidate images per triangle (0: every visible
// image), alpha-expansion with at most state.range(1) sweeps. Energies compare across the limits:
// a labelling's energy does not depend on the candidates it did not choose.
void BM_CandidateLimit(benchmark::State& state) {
  MrfSolverOptions mrf = BenchOptions().mrf;
  mrf.max_iterations = static_cast<int>(state.range(1));
  ViewSelectionOptions selection = BenchOptions().selection;
  selection.max_candidates = static_cast<int>(state.range(0));
  double solve_seconds = 0.0;
  const ViewSelectionResult result = TimeSelection(state, mrf, &solve_seconds, selection);
  state.counters["energy"] = result.mrf.energy;
  state.counters["candidates"] = result.num_candidates;
  state.counters["solve_ms"] = 1e3 * solve_seconds;
}
BENCHMARK(BM_CandidateLimit)
    ->ArgNames({"max_candidates", "max_sweeps"})
    ->ArgsProduct({{0, 2, 3, 4, 6}, {1, 50}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(0.5);

// Seam levelling of one frame's labelling (the texturer's state after kWarmupFrames frames), by
// a SeamLeveller made once for the mesh.
void BM_LevelSeams(benchmark::State& state) {
  const Sequence& seq = Walk();
  Texturer texturer(seq.body, BenchOptions());
  for (int f = 0; f < kWarmupFrames; ++f)
    texturer.AddFrame(f, seq.color[f], seq.camera, seq.posed[f]);
  const ImagePool& pool = texturer.pool();
  const auto colour = [&pool](int v, int frame_index, Eigen::Vector3f* c) {
    const int slot = pool.SlotOfFrame(frame_index);
    if (slot < 0 || !pool.entry(slot).vertex_colors.row(v).allFinite()) return false;
    *c = pool.entry(slot).vertex_colors.row(v).transpose();
    return true;
  };
  Eigen::MatrixX3f corrections;
  SeamLevellingSummary summary;
  SeamLeveller leveller(seq.body.num_vertices(), seq.body.triangles, BenchOptions().levelling);
  for (auto _ : state) leveller.Level(texturer.triangle_frames(), colour, &corrections, &summary);
  state.counters["unknowns"] = summary.unknowns;
  state.counters["seam_equations"] = summary.seam_equations;
  state.counters["rms_before"] = summary.seam_residual_before;
  state.counters["rms_after"] = summary.seam_residual_after;
}
BENCHMARK(BM_LevelSeams)->Unit(benchmark::kMillisecond)->MinTime(1.0);

// The texture as an image (Texturer::Atlas after kWarmupFrames frames, its seams levelled once
// before the timing): the texels scattered into the atlas, the padding grown around the
// charts, the conversion to 8 bits. What an atlas snapshot (texture quality, --export-atlases,
// the stream) costs.
void BM_ComposeAtlas(benchmark::State& state) {
  const Sequence& seq = Walk();
  Texturer texturer(seq.body, BenchOptions());
  for (int f = 0; f < kWarmupFrames; ++f)
    texturer.AddFrame(f, seq.color[f], seq.camera, seq.posed[f]);
  cv::Mat atlas = texturer.Atlas();
  for (auto _ : state) {
    atlas = texturer.Atlas();
    benchmark::DoNotOptimize(atlas.data);
  }
  state.counters["atlas_size"] = atlas.cols;
}
BENCHMARK(BM_ComposeAtlas)->Unit(benchmark::kMillisecond)->MinTime(1.0);

// BM_LevelFactor/ldlt_factor:<0|1>: seam levelling's factorisation and three-channel solve on
// the normal equations of one label over the whole body (its vertex graph with the default
// smoothness and regularisation, in AMD order, upper triangle): SimplicialLDLT with natural
// order on Eigen::Index indices and its solve (0, as Level did), or the leveller's LdltFactor
// (1: int indices, buffers kept across iterations, one pass per substitution for the three
// channels); the same solution bit for bit. Counter: the factor's nonzeros.
void BM_LevelFactor(benchmark::State& state) {
  using seam_levelling_internal::Rows3;
  using SparseMatrix = Eigen::SparseMatrix<double, Eigen::ColMajor, Eigen::Index>;
  const Template& body = Walk().body;
  const SeamLevellingOptions options;
  const int n = body.num_vertices();
  std::vector<Eigen::Triplet<double, Eigen::Index>> entries;
  for (int v = 0; v < n; ++v) entries.emplace_back(v, v, options.regularisation);
  for (int f = 0; f < body.num_triangles(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const int a = body.triangles(f, c), b = body.triangles(f, (c + 1) % 3);
      entries.emplace_back(a, a, options.smoothness);
      entries.emplace_back(b, b, options.smoothness);
      entries.emplace_back(std::min(a, b), std::max(a, b), -options.smoothness);
    }
  }
  SparseMatrix upper(n, n);
  upper.setFromTriplets(entries.begin(), entries.end());
  Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, Eigen::Index> order;
  Eigen::AMDOrdering<Eigen::Index>()(upper.selfadjointView<Eigen::Upper>(), order);
  SparseMatrix ordered(n, n);
  ordered.selfadjointView<Eigen::Upper>() =
      upper.selfadjointView<Eigen::Upper>().twistedBy(order.inverse());
  const std::vector<int> outer(ordered.outerIndexPtr(), ordered.outerIndexPtr() + n + 1);
  const std::vector<int> inner(ordered.innerIndexPtr(),
                               ordered.innerIndexPtr() + ordered.nonZeros());
  Rows3 b(n, 3);
  for (int v = 0; v < n; ++v) b.row(v) << std::sin(0.1 * v), std::cos(0.07 * v), 0.01 * (v % 17);
  const Eigen::MatrixX3d b_columns = b;
  seam_levelling_internal::LdltFactor factor;
  Rows3 x(n, 3);
  Eigen::Index factor_nonzeros = 0;
  for (auto _ : state) {
    if (state.range(0) == 0) {
      Eigen::SimplicialLDLT<SparseMatrix, Eigen::Upper, Eigen::NaturalOrdering<Eigen::Index>>
          solver(ordered);
      const Eigen::MatrixX3d solution = solver.solve(b_columns);
      benchmark::DoNotOptimize(solution.data());
      factor_nonzeros = solver.matrixL().nestedExpression().nonZeros();
    } else {
      if (!factor.Factorize(n, outer.data(), inner.data(), ordered.valuePtr()))
        state.SkipWithError("zero pivot");
      x = b;
      factor.Solve3(&x);
      benchmark::DoNotOptimize(x.data());
      factor_nonzeros = static_cast<Eigen::Index>(factor.l_value().size());
    }
  }
  state.counters["factor_nonzeros"] = static_cast<double>(factor_nonzeros);
}
BENCHMARK(BM_LevelFactor)->ArgName("ldlt_factor")->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// BM_ResampleTriangles/surface_aware:<0|1>: SampleTriangle over every triangle visible in one
// pooled image (frame kWarmupFrames of the walk, 2048^2 atlas), on one thread. Counters: median
// thread CPU time per texel over the iterations, texels, written texels, triangles.
double ThreadCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

void BM_ResampleTriangles(benchmark::State& state) {
  const Sequence& seq = Walk();
  ImagePoolOptions pool_options;
  pool_options.surface_aware_sampling = state.range(0) != 0;
  const TextureMesh mesh = TextureMesh::Build(seq.body.triangles);
  ImagePool pool(&mesh, pool_options, VisibilityOptions());
  const PoolEntry& entry = pool.entry(
      pool.Add(kWarmupFrames, seq.color[kWarmupFrames], seq.camera, seq.posed[kWarmupFrames]));
  const AtlasMap map(seq.body, kAtlasSize);
  TexelBuffer texels(map);
  std::vector<int> visible;
  int texel_count = 0;
  for (int f = 0; f < map.num_triangles(); ++f) {
    if (!entry.visibility.visible[f]) continue;
    visible.push_back(f);
    texel_count += map.last(f) - map.first(f);
  }
  std::vector<double> cpu;
  int written = 0;
  for (auto _ : state) {
    const double t0 = ThreadCpuSeconds();
    written = 0;
    for (int f : visible) written += SampleTriangle(map, f, seq.body.triangles, entry, &texels);
    cpu.push_back(ThreadCpuSeconds() - t0);
    benchmark::DoNotOptimize(texels.color.data());
  }
  state.counters["ns_per_texel"] = 1e9 * Median(cpu) / std::max(texel_count, 1);
  state.counters["texels"] = texel_count;
  state.counters["written"] = written;
  state.counters["triangles"] = static_cast<double>(visible.size());
}
BENCHMARK(BM_ResampleTriangles)
    ->ArgName("surface_aware")
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->MinTime(1.0);

}  // namespace
}  // namespace artex
