// Subject shape (docs/shape.md): tracking speed with the subject's template
// against the template as generated, and the cost of one calibration solve.
//   BM_TrackBase:    EMFitter tracking frames of a subject (a bones_girth shape, +-10 %) with the
//                    default template (resolution 1) as given: shape.mode fixed.
//   BM_TrackSubject: the same frames after EMFitter::SetRestShape with the subject's shape (as
//                    after the calibration phase); same vertex count and rig, so the same work
//                    per EM iteration. (Before, each ran on scans of its own template: a
//                    larger subject gives more scan points, which the E-step pays for.)
//   BM_TrackSubjectTemplate: the same frames with the subject's template as the tracker's own
//                    (no SetRestShape): what SetRestShape itself costs, if anything.
//   BM_CalibrationSolve/<hold_unseen>/<bias_scan_mask>: ShapeEstimator::Solve over 5 frames
//                    (default shape options otherwise).
//   BM_SurfaceDetail/<frames>: EstimateSurfaceDetail (the surface detail after the last round,
//                    default options) over that many frames.
// Counters: cpu_ms per frame (process CPU, all threads; the machine is shared), em_iterations per
// frame, cpu_ms_per_iteration, candidates_per_iteration (scan points the E-step visits).
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <random>
#include <vector>

#include "models/shape.h"
#include "models/template_generator.h"
#include "solvers/em_fitter.h"
#include "solvers/shape_detail.h"
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
  std::vector<Scan> subject_scans;
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
      Skinning(x.subject).Apply(p, &posed);
      x.subject_scans.push_back(
          testing_util::SampleScan(posed, x.base.triangles, camera, 20000.0, 0.004, &rng64));
    }
    return x;
  }();
  return f;
}

enum class Tracker { kBase, kSubjectShape, kSubjectTemplate };

void Track(benchmark::State& state, Tracker tracker) {
  const ShapeFixture& f = Fixture();
  const std::vector<Scan>& scans = f.subject_scans;
  double cpu = 0.0;
  int frames = 0, iterations = 0;
  double candidates = 0.0;
  for (auto _ : state) {
    state.PauseTiming();
    EMFitter fitter(tracker == Tracker::kSubjectTemplate ? f.subject : f.base, EMFitterOptions());
    if (tracker == Tracker::kSubjectShape) fitter.SetRestShape(f.subject);
    fitter.SetInitialPose(f.poses[0]);
    fitter.FitFrame(scans[0]);
    state.ResumeTiming();
    const double c0 = CpuSeconds();
    for (size_t i = 1; i < scans.size(); ++i) {
      const FitSummary s = fitter.FitFrame(scans[i]);
      iterations += s.iterations;
      candidates += static_cast<double>(s.candidates_visited);
    }
    cpu += CpuSeconds() - c0;
    frames += static_cast<int>(scans.size()) - 1;
  }
  state.counters["cpu_ms"] = 1000.0 * cpu / std::max(1, frames);
  // Different scans converge in different EM iteration counts: the cost per iteration compares
  // the work itself.
  state.counters["em_iterations"] = static_cast<double>(iterations) / std::max(1, frames);
  state.counters["cpu_ms_per_iteration"] = 1000.0 * cpu / std::max(1, iterations);
  state.counters["candidates_per_iteration"] = candidates / std::max(1, iterations);
  state.SetItemsProcessed(frames);
}

void BM_TrackBase(benchmark::State& state) { Track(state, Tracker::kBase); }
void BM_TrackSubject(benchmark::State& state) { Track(state, Tracker::kSubjectShape); }
void BM_TrackSubjectTemplate(benchmark::State& state) { Track(state, Tracker::kSubjectTemplate); }

