// The ground-truth evaluation's texture quality (experiments/texture_evaluation.h) at the
// benchmark walk's settings (bench/track_realtime.py --color-size 640x480): the default template
// posed by a walk, seen by the virtual Kinect's colour camera at 640 x 480, textured into the
// default 1024^2 atlas over kWarmupFrames frames. Every pipeline.texture_quality_every-th frame
// the texture stage composes the atlas (Texturer::Atlas) and the evaluation's thread renders
// the truth and the model from each held-out view and compares them.
//
// Freed memory is kept for reuse as in a tracking run (RetainFreedHeap, pipeline.heap_retain_mb).
//
// BM_ComposeAtlas/<threads>: Texturer::Atlas (seams levelled already) on 1 or 2 threads (the
//   texture stage runs it on oneTBB's workers): process CPU per call (counter cpu_ms; with 2
//   threads it includes oneTBB's workers waiting for work).
// BM_RenderTextured/<0 truth, 1 model>: one held-out view rendered, one thread (the evaluation's
//   thread runs its loops alone).
// BM_EvaluateNovelViews: the whole comparison of one frame (two views, four renders, PSNR and
//   SSIM), one thread. Counter psnr_db: the result.
#include <benchmark/benchmark.h>
#include <tbb/global_control.h>

#include <vector>

#include "bench/walk_sequence.h"
#include "experiments/heap_retention.h"
#include "experiments/texture_evaluation.h"
#include "texture/texture_quality.h"
#include "texture/texturer.h"

namespace artex {
namespace {

constexpr int kWarmupFrames = 10;

// The walk at 640 x 480, textured over its frames.
struct Scene {
  bench::WalkSequence walk;
  std::unique_ptr<Texturer> texturer;
  cv::Mat atlas;
  const Template& body() const { return walk.body; }
  const Eigen::MatrixX3d& posed() const { return walk.posed.back(); }  // the last frame's
};

const Scene& TexturedWalk() {
  static const Scene* scene = [] {
    RetainFreedHeap(512);  // as the pipeline (pipeline.heap_retain_mb's default)
    VirtualKinectOptions kinect_options;
    kinect_options.color_width = 640;
    kinect_options.color_height = 480;
    auto* s = new Scene;
    s->walk = bench::MakeWalk(kWarmupFrames, kinect_options);
    s->texturer = std::make_unique<Texturer>(s->body(), TexturingOptions());
    for (int f = 0; f < kWarmupFrames; ++f)
      s->texturer->AddFrame(f, s->walk.color[f], s->walk.camera, s->walk.posed[f]);
    s->atlas = s->texturer->Atlas();
    return s;
  }();
  return *scene;
}

TruthScene Truth(const Scene& s) {
  TruthScene truth;
  truth.subject = &s.body();
  truth.vertices = s.posed();
  truth.texture = s.walk.texture;
  truth.camera = s.walk.camera;
  return truth;
}

void BM_ComposeAtlas(benchmark::State& state) {
  const Scene& s = TexturedWalk();
  const tbb::global_control threads(tbb::global_control::max_allowed_parallelism,
                                    static_cast<std::size_t>(state.range(0)));
  cv::Mat atlas;
  const double cpu_start = bench::ProcessCpuSeconds();
  for (auto _ : state) {
    atlas = s.texturer->Atlas();
    benchmark::DoNotOptimize(atlas.data);
  }
  state.counters["cpu_ms"] =
      1e3 * (bench::ProcessCpuSeconds() - cpu_start) / static_cast<double>(state.iterations());
  state.counters["same_atlas"] = cv::norm(atlas, s.atlas, cv::NORM_INF) == 0.0;
}
BENCHMARK(BM_ComposeAtlas)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_RenderTextured(benchmark::State& state) {
  const Scene& s = TexturedWalk();
  const bool model = state.range(0) != 0;
  const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
  const PinholeCamera camera =
      HeldOutCameras(s.walk.camera, s.posed().colwise().mean().transpose(),
                     Eigen::Vector3d::UnitY(), HeldOutViewOptions())[0];
  const std::vector<int>& frames = s.texturer->triangle_frames();
  cv::Mat image, mask;
  for (auto _ : state) {
    if (model)
      RenderTextured(s.body(), s.posed(), s.atlas, camera, &image, &mask, &frames);
    else
      RenderTextured(s.body(), s.posed(), s.walk.texture, camera, &image, &mask);
    benchmark::DoNotOptimize(image.data);
  }
  state.counters["covered_px"] = cv::countNonZero(mask);
}
BENCHMARK(BM_RenderTextured)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_EvaluateNovelViews(benchmark::State& state) {
  const Scene& s = TexturedWalk();
  const tbb::global_control one(tbb::global_control::max_allowed_parallelism, 1);
  const TruthScene truth = Truth(s);
  NovelViewQuality quality;
  for (auto _ : state) {
    quality = EvaluateNovelViews(s.body(), s.posed(), s.atlas, s.texturer->triangle_frames(),
                                 truth, HeldOutViewOptions());
    benchmark::DoNotOptimize(quality.psnr_db);
  }
  state.counters["psnr_db"] = quality.psnr_db;
  state.counters["ssim"] = quality.ssim;
}
BENCHMARK(BM_EvaluateNovelViews)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace artex
