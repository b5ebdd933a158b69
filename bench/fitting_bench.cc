// Kinematic fitting (paper sec. 3) on the default template (resolution 1) with scans of the
// density of a preprocessed 640x480 frame (~20k points on the body, 4 mm noise along the ray):
//   BM_Track*:    a tracking sequence (a walking-like motion at 30 Hz: joints swinging up to
//                 ~0.35 rad, the body turning and moving ~2 cm per frame); each benchmark
//                 iteration fits its tracking frames in order, starting from the fitted first
//                 frame, with the fitter's own constant-velocity prediction. Time = per frame.
//                 12 frames (11 tracking frames), BM_TrackLongSequence 60 (59).
//   BM_FitFrame*: one hard tracking frame starting ~50 mm mean vertex error from the truth.
//   BM_InitializeFit: the multi-hypothesis first frame (solvers/initializer.h, default options:
//                 12 hypotheses, 4 EM fits) on a virtual Kinect frame (640 x 480, default
//                 noise, the subject facing away); counters: chosen yaw, ICP / EM / quality
//                 ms, the ICP iterations per hypothesis and how many converged before the cap;
//                 cpu_ms (the process's CPU per initialisation) and cores (CPU / wall).
//   BM_FitQuality: EvaluateFitQuality of the fitted (posed) template on that frame.
//   BM_FitterSetup: EMFitter's constructor (once per run); BM_VoxelVertexSubset/<count>: the
//                 fitted subset it chooses (twice: max_fit_vertices, tracking_max_fit_vertices).
// Variants side by side: truncated-radius E-step + Gauss-Newton (default options), the same
// with other E-step candidate margins (BM_TrackCandidateMargin/<mm>) and work budgets
// (BM_TrackBudget/<fitted vertices>/<voxel %>), a cloud and gather per tracking radius or one
// per frame (BM_TrackSharedCloud/<0|1>), the scale sample's ICP tolerance
// (BM_TrackScaleTolerance/<1e-5 units>), Ceres LM backend, dense
// exact E-step (single frame only: it takes seconds per EM iteration). For one core run under
// `taskset -c 0` (oneTBB follows the affinity mask).
// Counters: cpu_ms (process CPU per frame, all threads, of the fitter's calls alone: BM_Track*
// leave out the error against the truth they evaluate after each frame; wall times are unreliable
// on a shared machine), wall_ratio / cpu_ratio to the default of the same kind, EM iterations,
// E-/M-step ms, kd-tree queries and scan candidates visited per frame, error_mm (mean per-vertex
// error against the true pose, i.e. including tangential sliding), and for the dense variant the
// mean per-vertex difference to the default fit (mm). BM_Track* split cpu_ms: scale_cpu_ms per
// tracking frame that still samples the scale (the first scale_estimation_frames accepted frames: a
// similarity ICP each; scale_frames of the 11), steady_cpu_ms per frame after (the cost of a long
// sequence). With ARTEX_BENCH_DUMP_POSES set, BM_Track* print every tracked pose parameter as
// hexadecimal floats to stderr.
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <random>
#include <vector>

#include "models/error.h"
#include "models/so3.h"
#include "models/template_generator.h"
#include "solvers/em_fitter.h"
#include "solvers/fit_quality.h"
#include "solvers/fit_vertex_subset.h"
#include "solvers/initializer.h"
#include "tests/solvers/fitting_test_util.h"
#include "tests/solvers/virtual_kinect_scans.h"

