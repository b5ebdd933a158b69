// The parts of one EM iteration of the tracking fit, separately (bench/fitting_bench.cc times
// whole frames). Fixture as fitting_bench's: the default template (resolution 1) with the
// 2000 fitted vertices of a tracking frame (EMFitterOptions().tracking_max_fit_vertices),
// posed by a random pose (joints ~0.25 rad), and a front scan of that surface of ~20k points
// with 4 mm noise along the ray; the E-step sees the template posed ~1 cm off (another random
// pose about the first).
//   BM_EStepVoxelCloud:  EStep construction + the voxel-subsampled cloud of the first tracking
//                        radius (a Compute with no template vertices builds only the cloud)
//   BM_EStepFirst:       EStep construction + the first E-step at that radius: cloud, candidate
//                        gathers of every vertex, weighing
//   BM_EStepReweigh:     a later E-step of the same frame (candidate lists kept): weighing only
//   BM_MStepJacobian:    posing the fitted vertices with their skinning Jacobian (one
//                        Gauss-Newton evaluation, PrepareFitEvaluation)
//   BM_MStepNormalEquations: the data term's J^T J and J^T r on that evaluation
//   BM_FittedNormals/<0|1>: a normal refresh of the fitted vertices: the whole template's
//                        normals (0) or only the fitted vertices' (1, ComputeVertexNormalsOf)
//   BM_IndexNearestBuild/<cell mm>: PointCloudIndex (its kd-tree; cell 0) or NearestGrid over
//                        the whole posed template (the ICP's and the scale sample's target),
//                        and one nearest-point query
//   BM_IndexNearestWithin/<cell mm>/<bound>: the ICP's queries into that index, 1500 scan
//                        points (a fixed stride), each bounded by the distance to its nearest
//                        vertex at the pose 1 cm off (bound 1, as an ICP iteration bounds its
//                        search by the previous one's) or by 5 cm (bound 0, a first iteration)
// Counters: cpu_ms (process CPU per iteration, all threads), candidates (visited per E-step)
// and pairs (with p_st > 0). For one core run under `taskset -c 0` (oneTBB follows the
// affinity mask).
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <algorithm>
#include <memory>
#include <random>
#include <vector>

#include "energies/one_to_many_correspondence.h"
#include "models/normals.h"
#include "models/template_generator.h"
#include "solvers/em_fitter.h"
#include "solvers/estep.h"
#include "solvers/nearest_grid.h"
#include "tests/solvers/fitting_test_util.h"

