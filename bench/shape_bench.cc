// Subject shape (docs/shape.md): tracking speed with the subject's template
// against the template as generated, and the cost of one calibration solve.
//   BM_TrackBase:    EMFitter tracking frames on the default template (resolution 1), scans of
//                    that template; time per tracking frame.
//   BM_TrackSubject: the same after EMFitter::SetRestShape with a bones_girth shape (+-10 %),
//                    scans of that subject; same vertex count and rig, so the same work.
//   BM_CalibrationSolve: ShapeEstimator::Solve over 5 frames (default shape options).
// Counters: cpu_ms per frame (process CPU, all threads; the machine is shared).
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <random>
#include <vector>

#include "models/shape.h"
#include "models/template_generator.h"
#include "solvers/em_fitter.h"
#include "solvers/shape_estimator.h"
#include "tests/solvers/fitting_test_util.h"

namespace artex {
namespace {

double CpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_utime.tv_sec + u.ru_stime.tv_sec + 1e-6 * (u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

struct ShapeFixture {
  Template base, subject;
  std::vector<Pose> poses;
  std::vector<Scan> base_scans, subject_scans;
};

const ShapeFixture& Fixture() {
  static const ShapeFixture f = [] {
    ShapeFixture x;
    x.base = GenerateTemplate();
    const ShapeModel model(x.base, ShapeMode::kBonesGirth, true);
    std::mt19937 rng(15);
    std::uniform_real_distribution<double> u(-0.1, 0.1);
    Eigen::VectorXd q(model.num_parameters());
    for (int i = 0; i < q.size(); ++i) q[i] = u(rng);
    x.subject = model.Apply(q);
    std::mt19937_64 rng64(2014);
    const Eigen::Vector3d camera(0.0, 1.0, 3.0);
    for (int f = 0; f < 8; ++f) {
      Pose p = Pose::Identity(x.base.num_joints());
      const double phase = 0.4 * f;
      for (const char* j : {"l_shoulder", "r_hip"}) {
        p.joint_rotations[x.base.FindJoint(j)] =
            ExpSO3(Eigen::Vector3d(0.3 * std::sin(phase), 0.0, 0.0));
      }
      p.translation = Eigen::Vector3d(0.02 * f, 0.0, 0.0);
      x.poses.push_back(p);
      Eigen::MatrixX3d posed;
      Skinning(x.base).Apply(p, &posed);
      x.base_scans.push_back(
          testing_util::SampleScan(posed, x.base.triangles, camera, 20000.0, 0.004, &rng64));
      Skinning(x.subject).Apply(p, &posed);
      x.subject_scans.push_back(
          testing_util::SampleScan(posed, x.base.triangles, camera, 20000.0, 0.004, &rng64));
    }
    return x;
  }();
  return f;
}

void Track(benchmark::State& state, bool subject) {
  const ShapeFixture& f = Fixture();
  const std::vector<Scan>& scans = subject ? f.subject_scans : f.base_scans;
  double cpu = 0.0;
  int frames = 0;
  for (auto _ : state) {
    state.PauseTiming();
    EMFitter fitter(f.base, EMFitterOptions());
    if (subject) fitter.SetRestShape(f.subject);
    fitter.SetInitialPose(f.poses[0]);
    fitter.FitFrame(scans[0]);
    state.ResumeTiming();
    const double c0 = CpuSeconds();
    for (size_t i = 1; i < scans.size(); ++i) benchmark::DoNotOptimize(fitter.FitFrame(scans[i]));
    cpu += CpuSeconds() - c0;
    frames += static_cast<int>(scans.size()) - 1;
  }
  state.counters["cpu_ms"] = 1000.0 * cpu / std::max(1, frames);
  state.SetItemsProcessed(frames);
}

void BM_TrackBase(benchmark::State& state) { Track(state, false); }
void BM_TrackSubject(benchmark::State& state) { Track(state, true); }

void BM_CalibrationSolve(benchmark::State& state) {
  const ShapeFixture& f = Fixture();
  ShapeOptions o;
  o.mode = ShapeMode::kBonesGirth;
  std::vector<const Scan*> scans;
  for (int i = 0; i < 5; ++i) scans.push_back(&f.subject_scans[i]);
  double cpu = 0.0;
  int solves = 0;
  for (auto _ : state) {
    ShapeEstimator estimator(f.base, o);
    std::vector<Pose> poses(f.poses.begin(), f.poses.begin() + 5);
    const double c0 = CpuSeconds();
    benchmark::DoNotOptimize(estimator.Solve(
        scans, &poses, Eigen::VectorXd::Zero(estimator.model().num_parameters()), o.prior_weight));
    cpu += CpuSeconds() - c0;
    ++solves;
  }
  state.counters["cpu_ms"] = 1000.0 * cpu / std::max(1, solves);
}

BENCHMARK(BM_TrackBase)->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_TrackSubject)->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_CalibrationSolve)->Unit(benchmark::kMillisecond)->Iterations(1);

}  // namespace
}  // namespace artex