namespace artex {
namespace {

constexpr int kSequenceFrames = 12;  // 1 first frame + 11 tracking frames
// BM_TrackLongSequence: the same motion over 60 frames (the length of bench/track_realtime.py's
// walk), so the 4 frames that sample the scale are 4 of 59 tracking frames rather than 4 of 11.
constexpr int kLongSequenceFrames = 60;
constexpr double kScanPoints = 20000.0;
constexpr double kNoise = 0.004;  // m, along the viewing ray
constexpr uint64_t kSeed = 2014;

struct Fixture {
  Template model;
  std::string template_name;
  std::unique_ptr<Skinning> skinning;
  // Single hard frame.
  Pose truth, guess;
  Scan scan;
  // Tracking sequence.
  std::vector<Pose> sequence_truth;
  std::vector<Scan> sequence_scans;
  // Results of the default variants (for the ratios and the dense deviation).
  Pose default_result;
  bool has_default_result = false;
  double default_wall_ms[2] = {0.0, 0.0}, default_cpu_ms[2] = {0.0, 0.0};  // frame, track
};

// CPU time of the whole process (all threads), s.
double ProcessCpuSeconds() {
  rusage usage;
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_utime.tv_sec + usage.ru_stime.tv_sec +
         1e-6 * (usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
}

Scan ScanOf(const Fixture& f, const Pose& pose, std::mt19937_64* rng) {
  Eigen::MatrixX3d posed;
  f.skinning->Apply(pose, &posed);
  const Eigen::Vector3d camera(0.0, 1.0, 2.5);
  const Scan probe = testing_util::SampleScan(posed, f.model.triangles, camera, 1000.0, 0.0, rng);
  const double density = 1000.0 * kScanPoints / std::max(1, probe.size());
  return testing_util::SampleScan(posed, f.model.triangles, camera, density, kNoise, rng);
}

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
    std::mt19937_64 rng(kSeed);
    f->truth = testing_util::RandomPose(f->model.num_joints(), 0.25, 0.15, 0.05, &rng);
    f->scan = ScanOf(*f, f->truth, &rng);
    Eigen::VectorXd d = Eigen::VectorXd::Zero(f->truth.num_parameters());
    std::normal_distribution<double> g(0.0, 1.0);
    for (int i = 0; i < 3; ++i) d[kTranslationIndex + i] = 0.01 * g(rng);
    for (int i = 0; i < 3; ++i) d[kGlobalRotationIndex + i] = 0.02 * g(rng);
    for (int i = kNumGlobalParameters; i < d.size(); ++i) d[i] = 0.03 * g(rng);
    f->guess = f->truth.Retracted(d);

    // Sequence: every joint swings about a random axis (amplitude up to 0.35 rad, period
    // 1 s at 30 Hz, random phase), the body turns by 0.02 rad and moves 2 cm per frame.
    const int joints = f->model.num_joints();
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::vector<Eigen::Vector3d> axis(joints);
    std::vector<double> amplitude(joints), phase(joints);
    for (int j = 0; j < joints; ++j) {
      axis[j] = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
      amplitude[j] = 0.35 * u(rng);
      phase[j] = 2.0 * M_PI * u(rng);
    }
    for (int frame = 0; frame < kLongSequenceFrames; ++frame) {
      Pose pose = Pose::Identity(joints);
      const double time = frame / 30.0;
      pose.translation = Eigen::Vector3d(0.6 * time, 0.0, -0.1 * time);
      pose.rotation = ExpSO3(Eigen::Vector3d(0.0, 0.6 * time, 0.0));
      for (int j = 0; j < joints; ++j) {
        pose.joint_rotations[j] =
            ExpSO3(amplitude[j] * std::sin(2.0 * M_PI * time + phase[j]) * axis[j]);
      }
      f->sequence_truth.push_back(pose);
      f->sequence_scans.push_back(ScanOf(*f, pose, &rng));
    }
    return f;
  }();
  return *fixture;
}

struct Totals {
  double iterations = 0.0, estep = 0.0, mstep = 0.0, queries = 0.0, visited = 0.0;
  double error = 0.0, max_error = 0.0, first_error = 0.0;
  int frames = 0;
  // Process CPU (s) and frames of the tracking frames that still sample the scale
  // (scale_estimation_frames, a similarity ICP each) and of those after.
  double scale_cpu = 0.0, steady_cpu = 0.0;
  int scale_frames = 0, steady_frames = 0;