namespace artex {
namespace {

constexpr double kScanPoints = 20000.0;
constexpr double kNoise = 0.004;  // m, along the viewing ray
constexpr uint64_t kSeed = 2014;

double ProcessCpuSeconds() {
  rusage usage;
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_utime.tv_sec + usage.ru_stime.tv_sec +
         1e-6 * (usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
}

struct Fixture {
  Template model;
  Template subset;  // the fitted vertices (skinning constants per vertex, as EMFitter's)
  std::unique_ptr<Skinning> subset_skinning;
  Scan scan;
  Pose truth, guess;
  Eigen::MatrixX3d posed, normals;          // fitted vertices at `guess`
  Eigen::MatrixX3d full_truth, full_guess;  // every template vertex at `truth`, `guess`
  EStepOptions estep;
  double radius = 0.0;
};

Fixture& GetFixture() {
  static Fixture* fixture = [] {
    auto* f = new Fixture;
    f->model = GenerateTemplate(BodyShapeOptions());
    const EMFitterOptions options;
    f->estep = options.estep;
    f->radius = options.tracking_radii.front();
    const EMFitter fitter(f->model, options);
    const std::vector<int>& fit = fitter.fit_vertices(true);  // a tracking frame's subset
    const int n = static_cast<int>(fit.size());
    f->subset.vertices.resize(n, 3);
    f->subset.vertex_joint.resize(n);
    f->subset.lbs_weight.resize(n);
    f->subset.slerp_tau.resize(n);
    for (int i = 0; i < n; ++i) {
      f->subset.vertices.row(i) = f->model.vertices.row(fit[i]);
      f->subset.vertex_joint[i] = f->model.vertex_joint[fit[i]];
      f->subset.lbs_weight[i] = f->model.lbs_weight[fit[i]];
      f->subset.slerp_tau[i] = f->model.slerp_tau[fit[i]];
    }
    f->subset.triangles.resize(1, 3);
    f->subset.triangles << 0, 1, 2;  // unused
    f->subset.joints = f->model.joints;
    f->subset_skinning = std::make_unique<Skinning>(f->subset);

    std::mt19937_64 rng(kSeed);
    const Skinning skinning(f->model);
    f->truth = testing_util::RandomPose(f->model.num_joints(), 0.25, 0.15, 0.05, &rng);
    Eigen::MatrixX3d posed;
    skinning.Apply(f->truth, &posed);
    const Eigen::Vector3d camera(0.0, 1.0, 2.5);
    const Scan probe =
        testing_util::SampleScan(posed, f->model.triangles, camera, 1000.0, 0.0, &rng);
    const double density = 1000.0 * kScanPoints / std::max(1, probe.size());
    f->scan = testing_util::SampleScan(posed, f->model.triangles, camera, density, kNoise, &rng);

    Eigen::VectorXd d = Eigen::VectorXd::Zero(f->truth.num_parameters());
    std::normal_distribution<double> g(0.0, 1.0);
    for (int i = 0; i < 3; ++i) d[kTranslationIndex + i] = 0.005 * g(rng);
    for (int i = 0; i < 3; ++i) d[kGlobalRotationIndex + i] = 0.005 * g(rng);
    for (int i = kNumGlobalParameters; i < d.size(); ++i) d[i] = 0.01 * g(rng);
    f->guess = f->truth.Retracted(d);
    Eigen::MatrixX3d full_posed, full_normals;
    skinning.Apply(f->guess, &full_posed);
    f->full_truth = posed;
    f->full_guess = full_posed;
    ComputeVertexNormals(full_posed, f->model.triangles, &full_normals);
    f->posed.resize(n, 3);
    f->normals.resize(n, 3);
    for (int i = 0; i < n; ++i) {
      f->posed.row(i) = full_posed.row(fit[i]);
      f->normals.row(i) = full_normals.row(fit[i]);
    }
    return f;
  }();
  return *fixture;
}

PosedTemplateView View(const Fixture& f) {
  PosedTemplateView view;
  view.vertices = &f.posed;
  view.normals = &f.normals;
  return view;
}

void ReportCpu(benchmark::State& state, double cpu_start) {
  const double runs = std::max<double>(1.0, static_cast<double>(state.iterations()));
  state.counters["cpu_ms"] = 1e3 * (ProcessCpuSeconds() - cpu_start) / runs;
  state.counters["scan_points"] = GetFixture().scan.size();
  state.counters["fitted_vertices"] = static_cast<double>(GetFixture().posed.rows());
}

void BM_EStepVoxelCloud(benchmark::State& state) {
  Fixture& f = GetFixture();
  const Eigen::MatrixX3d none(0, 3);
  PosedTemplateView view;
  view.vertices = &none;
  view.normals = &none;
  CorrespondenceTargets targets;
  const double cpu_start = ProcessCpuSeconds();
  for (auto _ : state) {
    EStep estep(f.scan, f.estep);
    estep.Compute(view, f.radius, &targets);
    benchmark::DoNotOptimize(targets.weight.data());
  }
  ReportCpu(state, cpu_start);
}
BENCHMARK(BM_EStepVoxelCloud)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_EStepFirst(benchmark::State& state) {
  Fixture& f = GetFixture();
  CorrespondenceTargets targets;
  long long visited = 0;
  const double cpu_start = ProcessCpuSeconds();
  for (auto _ : state) {
    EStep estep(f.scan, f.estep);
    estep.Compute(View(f), f.radius, &targets);
    visited = estep.candidates_visited();
    benchmark::DoNotOptimize(targets.weight.data());
  }
  ReportCpu(state, cpu_start);
  state.counters["candidates"] = static_cast<double>(visited);
  state.counters["pairs"] = static_cast<double>(targets.num_pairs);
  state.counters["total_weight"] = targets.total_weight();
}
BENCHMARK(BM_EStepFirst)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_EStepReweigh(benchmark::State& state) {
  Fixture& f = GetFixture();
  CorrespondenceTargets targets;
  EStep estep(f.scan, f.estep);
  estep.Compute(View(f), f.radius, &targets);
  const long long visited_start = estep.candidates_visited();
  const double cpu_start = ProcessCpuSeconds();
  for (auto _ : state) {
    estep.Compute(View(f), f.radius, &targets);
    benchmark::DoNotOptimize(targets.weight.data());
  }
  ReportCpu(state, cpu_start);
  const double runs = std::max<double>(1.0, static_cast<double>(state.iterations()));
  state.counters["candidates"] = (estep.candidates_visited() - visited_start) / runs;
  state.counters["pairs"] = static_cast<double>(targets.num_pairs);
  state.counters["total_weight"] = targets.total_weight();
}
BENCHMARK(BM_EStepReweigh)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_MStepJacobian(benchmark::State& state) {
  Fixture& f = GetFixture();
  const Eigen::VectorXd delta = Eigen::VectorXd::Zero(f.guess.num_parameters());
  FitEvaluation eval;
  const double cpu_start = ProcessCpuSeconds();
  for (auto _ : state) {
    PrepareFitEvaluation(f.subset_skinning.get(), f.guess, delta, true, true, &eval);
    benchmark::DoNotOptimize(eval.posed.data());
  }
  ReportCpu(state, cpu_start);
}
BENCHMARK(BM_MStepJacobian)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_MStepNormalEquations(benchmark::State& state) {
  Fixture& f = GetFixture();
  CorrespondenceTargets targets;
  EStep estep(f.scan, f.estep);
  estep.Compute(View(f), f.radius, &targets);
  const Eigen::VectorXd delta = Eigen::VectorXd::Zero(f.guess.num_parameters());
  FitEvaluation eval;
  PrepareFitEvaluation(f.subset_skinning.get(), f.guess, delta, true, true, &eval);
  const OneToManyCorrespondenceTerm term(&targets, 1.0 / targets.total_weight());
  const int p = f.guess.num_parameters();
  Eigen::MatrixXd jtj(p, p);
  Eigen::VectorXd jtr(p);
  double cost = 0.0;
  const double cpu_start = ProcessCpuSeconds();
  for (auto _ : state) {
    jtj.setZero();
    jtr.setZero();
    cost = term.AccumulateNormalEquations(eval, &jtj, &jtr);
    benchmark::DoNotOptimize(jtj.data());
  }
  ReportCpu(state, cpu_start);
  state.counters["cost"] = cost;
  state.counters["jtj_trace"] = jtj.trace();
}
BENCHMARK(BM_MStepNormalEquations)->Unit(benchmark::kMillisecond)->UseRealTime();

// The ICP's target: the posed template; its queries: a fixed-stride subsample of the scan.
// A normal refresh of a tracking frame's fitted vertices from the posed template: range(0) = 0
// the whole template's normals, then the fitted rows (before); 1 only the fitted vertices',
// from their incident triangles (EMFitter now).
void BM_FittedNormals(benchmark::State& state) {
  const Fixture& f = GetFixture();
  const EMFitter fitter(f.model, EMFitterOptions());
  const std::vector<int>& fit = fitter.fit_vertices(true);
  const IncidentTriangles incident =
      FindIncidentTriangles(f.model.triangles, fit, f.model.num_vertices());
  Eigen::MatrixX3d whole, normals(fit.size(), 3);
  const double cpu_start = ProcessCpuSeconds();
  for (auto _ : state) {
    if (state.range(0) == 0) {
      ComputeVertexNormals(f.full_guess, f.model.triangles, &whole);
      for (size_t i = 0; i < fit.size(); ++i) normals.row(i) = whole.row(fit[i]);
    } else {
      ComputeVertexNormalsOf(f.full_guess, f.model.triangles, incident, &normals);
    }
    benchmark::DoNotOptimize(normals.data());
  }
  ReportCpu(state, cpu_start);
  state.counters["triangles"] = static_cast<double>(
      state.range(0) == 0 ? f.model.num_triangles() : static_cast<int>(incident.triangles.size()));
}
BENCHMARK(BM_FittedNormals)->Unit(benchmark::kMicrosecond)->UseRealTime()->Arg(0)->Arg(1);

// The template's nearest-vertex index of an ICP: range(0) = 0 the kd-tree (leaf 24), else
// a NearestGrid of that cell in mm.
struct NearestIndex {
  NearestIndex(const Eigen::MatrixX3d& points, int64_t cell_mm) {
    if (cell_mm > 0) {
      grid = std::make_unique<NearestGrid>(points, 1e-3 * static_cast<double>(cell_mm));
    } else {
      tree = std::make_unique<PointCloudIndex>(points, 24);
    }
  }
  int NearestWithin(const Eigen::Vector3d& q, double bound2, double* d2) const {
    return grid ? grid->NearestWithin(q, bound2, d2) : tree->NearestWithin(q, bound2, d2);
  }
  std::unique_ptr<PointCloudIndex> tree;
  std::unique_ptr<NearestGrid> grid;
};

void BM_IndexNearestBuild(benchmark::State& state) {
  const Fixture& f = GetFixture();
  const double cpu_start = ProcessCpuSeconds();
  for (auto _ : state) {
    const NearestIndex index(f.full_guess, state.range(0));
    double d2 = 0.0;
    benchmark::DoNotOptimize(index.NearestWithin(f.scan.points.row(0).transpose(), 1.0, &d2));
  }
  ReportCpu(state, cpu_start);
  state.counters["points"] = static_cast<double>(f.full_guess.rows());
}
BENCHMARK(BM_IndexNearestBuild)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Arg(0)
    ->Arg(10)
    ->Arg(20)
    ->Arg(30)
    ->Arg(40);

// range(1) = 1: each query bounded by the distance to its nearest vertex at the pose 1 cm off
// (as an ICP iteration bounds its search by the previous one's); 0: by 5 cm (the scale
// sample's first iteration, fitting.scale_sample_max_distance).
void BM_IndexNearestWithin(benchmark::State& state) {
  const Fixture& f = GetFixture();
  const NearestIndex index(f.full_guess, state.range(0));
  const bool from_previous = state.range(1) != 0;
  const int stride = std::max(1, f.scan.size() / 1500);
  std::vector<int> sample, previous;
  for (int s = 0; s < f.scan.size(); s += stride) sample.push_back(s);
  {
    // Each query's nearest vertex at the pose 1 cm off: the previous iteration's.
    const PointCloudIndex other(f.full_truth, 24);
    for (int s : sample) {
      double d2 = 0.0;
      previous.push_back(other.Nearest(f.scan.points.row(s).transpose(), &d2));
    }
  }
  double d2 = 0.0;
  long long found = 0;
  const double cpu_start = ProcessCpuSeconds();
  for (auto _ : state) {
    for (size_t k = 0; k < sample.size(); ++k) {
      const Eigen::Vector3d q = f.scan.points.row(sample[k]).transpose();
      const double bound2 =
          from_previous
              ? (f.full_guess.row(previous[k]).transpose() - q).squaredNorm() * (1.0 + 1e-9) +
                    1e-300
              : 0.05 * 0.05;
      found += index.NearestWithin(q, bound2, &d2) >= 0;
    }
  }
  ReportCpu(state, cpu_start);
  state.counters["queries"] = static_cast<double>(sample.size());
  benchmark::DoNotOptimize(found);
}
BENCHMARK(BM_IndexNearestWithin)
    ->Unit(benchmark::kMicrosecond)
    ->UseRealTime()
    ->ArgsProduct({{0, 10, 20, 30, 40}, {1, 0}});

}  // namespace
}  // namespace artex
