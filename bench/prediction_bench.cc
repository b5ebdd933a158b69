// Per-frame cost of the pose predictors (solvers/prediction.h), side by side in one run:
//   BM_PredictorUpdate/<model>: Observe (with a 58 x 58 information matrix) + Predict of one
//                 frame on the default template's pose, i.e. the predictor's own overhead;
//   BM_TrackFast/<model>/<speed>: tracking frames of the punch_kick motion (sensors/motion.h)
//                 at 1x or 3x playback, default template, scans of ~20k points sampled from the
//                 posed surface seen from 2.5 m (4 mm noise); each benchmark iteration tracks
//                 kFrames frames from the true first pose with TrackFrame (the particle stage
//                 when the model is particle). Time and cpu_ms = per tracking frame; counters:
//                 EM iterations per frame, mean vertex error (mm, against the true pose),
//                 fraction of frames where the particle stage triggered.
// Models: 0 previous, 1 constant_velocity, 2 kalman, 3 particle.
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <chrono>
#include <memory>
#include <random>
#include <vector>

#include "models/so3.h"
#include "models/template_generator.h"
#include "sensors/motion.h"
#include "solvers/em_fitter.h"
#include "solvers/particle_predictor.h"
#include "solvers/prediction.h"
#include "tests/solvers/fitting_test_util.h"

namespace artex {
namespace {

constexpr int kFrames = 10;  // 1 first frame + 9 tracking frames
constexpr double kScanPoints = 20000.0;
constexpr double kNoise = 0.004;
constexpr uint64_t kSeed = 2026;
const Eigen::Vector3d kEye(0.0, 1.0, 2.5);

double ProcessCpuSeconds() {
  rusage usage;
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_utime.tv_sec + usage.ru_stime.tv_sec +
         1e-6 * (usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
}

PredictionModel ModelOf(int64_t index) {
  static const PredictionModel kModels[] = {PredictionModel::kPrevious,
                                            PredictionModel::kConstantVelocity,
                                            PredictionModel::kKalman, PredictionModel::kParticle};
  return kModels[index];
}

struct Sequence {
  std::vector<Pose> truth;
  std::vector<Scan> scans;
};

struct Fixture {
  Template model = GenerateTemplate();
  Skinning skinning{model};
  PinholeCamera camera;
  Sequence speeds[2];  // 1x, 3x
  Fixture() {
    camera.world_to_camera =
        PinholeCamera::LookAt(kEye, Eigen::Vector3d(0.0, 0.9, 0.0), Eigen::Vector3d::UnitY());
    std::mt19937_64 rng(kSeed);
    for (int s = 0; s < 2; ++s) {
      MotionOptions motion;
      motion.type = MotionType::kPunchKick;
      motion.frames = kFrames;
      motion.speed = s == 0 ? 1.0 : 3.0;
      speeds[s].truth = GenerateMotion(model, motion);
      for (const Pose& pose : speeds[s].truth) {
        Eigen::MatrixX3d posed;
        skinning.Apply(pose, &posed);
        const Scan probe =
            testing_util::SampleScan(posed, model.triangles, kEye, 1000.0, 0.0, &rng);
        const double density = 1000.0 * kScanPoints / std::max(1, probe.size());
        speeds[s].scans.push_back(
            testing_util::SampleScan(posed, model.triangles, kEye, density, kNoise, &rng));
      }
    }
  }
};

Fixture& GetFixture() {
  static Fixture* f = new Fixture;
  return *f;
}

void BM_PredictorUpdate(benchmark::State& state) {
  Fixture& f = GetFixture();
  PredictionOptions options;
  options.model = ModelOf(state.range(0));
  const std::unique_ptr<PosePredictor> predictor = PosePredictor::Create(options);
  const Sequence& seq = f.speeds[1];
  const int p = seq.truth[0].num_parameters();
  std::mt19937_64 rng(kSeed);
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::MatrixXd a(p, p);
  for (int i = 0; i < a.size(); ++i) a.data()[i] = g(rng);
  const Eigen::MatrixXd information = 1e-2 * a * a.transpose();
  int frame = 0;
  double checksum = 0.0;
  for (auto _ : state) {
    predictor->Observe(seq.truth[frame % kFrames], information);
    const Pose next = predictor->Predict();
    checksum += next.translation.x();
    ++frame;
  }
  benchmark::DoNotOptimize(checksum);
  state.SetLabel(predictor->name());
}
BENCHMARK(BM_PredictorUpdate)->DenseRange(0, 2)->Unit(benchmark::kMicrosecond);

void BM_TrackFast(benchmark::State& state) {
  Fixture& f = GetFixture();
  const PredictionModel model = ModelOf(state.range(0));
  const Sequence& seq = f.speeds[state.range(1) == 1 ? 0 : 1];
  EMFitterOptions options;
  options.icp_first_frame = false;
  options.prediction.model = model;
  double cpu = 0.0, iterations = 0.0, error = 0.0, triggered = 0.0;
  int frames = 0;
  for (auto _ : state) {
    state.PauseTiming();
    EMFitter fitter(f.model, options);
    fitter.SetInitialPose(seq.truth[0]);
    fitter.FitFrame(seq.scans[0]);
    state.ResumeTiming();
    const double cpu_start = ProcessCpuSeconds();
    const auto wall_start = std::chrono::steady_clock::now();
    for (int frame = 1; frame < kFrames; ++frame) {
      ParticleFrameReport report;
      const FitSummary s =
          TrackFrame(&fitter, seq.scans[frame], f.camera, FitQualityOptions(), &report);
      iterations += s.iterations;
      triggered += report.triggered;
      error += testing_util::MeanVertexError(f.skinning, fitter.pose(), seq.truth[frame]);
      ++frames;
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
    cpu += ProcessCpuSeconds() - cpu_start;
    state.SetIterationTime(seconds / (kFrames - 1));
  }
  state.counters["cpu_ms"] = 1e3 * cpu / std::max(1, frames);
  state.counters["em_iterations"] = iterations / std::max(1, frames);
  state.counters["error_mm"] = 1e3 * error / std::max(1, frames);
  state.counters["triggered"] = triggered / std::max(1, frames);
  state.SetLabel(std::string(PredictionModelName(model)) + " " + std::to_string(state.range(1)) +
                 "x");
}
BENCHMARK(BM_TrackFast)
    ->ArgsProduct({{0, 1, 2, 3}, {1, 3}})
    ->Unit(benchmark::kMillisecond)
    ->UseManualTime()
    ->Iterations(1);

}  // namespace
}  // namespace artex