  void Add(const FitSummary& s) {
    iterations += s.iterations;
    estep += s.estep_seconds;
    mstep += s.mstep_seconds;
    queries += s.neighbor_queries;
    visited += s.candidates_visited;
    ++frames;
  }
};

void Report(benchmark::State& state, const Totals& totals, double cpu_seconds, double wall_seconds,
            bool is_default, int kind) {
  Fixture& f = GetFixture();
  const int frames = std::max(1, totals.frames);
  const double cpu_ms = 1e3 * cpu_seconds / frames;
  const double wall_ms = 1e3 * wall_seconds / frames;
  if (is_default) {
    f.default_wall_ms[kind] = wall_ms;
    f.default_cpu_ms[kind] = cpu_ms;
  }
  state.counters["cpu_ms"] = cpu_ms;
  if (f.default_cpu_ms[kind] > 0.0) {
    state.counters["wall_ratio"] = wall_ms / f.default_wall_ms[kind];
    state.counters["cpu_ratio"] = cpu_ms / f.default_cpu_ms[kind];
  }
  state.counters["em_iterations"] = totals.iterations / frames;
  state.counters["estep_ms"] = 1e3 * totals.estep / frames;
  state.counters["mstep_ms"] = 1e3 * totals.mstep / frames;
  state.counters["neighbor_queries"] = totals.queries / frames;
  state.counters["candidates"] = totals.visited / frames;
  state.counters["error_mm"] = 1e3 * totals.error / frames;
  if (totals.max_error > 0.0) state.counters["max_error_mm"] = 1e3 * totals.max_error;
  if (totals.first_error > 0.0) state.counters["first_frame_error_mm"] = 1e3 * totals.first_error;
  if (totals.scale_frames > 0) {
    state.counters["scale_cpu_ms"] = 1e3 * totals.scale_cpu / totals.scale_frames;
    state.counters["scale_frames"] = totals.scale_frames / state.iterations();
  }
  if (totals.steady_frames > 0) {
    state.counters["steady_cpu_ms"] = 1e3 * totals.steady_cpu / totals.steady_frames;
  }
  state.counters["template_vertices"] = f.model.num_vertices();
  state.SetLabel(f.template_name);
}

void RunFrame(benchmark::State& state, EMFitterOptions options, bool is_default, bool is_dense) {
  Fixture& f = GetFixture();
  options.icp_first_frame = false;
  EMFitter fitter(f.model, options);
  fitter.SetInitialPose(f.truth);
  fitter.FitFrame(f.scan);  // history: the next frames are tracking frames
  Totals totals;
  const double cpu_start = ProcessCpuSeconds();
  const auto wall_start = std::chrono::steady_clock::now();
  for (auto _ : state) {
    fitter.BeginFrame(f.scan, f.guess);
    while (!fitter.frame_done()) fitter.Iterate();
    totals.Add(fitter.EndFrame());
  }
  const double cpu = ProcessCpuSeconds() - cpu_start;
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  totals.error = totals.frames * testing_util::MeanVertexError(*f.skinning, fitter.pose(), f.truth);
  Report(state, totals, cpu, wall, is_default, 0);
  state.counters["scan_points"] = f.scan.size();
  if (is_default) {
    f.default_result = fitter.pose();
    f.has_default_result = true;
  }
  if (is_dense && f.has_default_result) {
    state.counters["dense_vs_truncated_mm"] =
        1e3 * testing_util::MeanVertexError(*f.skinning, fitter.pose(), f.default_result);
  }
}

// One tracking frame (a separate symbol, so that profilers can single out tracking frames).
__attribute__((noinline)) FitSummary TrackFrame(EMFitter* fitter, const Scan& scan) {
  return fitter->FitFrame(scan);
}

void RunSequence(benchmark::State& state, EMFitterOptions options, bool is_default,
                 int sequence_frames = kSequenceFrames) {
  Fixture& f = GetFixture();
  options.icp_first_frame = false;
  Totals totals;
  double cpu = 0.0, wall = 0.0;
  for (auto _ : state) {
    state.PauseTiming();
    EMFitter fitter(f.model, options);
    // The depth camera the scans were sampled from (as the pipeline gives the fitter): the
    // out-of-view check runs every frame (the whole body is in view, nothing is held).
    PinholeCamera camera;
    camera.world_to_camera = PinholeCamera::LookAt(
        Eigen::Vector3d(0.0, 1.0, 2.5), Eigen::Vector3d(0.0, 0.9, 0.0), Eigen::Vector3d::UnitY());
    fitter.SetDepthCamera(camera);
    fitter.SetInitialPose(f.sequence_truth[0]);
    fitter.FitFrame(f.sequence_scans[0]);  // first frame: not measured
    totals.first_error =
        testing_util::MeanVertexError(*f.skinning, fitter.pose(), f.sequence_truth[0]);
    state.ResumeTiming();
    // The tracking frames alone: not the error against the truth evaluated after each.
    double sequence_cpu = 0.0, sequence_wall = 0.0;
    for (int frame = 1; frame < sequence_frames; ++frame) {
      const bool sampling_scale = fitter.ScaleIsFree();
      const double frame_cpu_start = ProcessCpuSeconds();
      const auto frame_wall_start = std::chrono::steady_clock::now();
      const FitSummary s = TrackFrame(&fitter, f.sequence_scans[frame]);
      sequence_wall += std::chrono::duration<double>(std::chrono::steady_clock::now() -
                                                     frame_wall_start)
                           .count();
      const double frame_cpu = ProcessCpuSeconds() - frame_cpu_start;
      sequence_cpu += frame_cpu;
      (sampling_scale ? totals.scale_cpu : totals.steady_cpu) += frame_cpu;
      ++(sampling_scale ? totals.scale_frames : totals.steady_frames);
      totals.Add(s);
      const double error =
          testing_util::MeanVertexError(*f.skinning, fitter.pose(), f.sequence_truth[frame]);
      totals.error += error;
      totals.max_error = std::max(totals.max_error, error);
      if (std::getenv("ARTEX_BENCH_DUMP_POSES") != nullptr) {
        // Every pose parameter as a hexadecimal float (bit-identity checks between builds).
        std::fprintf(stderr, "frame %d scale %a t", frame, fitter.pose().scale);
        for (int i = 0; i < 3; ++i) std::fprintf(stderr, " %a", fitter.pose().translation[i]);
        for (int i = 0; i < 9; ++i) std::fprintf(stderr, " %a", fitter.pose().rotation(i));
        for (const Eigen::Matrix3d& r : fitter.pose().joint_rotations) {
          for (int i = 0; i < 9; ++i) std::fprintf(stderr, " %a", r(i));
        }
        std::fprintf(stderr, "\n");
      }
    }
    cpu += sequence_cpu;
    wall += sequence_wall;
    state.SetIterationTime(sequence_wall / (sequence_frames - 1));
  }
  Report(state, totals, cpu, wall, is_default, 1);
  state.counters["scan_points"] = f.sequence_scans[1].size();
}

EMFitterOptions CeresOptions() {
  EMFitterOptions options;
  options.solver.type = FitSolverType::kCeresLevenbergMarquardt;
  return options;
}

void BM_TrackTruncatedGaussNewton(benchmark::State& state) {
  RunSequence(state, EMFitterOptions(), true);
}
BENCHMARK(BM_TrackTruncatedGaussNewton)->Unit(benchmark::kMillisecond)->UseManualTime();

// The default options over kLongSequenceFrames (cpu_ms: per tracking frame of the 59).
void BM_TrackLongSequence(benchmark::State& state) {
  RunSequence(state, EMFitterOptions(), false, kLongSequenceFrames);
}
BENCHMARK(BM_TrackLongSequence)->Unit(benchmark::kMillisecond)->UseManualTime();

// The default with another E-step candidate margin (state.range(0), mm): exact whatever the
// margin (only the work changes: a larger margin gathers less often but weighs more candidates).
void BM_TrackCandidateMargin(benchmark::State& state) {
  EMFitterOptions options;
  options.estep.candidate_margin = 1e-3 * static_cast<double>(state.range(0));
  RunSequence(state, options, false);
}
BENCHMARK(BM_TrackCandidateMargin)
    ->Unit(benchmark::kMillisecond)
    ->UseManualTime()
    ->Arg(3)
    ->Arg(5)
    ->Arg(7)
    ->Arg(10)
    ->Arg(15);

// The default with another work budget: at most state.range(0) fitted template vertices (in
// every frame, first and tracking) and a scan voxel cell of state.range(1) % of the radius.
// The candidate gathers, weighing and skinning scale with the fitted vertices, the candidates
// per vertex with the cube of the voxel cell; configs/experiments/fit_budget.yaml measures
// the accuracy of each on the virtual Kinect.
void BM_TrackBudget(benchmark::State& state) {
  EMFitterOptions options;
  options.max_fit_vertices = static_cast<int>(state.range(0));
  options.tracking_max_fit_vertices = 0;  // the same budget in every frame
  options.estep.voxel_fraction = 0.01 * static_cast<double>(state.range(1));
  RunSequence(state, options, false);
}
BENCHMARK(BM_TrackBudget)
    ->Unit(benchmark::kMillisecond)
    ->UseManualTime()
    ->Args({3000, 25})
    ->Args({3000, 35})
    ->Args({2000, 25})
    ->Args({2000, 35})
    ->Args({1500, 25})
    ->Args({1500, 35})
    ->Args({1000, 25})
    ->Args({1000, 35});

// A voxel cloud and a candidate gather per tracking radius (the previous default,
// fitting.tracking_shared_cloud false) against one of each per tracking frame.
void BM_TrackSharedCloud(benchmark::State& state) {
  EMFitterOptions options;
  options.tracking_shared_cloud = state.range(0) != 0;
  RunSequence(state, options, false);
}
BENCHMARK(BM_TrackSharedCloud)->Unit(benchmark::kMillisecond)->UseManualTime()->Arg(0)->Arg(1);

// The scale sample's ICP tolerance (fitting.scale_sample_tolerance), in units of 1e-5 (0: the
// pre-alignment's, 1e-5): the 4 scale frames' cost against the scale estimate (error_mm).
void BM_TrackScaleTolerance(benchmark::State& state) {
  EMFitterOptions options;
  options.scale_sample_tolerance = 1e-5 * static_cast<double>(state.range(0));
  RunSequence(state, options, false);
}
BENCHMARK(BM_TrackScaleTolerance)
    ->Unit(benchmark::kMillisecond)
    ->UseManualTime()
    ->Arg(0)
    ->Arg(10)
    ->Arg(30);

// The scale sample's nearest-vertex index (fitting.scale_sample_grid_cell), the grid's cell in
// mm (0: the kd-tree): the 4 scale frames' cost; the samples, and so error_mm, are the same.
void BM_TrackScaleGrid(benchmark::State& state) {
  EMFitterOptions options;
  options.scale_sample_grid_cell = 1e-3 * static_cast<double>(state.range(0));
  RunSequence(state, options, false);
}
BENCHMARK(BM_TrackScaleGrid)
    ->Unit(benchmark::kMillisecond)
    ->UseManualTime()
    ->Arg(0)
    ->Arg(20)
    ->Arg(30)
    ->Arg(40);

void BM_TrackCeresLm(benchmark::State& state) { RunSequence(state, CeresOptions(), false); }
BENCHMARK(BM_TrackCeresLm)->Unit(benchmark::kMillisecond)->UseManualTime();

void BM_FitFrameTruncatedGaussNewton(benchmark::State& state) {
  RunFrame(state, EMFitterOptions(), true, false);
}
BENCHMARK(BM_FitFrameTruncatedGaussNewton)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_FitFrameCeresLm(benchmark::State& state) { RunFrame(state, CeresOptions(), false, false); }
BENCHMARK(BM_FitFrameCeresLm)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_FitFrameDenseEStep(benchmark::State& state) {
  EMFitterOptions options;
  options.estep.mode = EStepMode::kDense;
  options.max_mean_motion = 1e3;  // measure the dense optimum, do not reject it
  RunFrame(state, options, false, true);
}
BENCHMARK(BM_FitFrameDenseEStep)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);

