// The output stage's vertex error against the truth (experiments/surface_error.h): one
// frame's SurfaceErrors, the default template (11,897 vertices) posed by a random pose against
// itself posed by another about 1 cm off (a tracked frame against its truth). Counter: cpu_ms
// (process CPU per call). For one core run under `taskset -c 0`.
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <random>
#include <vector>

#include "experiments/surface_error.h"
#include "models/normals.h"
#include "models/skinning.h"
#include "models/template_generator.h"
#include "tests/solvers/fitting_test_util.h"

namespace artex {
namespace {

double ProcessCpuSeconds() {
  rusage usage;
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_utime.tv_sec + usage.ru_stime.tv_sec +
         1e-6 * (usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
}

// Each of `pose`'s parameters moved by N(0, sigma): the tracked pose to `pose` as the truth.
Eigen::VectorXd Perturbation(const Pose& pose, double sigma, std::mt19937_64* rng) {
  Eigen::VectorXd d(pose.num_parameters());
  std::normal_distribution<double> g(0.0, sigma);
  for (int i = 0; i < d.size(); ++i) d[i] = g(*rng);
  return d;
}

// The template posed by `pose` as a truth: its vertices and their normals.
void TrueSurface(const Skinning& skinning, const Pose& pose, Eigen::MatrixX3d* vertices,
                 Eigen::MatrixX3d* normals) {
  skinning.Apply(pose, vertices);
  ComputeVertexNormals(*vertices, skinning.model().triangles, normals);
}

void BM_SurfaceErrors(benchmark::State& state) {
  const Template model = GenerateTemplate(BodyShapeOptions());
  const Skinning skinning(model);
  std::mt19937_64 rng(2014);
  const Pose truth = testing_util::RandomPose(model.num_joints(), 0.25, 0.15, 0.05, &rng);
  const Eigen::VectorXd d = Perturbation(truth, 0.02, &rng);
  Eigen::MatrixX3d tracked, true_vertices, true_normals;
  skinning.Apply(truth.Retracted(d), &tracked);
  TrueSurface(skinning, truth, &true_vertices, &true_normals);
  double mean = 0.0, max = 0.0;
  const double cpu_start = ProcessCpuSeconds();
  for (auto _ : state) {
    SurfaceErrors(tracked, true_vertices, true_normals, &mean, &max);
    benchmark::DoNotOptimize(mean);
  }
  state.counters["cpu_ms"] =
      1e3 * (ProcessCpuSeconds() - cpu_start) / static_cast<double>(state.iterations());
  state.counters["mean_mm"] = 1e3 * mean;
  state.counters["vertices"] = static_cast<double>(tracked.rows());
}
BENCHMARK(BM_SurfaceErrors)->Unit(benchmark::kMillisecond)->UseRealTime();

// A frame of tracking: the truth moves on by a small step from the frame before (its pose
// retracted by 0.01 per parameter), the tracked vertices follow it within about a centimetre.
// Arg 0: SurfaceErrors without a guess; 1: with the frame before's nearest vertices as the
// guess, as the ground-truth evaluation calls it (the same errors bit for bit; counter
// same_errors).
void BM_SurfaceErrorsNextFrame(benchmark::State& state) {
  const bool guess = state.range(0) != 0;
  const Template model = GenerateTemplate(BodyShapeOptions());
  const Skinning skinning(model);
  std::mt19937_64 rng(2014);
  const Pose before = testing_util::RandomPose(model.num_joints(), 0.25, 0.15, 0.05, &rng);
  const Eigen::VectorXd step = Eigen::VectorXd::Constant(before.num_parameters(), 0.01);
  const Pose truth = before.Retracted(step);
  const Eigen::VectorXd d = Perturbation(truth, 0.005, &rng);
  Eigen::MatrixX3d tracked_before, tracked, before_vertices, before_normals;
  Eigen::MatrixX3d true_vertices, true_normals;
  skinning.Apply(before.Retracted(d), &tracked_before);
  skinning.Apply(truth.Retracted(d), &tracked);
  TrueSurface(skinning, before, &before_vertices, &before_normals);
  TrueSurface(skinning, truth, &true_vertices, &true_normals);
  std::vector<int> previous;
  double mean = 0.0, max = 0.0;
  SurfaceErrors(tracked_before, before_vertices, before_normals, &mean, &max, &previous);
  double plain_mean = 0.0, plain_max = 0.0;
  SurfaceErrors(tracked, true_vertices, true_normals, &plain_mean, &plain_max);
  std::vector<int> nearest;
  const double cpu_start = ProcessCpuSeconds();
  for (auto _ : state) {
    if (guess) {
      nearest = previous;
      SurfaceErrors(tracked, true_vertices, true_normals, &mean, &max, &nearest);
    } else {
      SurfaceErrors(tracked, true_vertices, true_normals, &mean, &max);
    }
    benchmark::DoNotOptimize(mean);
  }
  state.counters["cpu_ms"] =
      1e3 * (ProcessCpuSeconds() - cpu_start) / static_cast<double>(state.iterations());
  state.counters["mean_mm"] = 1e3 * mean;
  state.counters["same_errors"] = mean == plain_mean && max == plain_max;
}
BENCHMARK(BM_SurfaceErrorsNextFrame)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace artex
