// The output stage's vertex error against the truth (experiments/surface_error.h): one
// frame's SurfaceErrors, the default template (11,897 vertices) posed by a random pose against
// itself posed by another about 1 cm off (a tracked frame against its truth). Counter: cpu_ms
// (process CPU per call). For one core run under `taskset -c 0`.
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <random>

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

void BM_SurfaceErrors(benchmark::State& state) {
  const Template model = GenerateTemplate(BodyShapeOptions());
  const Skinning skinning(model);
  std::mt19937_64 rng(2014);
  const Pose truth = testing_util::RandomPose(model.num_joints(), 0.25, 0.15, 0.05, &rng);
  Eigen::VectorXd d = Eigen::VectorXd::Zero(truth.num_parameters());
  std::normal_distribution<double> g(0.0, 0.02);
  for (int i = 0; i < d.size(); ++i) d[i] = g(rng);
  Eigen::MatrixX3d tracked, true_vertices, true_normals;
  skinning.Apply(truth.Retracted(d), &tracked);
  skinning.Apply(truth, &true_vertices);
  ComputeVertexNormals(true_vertices, model.triangles, &true_normals);
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

}  // namespace
}  // namespace artex