// One virtual Kinect frame of a walk (the subject facing away), its tracking template and
// the fitted pose.
struct KinectFixture {
  testing_util::KinectScans data;
  Template model;
  Pose fitted;
};

KinectFixture& GetKinectFixture() {
  static KinectFixture* fixture = [] {
    auto* f = new KinectFixture;
    SynthOptions options = testing_util::TestSynthOptions(1);
    options.subject_yaw_deg = 180.0;
    f->data = testing_util::SynthesizeScans(options, "fitting_bench");
    f->model = GenerateTemplate(BodyShapeOptions());
    EMFitter fitter(f->model, EMFitterOptions());
    InitializeFit(&fitter, f->data.scans[0], f->data.depth_camera, InitializerOptions());
    f->fitted = fitter.pose();
    return f;
  }();
  return *fixture;
}

// The fitter's set-up on the generated template (paid once per run, before the first frame):
// the whole constructor, and the voxel vertex subset it chooses twice (max_fit_vertices and
// tracking_max_fit_vertices, range(0) vertices here).
void BM_FitterSetup(benchmark::State& state) {
  const Fixture& f = GetFixture();
  for (auto _ : state) {
    EMFitter fitter(f.model, EMFitterOptions());
    benchmark::DoNotOptimize(fitter);
  }
  state.counters["template_vertices"] = static_cast<double>(f.model.vertices.rows());
}
BENCHMARK(BM_FitterSetup)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_VoxelVertexSubset(benchmark::State& state) {
  const Fixture& f = GetFixture();
  std::vector<int> subset;
  for (auto _ : state) {
    subset = VoxelVertexSubset(f.model.vertices, static_cast<int>(state.range(0)));
    benchmark::DoNotOptimize(subset);
  }
  state.counters["subset"] = static_cast<double>(subset.size());
}
BENCHMARK(BM_VoxelVertexSubset)->Unit(benchmark::kMillisecond)->UseRealTime()->Arg(3000)->Arg(2000);

