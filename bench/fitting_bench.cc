// One full frame of kinematic fitting (paper sec. 3): the default template (resolution 1),
// a front-facing scan with the density of a preprocessed 640x480 frame (~20k points on the
// body, 4 mm noise), a tracking frame starting ~1-2 cm / a few degrees per joint away from the
// truth. Variants: truncated-radius E-step + Gauss-Newton (default), Ceres LM backend, dense
// exact E-step. Counters: EM iterations, mean vertex error vs truth (mm), and for the dense
// variant the mean per-vertex difference to the default fit (mm).
#include <memory>
#include <random>

#include <benchmark/benchmark.h>

#include "models/error.h"
#include "models/template_generator.h"
#include "solvers/em_fitter.h"
#include "tests/solvers/fitting_test_util.h"

namespace artex {
namespace {

struct Fixture {
  Template model;
  std::string template_name;
  std::unique_ptr<Skinning> skinning;
  Pose truth, guess;
  Scan scan;
  Pose default_result;  // filled by the default variant (for the dense deviation)
  bool has_default_result = false;
};

Fixture& GetFixture() {
  static Fixture* fixture = [] {
    auto* f = new Fixture;
    try {
      f->model = GenerateTemplate(BodyShapeOptions());
      f->template_name = "generated resolution 1";
    } catch (const Error&) {
      // The generator is unavailable in this build: a synthetic articulated template with
      // the same vertex count (reported in the label).
      f->model = testing_util::MakeStickTemplate(40, 50);
      f->template_name = "synthetic tubes";
    }
    f->skinning = std::make_unique<Skinning>(f->model);
    std::mt19937_64 rng(2014);
    f->truth = testing_util::RandomPose(f->model.num_joints(), 0.25, 0.15, 0.05, &rng);
    Eigen::MatrixX3d posed;
    f->skinning->Apply(f->truth, &posed);
    const Eigen::Vector3d camera(0.0, 1.0, 2.5);
    // Scale the sampling density to ~20k points.
    const Scan probe = testing_util::SampleScan(posed, f->model.triangles, camera, 1000.0, 0.0, &rng);
    const double density = 1000.0 * 20000.0 / std::max(1, probe.size());
    f->scan = testing_util::SampleScan(posed, f->model.triangles, camera, density, 0.004, &rng);
    Eigen::VectorXd d = Eigen::VectorXd::Zero(f->truth.num_parameters());
    std::normal_distribution<double> g(0.0, 1.0);
    for (int i = 0; i < 3; ++i) d[kTranslationIndex + i] = 0.01 * g(rng);
    for (int i = 0; i < 3; ++i) d[kGlobalRotationIndex + i] = 0.02 * g(rng);
    for (int i = kNumGlobalParameters; i < d.size(); ++i) d[i] = 0.03 * g(rng);
    f->guess = f->truth.Retracted(d);
    return f;
  }();
  return *fixture;
}

void RunFrames(benchmark::State& state, EMFitterOptions options, bool is_default, bool is_dense) {
  Fixture& f = GetFixture();
  options.icp_first_frame = false;
  EMFitter fitter(f.model, options);
  fitter.SetInitialPose(f.truth);
  fitter.FitFrame(f.scan);  // history: the next frames are tracking frames
  double iterations = 0.0, error = 0.0, estep = 0.0, mstep = 0.0;
  int frames = 0;
  for (auto _ : state) {
    fitter.BeginFrame(f.scan, f.guess);
    while (!fitter.frame_done()) fitter.Iterate();
    const FitSummary s = fitter.EndFrame();
    iterations += s.iterations;
    estep += s.estep_seconds;
    mstep += s.mstep_seconds;
    ++frames;
  }
  error = testing_util::MeanVertexError(*f.skinning, fitter.pose(), f.truth);
  state.counters["em_iterations"] = iterations / frames;
  state.counters["estep_ms"] = 1e3 * estep / frames;
  state.counters["mstep_ms"] = 1e3 * mstep / frames;
  state.counters["error_mm"] = error * 1e3;
  state.counters["scan_points"] = f.scan.size();
  state.counters["template_vertices"] = f.model.num_vertices();
  if (is_default) {
    f.default_result = fitter.pose();
    f.has_default_result = true;
  }
  if (is_dense && f.has_default_result) {
    state.counters["dense_vs_truncated_mm"] =
        1e3 * testing_util::MeanVertexError(*f.skinning, fitter.pose(), f.default_result);
  }
  state.SetLabel(f.template_name);
}

void BM_FitFrameTruncatedGaussNewton(benchmark::State& state) {
  RunFrames(state, EMFitterOptions(), true, false);
}
BENCHMARK(BM_FitFrameTruncatedGaussNewton)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_FitFrameCeresLm(benchmark::State& state) {
  EMFitterOptions options;
  options.solver.type = FitSolverType::kCeresLevenbergMarquardt;
  options.solver.max_iterations = 3;
  RunFrames(state, options, false, false);
}
BENCHMARK(BM_FitFrameCeresLm)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_FitFrameDenseEStep(benchmark::State& state) {
  EMFitterOptions options;
  options.estep.mode = EStepMode::kDense;
  options.max_mean_motion = 1e3;  // measure the dense optimum, do not reject it
  RunFrames(state, options, false, true);
}
BENCHMARK(BM_FitFrameDenseEStep)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);

}  // namespace
}  // namespace artex