// One calibration solve over 5 frames, the depth camera and the floor (y = 0) set. First
// argument: shape.hold_unseen's out-of-view test (1; the whole body is in view: nothing is
// held); second: shape.bias_scan_mask (1, the default; the scans have no free-space maps, so
// the mask keeps the vertices the scan saw); third: the self scans from the template's vertices
// (0: the previous version), the scan-to-model term's rendered on the depth camera's pixel grid
// (1, the default), and the E-step's too in the last radius stage (2:
// shape.bias_rendered_estep_max_radius 0.03).
void BM_CalibrationSolve(benchmark::State& state) {
  const ShapeFixture& f = Fixture();
  ShapeOptions o;
  o.mode = ShapeMode::kBonesGirth;
  o.hold_unseen = state.range(0) != 0;
  o.bias_scan_mask = state.range(1) != 0;
  o.bias_rendered_scan_to_model = state.range(2) >= 1;
  o.bias_rendered_estep_max_radius = state.range(2) == 2 ? 0.03 : 0.0;
  PinholeCamera camera;
  camera.world_to_camera = PinholeCamera::LookAt(Eigen::Vector3d(0.0, 1.0, 3.0),
                                                 Eigen::Vector3d(0.0, 1.0, 0.0),
                                                 Eigen::Vector3d::UnitY());
  std::vector<const Scan*> scans;
  for (int i = 0; i < 5; ++i) scans.push_back(&f.subject_scans[i]);
  double cpu = 0.0;
  int solves = 0;
  for (auto _ : state) {
    ShapeEstimator estimator(f.base, o);
    estimator.SetDepthCamera(camera, OutOfViewOptions());
    estimator.SetFloor(Eigen::Vector3d::UnitY(), 0.0);
    std::vector<Pose> poses(f.poses.begin(), f.poses.begin() + 5);
    const double c0 = CpuSeconds();
    benchmark::DoNotOptimize(estimator.Solve(
        scans, &poses, Eigen::VectorXd::Zero(estimator.model().num_parameters()), o.prior_weight));
    cpu += CpuSeconds() - c0;
    ++solves;
  }
  state.counters["cpu_ms"] = 1000.0 * cpu / std::max(1, solves);
}

// The surface detail of the template against the subject's scans over state.range(0) frames.
void BM_SurfaceDetail(benchmark::State& state) {
  const ShapeFixture& f = Fixture();
  PinholeCamera camera;
  camera.world_to_camera = PinholeCamera::LookAt(Eigen::Vector3d(0.0, 1.0, 3.0),
                                                 Eigen::Vector3d(0.0, 1.0, 0.0),
                                                 Eigen::Vector3d::UnitY());
  const int frames = static_cast<int>(state.range(0));
  std::vector<const Scan*> scans;
  for (int i = 0; i < frames; ++i) scans.push_back(&f.subject_scans[i]);
  const std::vector<Pose> poses(f.poses.begin(), f.poses.begin() + frames);
  double cpu = 0.0;
  int runs = 0;
  ShapeDetailSummary summary;
  for (auto _ : state) {
    const double c0 = CpuSeconds();
    benchmark::DoNotOptimize(
        EstimateSurfaceDetail(f.base, scans, poses, camera, ShapeDetailOptions(), &summary));
    cpu += CpuSeconds() - c0;
    ++runs;
  }
  state.counters["cpu_ms"] = 1000.0 * cpu / std::max(1, runs);
  state.counters["observations"] = summary.observations;
}

BENCHMARK(BM_TrackBase)->Unit(benchmark::kMillisecond)->Iterations(10);
BENCHMARK(BM_TrackSubject)->Unit(benchmark::kMillisecond)->Iterations(10);
BENCHMARK(BM_TrackSubjectTemplate)->Unit(benchmark::kMillisecond)->Iterations(10);
BENCHMARK(BM_CalibrationSolve)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->Args({0, 1, 1})
    ->Args({1, 0, 1})
    ->Args({1, 1, 0})
    ->Args({1, 1, 1})
    ->Args({1, 1, 2});
BENCHMARK(BM_SurfaceDetail)->Unit(benchmark::kMillisecond)->Iterations(3)->Arg(5)->Arg(8);

}  // namespace
}  // namespace artex