// range(0): the hypotheses' ICP template index, 0 the kd-tree (default), else a grid of that
// cell in mm (fitting.init.icp.grid_cell).
void BM_InitializeFit(benchmark::State& state) {
  KinectFixture& f = GetKinectFixture();
  EMFitter fitter(f.model, EMFitterOptions());
  InitializerOptions init;
  init.icp.grid_cell = 1e-3 * static_cast<double>(state.range(0));
  InitResult r;
  double icp = 0.0, em = 0.0, quality = 0.0;
  int runs = 0;
  const double cpu0 = ProcessCpuSeconds();
  const auto wall0 = std::chrono::steady_clock::now();
  for (auto _ : state) {
    fitter.Reset();
    r = InitializeFit(&fitter, f.data.scans[0], f.data.depth_camera, init);
    icp += r.icp_seconds;
    em += r.em_seconds;
    quality += r.quality_seconds;
    ++runs;
  }
  runs = std::max(runs, 1);
  const double cpu = ProcessCpuSeconds() - cpu0;
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  state.counters["cpu_ms"] = 1e3 * cpu / runs;
  state.counters["cores"] = cpu / wall;
  state.counters["icp_ms"] = 1e3 * icp / runs;
  state.counters["em_ms"] = 1e3 * em / runs;
  state.counters["quality_ms"] = 1e3 * quality / runs;
  state.counters["hypotheses"] = static_cast<double>(r.hypotheses.size());
  state.counters["chosen_yaw_deg"] = r.chosen >= 0 ? r.hypotheses[r.chosen].yaw_deg : -1.0;
  state.counters["score"] = r.quality.score;
  state.counters["scan_points"] = f.data.scans[0].size();
  double icp_iterations = 0.0, converged = 0.0;
  int aligned = 0;
  for (const InitHypothesis& h : r.hypotheses) {
    if (h.icp.iterations == 0) continue;
    icp_iterations += h.icp.iterations;
    converged += h.icp.converged;
    ++aligned;
  }
  state.counters["icp_iterations"] = aligned > 0 ? icp_iterations / aligned : 0.0;
  state.counters["icp_converged"] = converged;
}
BENCHMARK(BM_InitializeFit)->Unit(benchmark::kMillisecond)->UseRealTime()->Arg(0)->Arg(30);

void BM_FitQuality(benchmark::State& state) {
  KinectFixture& f = GetKinectFixture();
  const Skinning skinning(f.model);
  Eigen::MatrixX3d posed;
  skinning.Apply(f.fitted, &posed);
  FitQuality q;
  for (auto _ : state) {
    q = EvaluateFitQuality(posed, f.model.triangles, f.data.scans[0], f.data.depth_camera,
                           FitQualityOptions());
    benchmark::DoNotOptimize(q);
  }
  state.counters["inlier_fraction"] = q.inlier_fraction;
  state.counters["support_fraction"] = q.support_fraction;
  state.counters["depth_residual_mm"] = 1e3 * q.depth_residual_m;
  state.counters["scan_points"] = f.data.scans[0].size();
}
BENCHMARK(BM_FitQuality)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace artex
