// The pipelined schedule of `artex track` (experiments/pipeline_stages.h): the same poses,
// labels, metrics and texture as the sequential one, with re-initialisations (doubtful, lost)
// and the colour feedback; the live mode's accounting; the bounded queue and the colour mailbox
// under concurrent use. Written to be run under ThreadSanitizer too (suite names *Pipelined*,
// *Concurrent*): no wall-clock assertions, small inputs.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "experiments/blas_threads.h"
#include "experiments/bounded_queue.h"
#include "experiments/config.h"
#include "experiments/pipeline.h"
#include "experiments/pipeline_stages.h"
#include "models/error.h"
#include "sensors/virtual_kinect.h"
#include "tests/solvers/virtual_kinect_scans.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
using testing_util::ReadFileBytes;

// ARTEX_TEST_TBB_THREADS=N limits oneTBB to N threads for the whole test. The ThreadSanitizer
// tier sets 1 for these tests: the stage threads' own synchronisation (queues, mailbox) is what
// they check, while oneTBB's hand-over of tasks started from threads outside its pool is not
// visible to TSan (libtbb is not instrumented; docs/reliability.md). The TBB loops themselves
// are checked under TSan by the texturing, E-step, skinning and MRF tests.
const std::unique_ptr<tbb::global_control> kTbbLimit = []() -> std::unique_ptr<tbb::global_control> {
  const char* value = std::getenv("ARTEX_TEST_TBB_THREADS");
  if (value == nullptr || std::atoi(value) < 1) return nullptr;
  return std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                               static_cast<size_t>(std::atoi(value)));
}();

constexpr int kFrames = 6;

// A 6-frame walk from the virtual Kinect (half-size depth camera, small colour camera, coarse
// subject) and a coarse tracking template, made once per process.
const testing_util::SequenceFixture& TestData() {
  static const testing_util::SequenceFixture data("pipelined_test",
                                                  testing_util::SmallSequenceOptions(kFrames));
  return data;
}

Config BaseConfig() {
  Config config = Config::Load(std::string(ARTEX_SOURCE_DIR) + "/configs/default.yaml");
  config.Set("texture.atlas_size", "256");
  config.Set("pipeline.texture", "true");
  config.Set("pipeline.texture_quality_every", "2");
  config.Set("pipeline.export_glb", "false");
  config.Set("pipeline.stream_estimate", "true");
  return config;
}

PipelineResult RunWith(Config config, const std::string& concurrency, const std::string& name) {
  config.Set("pipeline.concurrency", concurrency);
  const PipelineOptions options = LoadPipelineOptions(config);
  return RunPipeline(TestData().sequence, TestData().template_path, options, config,
                     (TestData().root / name).string());
}

void ExpectNear(double a, double b, const std::string& what) {
  if (std::isnan(a) || std::isnan(b)) {
    EXPECT_EQ(std::isnan(a), std::isnan(b)) << what;
  } else {
    EXPECT_NEAR(a, b, 1e-9) << what;
  }
}

// Under ThreadSanitizer (scripts/test's TSan tier) the sequential run is left out: it runs on one
// thread, so it has nothing for TSan, and the comparison with it is made by the Release build's
// run of the same tests. The pipelined run and its own checks remain (half the tier's longest
// entries).
#if defined(__SANITIZE_THREAD__)
constexpr bool kThreadSanitizer = true;
#else
constexpr bool kThreadSanitizer = false;
#endif

// Runs `config` both ways (pipelined only under TSan) and compares everything the run reports.
void ExpectSameRuns(const Config& config, const std::string& name, int* reinitialised = nullptr) {
  const PipelineResult pip = RunWith(config, "pipelined", name + "_pip");
  EXPECT_EQ(pip.realtime.concurrency, PipelineConcurrency::kPipelined);
  EXPECT_EQ(pip.realtime.frames_processed, kFrames);
  EXPECT_EQ(pip.realtime.frames_dropped, 0);
  // The five stages, and the background evaluation of the ground truth (the fixture has it).
  EXPECT_EQ(pip.realtime.evaluated_in_background,
            LoadPipelineOptions(config).realtime.evaluate_in_background);
  ASSERT_EQ(pip.realtime.stages.size(), pip.realtime.evaluated_in_background ? 6u : 5u);
  for (const StageTiming& s : pip.realtime.stages) EXPECT_EQ(s.frames, kFrames) << s.name;
  // The reader kept at most max_frames_in_flight frames read and not yet textured.
  const int in_flight = LoadPipelineOptions(config).realtime.max_frames_in_flight;
  EXPECT_GE(pip.realtime.frames_in_flight_max, 1);
  if (in_flight > 0) {
    EXPECT_LE(pip.realtime.frames_in_flight_max, in_flight);
  }
  if (reinitialised) {
    *reinitialised = 0;
    for (const FrameRecord& f : pip.frames) *reinitialised += f.reinitialised;
  }
  if (kThreadSanitizer) return;
  const PipelineResult seq = RunWith(config, "sequential", name + "_seq");
  EXPECT_EQ(seq.realtime.concurrency, PipelineConcurrency::kSequential);
  ASSERT_EQ(seq.frames.size(), pip.frames.size());
  for (size_t i = 0; i < seq.frames.size(); ++i) {
    const FrameRecord& a = seq.frames[i];
    const FrameRecord& b = pip.frames[i];
    const std::string at = name + " frame " + std::to_string(i);
    EXPECT_EQ(a.frame, b.frame) << at;
    EXPECT_EQ(a.quality.label, b.quality.label) << at;
    EXPECT_EQ(a.reinitialised, b.reinitialised) << at;
    EXPECT_EQ(a.fit.iterations, b.fit.iterations) << at;
    EXPECT_EQ(a.scan_points, b.scan_points) << at;
    ExpectNear(a.quality.score, b.quality.score, at + " quality score");
    ExpectNear(a.mean_vertex_error_mm, b.mean_vertex_error_mm, at + " vertex error");
    ExpectNear(a.mean_joint_error_mm, b.mean_joint_error_mm, at + " joint error");
    EXPECT_EQ(a.texture.pool_size, b.texture.pool_size) << at;
    ExpectNear(a.texture_quality.psnr_db, b.texture_quality.psnr_db, at + " PSNR");
  }
  EXPECT_EQ(seq.good_frames, pip.good_frames);
  EXPECT_EQ(seq.doubtful_frames, pip.doubtful_frames);
  EXPECT_EQ(seq.lost_frames, pip.lost_frames);
  EXPECT_EQ(seq.initialisations, pip.initialisations);
  ExpectNear(seq.mean_vertex_error_mm, pip.mean_vertex_error_mm, name + " mean vertex error");
  ExpectNear(seq.mean_novel_view_psnr_db, pip.mean_novel_view_psnr_db, name + " mean PSNR");
  EXPECT_EQ(seq.stream_kbit_per_s, pip.stream_kbit_per_s);
  // Poses as written (17 significant digits) and the atlas, byte for byte.
  const fs::path root = TestData().root;
  EXPECT_EQ(ReadFileBytes(root / (name + "_seq") / "poses.csv"),
            ReadFileBytes(root / (name + "_pip") / "poses.csv"));
  EXPECT_EQ(ReadFileBytes(root / (name + "_seq") / "texture.png"),
            ReadFileBytes(root / (name + "_pip") / "texture.png"));
}

TEST(PipelinedTrackingTest, SameAsSequentialWithDefaultOptions) {
  Config config = BaseConfig();
  ExpectSameRuns(config, "default");
}

TEST(PipelinedTrackingTest, SameAsSequentialWithoutColourDelayAndDepthOneQueues) {
  Config config = BaseConfig();
  config.Set("pipeline.colour_delay_frames", "0");
  config.Set("pipeline.queue_depth", "1");
  ExpectSameRuns(config, "nodelay");
}

// One frame in flight (the stages take turns) and none limited but by the queues.
TEST(PipelinedTrackingTest, SameAsSequentialWithOneOrUnlimitedFramesInFlight) {
  Config config = BaseConfig();
  config.Set("pipeline.max_frames_in_flight", "1");
  ExpectSameRuns(config, "in_flight_1");
  config.Set("pipeline.max_frames_in_flight", "0");
  ExpectSameRuns(config, "in_flight_0");
}

TEST(PipelinedTrackingTest, SameAsSequentialWithDoubtfulReinitialisations) {
  // Every frame doubtful (a strict residual for good): re-initialised in place every 2nd.
  Config config = BaseConfig();
  config.Set("fitting.quality.good_max_depth_residual", "0.001");
  config.Set("pipeline.reinitialise_after_doubtful", "2");
  // Without the neck/head coupling (fitting.joint_coupling): with it only the first frame of
  // this sequence counts as re-initialised, and this test needs an in-place one too.
  config.Set("fitting.joint_coupling.weight", "0");
  int reinitialised = 0;
  ExpectSameRuns(config, "doubtful", &reinitialised);
  EXPECT_GE(reinitialised, 2);  // the first frame and at least one in place
}

TEST(PipelinedTrackingTest, SameAsSequentialWithLostFrames) {
  // Every frame lost (strict residual): subject reset, re-segmented and initialised again.
  Config config = BaseConfig();
  config.Set("fitting.quality.good_max_depth_residual", "0.001");
  config.Set("fitting.quality.lost_max_depth_residual", "0.002");
  config.Set("pipeline.max_frames", "3");
  const PipelineResult seq = RunWith(config, "sequential", "lost_seq");
  const PipelineResult pip = RunWith(config, "pipelined", "lost_pip");
  ASSERT_EQ(seq.frames.size(), 3u);
  ASSERT_EQ(pip.frames.size(), 3u);
  EXPECT_EQ(seq.lost_frames, 3);
  EXPECT_EQ(pip.lost_frames, seq.lost_frames);
  EXPECT_EQ(pip.initialisations, seq.initialisations);
  for (size_t i = 0; i < seq.frames.size(); ++i) {
    ExpectNear(seq.frames[i].mean_vertex_error_mm, pip.frames[i].mean_vertex_error_mm,
               "lost frame " + std::to_string(i));
    EXPECT_EQ(seq.frames[i].scan_points, pip.frames[i].scan_points);
  }
  EXPECT_EQ(ReadFileBytes(TestData().root / "lost_seq" / "poses.csv"),
            ReadFileBytes(TestData().root / "lost_pip" / "poses.csv"));
}

TEST(PipelinedTrackingTest, TexturesEveryNthFrameWithTextureEvery) {
  // Every frame good or doubtful (none lost): frames 0, 2, 4 are textured, 1, 3, 5 are not due.
  Config config = BaseConfig();
  config.Set("pipeline.texture_every", "2");
  ExpectSameRuns(config, "every2");
  const PipelineResult run = RunWith(config, "pipelined", "every2_check");
  ASSERT_EQ(run.frames.size(), static_cast<size_t>(kFrames));
  int pooled = 0;
  for (const FrameRecord& f : run.frames) {
    ASSERT_NE(f.quality.label, FitQualityLabel::kLost) << f.frame;
    const bool due = f.frame % 2 == 0;
    EXPECT_EQ(f.texture_not_due, !due) << f.frame;
    EXPECT_EQ(f.texture.image_added, due) << f.frame;
    pooled += f.texture.image_added;
    if (due) {
      EXPECT_EQ(f.texture.pool_size, pooled) << f.frame;
    }
  }
  EXPECT_EQ(run.realtime.frames_texture_not_due, kFrames / 2);
  // The texture of every 2nd frame is not that of every frame.
  const PipelineResult every = RunWith(BaseConfig(), "pipelined", "every1_check");
  EXPECT_NE(ReadFileBytes(TestData().root / "every1_check" / "texture.png"),
            ReadFileBytes(TestData().root / "every2_check" / "texture.png"));
  EXPECT_EQ(every.realtime.frames_texture_not_due, 0);
}

TEST(PipelinedTrackingTest, OneThreadPerStageGivesTheSameResults) {
  // pipeline.threads 1: every parallel loop on its stage's thread; the same poses and texture.
  Config config = BaseConfig();
  config.Set("pipeline.threads", "1");
  const PipelineResult one = RunWith(config, "pipelined", "threads1");
  const PipelineResult all = RunWith(BaseConfig(), "pipelined", "threads0");
  ASSERT_EQ(one.frames.size(), all.frames.size());
  for (size_t i = 0; i < one.frames.size(); ++i) {
    ExpectNear(one.frames[i].mean_vertex_error_mm, all.frames[i].mean_vertex_error_mm,
               "frame " + std::to_string(i));
  }
  const fs::path root = TestData().root;
  EXPECT_EQ(ReadFileBytes(root / "threads1" / "poses.csv"),
            ReadFileBytes(root / "threads0" / "poses.csv"));
  EXPECT_EQ(ReadFileBytes(root / "threads1" / "texture.png"),
            ReadFileBytes(root / "threads0" / "texture.png"));
}

// The ground truth evaluated on its own thread off the frame loop (the default) or in the output
// stage: the same metrics in every record and in the run's figures, and the same files.
TEST(PipelinedTrackingTest, GroundTruthEvaluatedInTheBackgroundGivesTheSameMetrics) {
  Config config = BaseConfig();
  // One frame queued: the output stage evaluates frames itself while one waits.
  config.Set("pipeline.evaluation_queue_depth", "1");
  const PipelineResult behind = RunWith(config, "pipelined", "evaluate_behind");
  config.Set("pipeline.evaluate_in_background", "false");
  const PipelineResult inline_ = RunWith(config, "pipelined", "evaluate_inline");
  EXPECT_TRUE(behind.realtime.evaluated_in_background);
  EXPECT_FALSE(inline_.realtime.evaluated_in_background);
  ASSERT_EQ(behind.realtime.stages.size(), 6u);
  EXPECT_EQ(behind.realtime.stages.back().name, "evaluate");
  EXPECT_EQ(behind.realtime.stages.back().frames, kFrames);
  EXPECT_GT(behind.realtime.stages.back().cpu_seconds, 0.0);
  EXPECT_LE(behind.realtime.evaluated_during_loop, kFrames);
  EXPECT_LE(behind.realtime.evaluated_in_output_stage, kFrames);
  EXPECT_GE(behind.realtime.evaluation_after_loop_seconds, 0.0);
  ASSERT_EQ(behind.frames.size(), inline_.frames.size());
  int textures = 0;
  for (size_t i = 0; i < behind.frames.size(); ++i) {
    const FrameRecord& a = behind.frames[i];
    const FrameRecord& b = inline_.frames[i];
    const std::string at = "frame " + std::to_string(i);
    ASSERT_TRUE(std::isfinite(a.mean_vertex_error_mm)) << at;  // merged after the loop
    EXPECT_EQ(a.mean_vertex_error_mm, b.mean_vertex_error_mm) << at;
    EXPECT_EQ(a.max_vertex_error_mm, b.max_vertex_error_mm) << at;
    EXPECT_EQ(a.mean_joint_error_mm, b.mean_joint_error_mm) << at;
    ASSERT_EQ(a.joint_errors_mm.size(), b.joint_errors_mm.size()) << at;
    for (size_t j = 0; j < a.joint_errors_mm.size(); ++j)
      ExpectNear(a.joint_errors_mm[j], b.joint_errors_mm[j], at + " joint " + std::to_string(j));
    ExpectNear(a.texture_quality.psnr_db, b.texture_quality.psnr_db, at + " PSNR");
    textures += std::isfinite(a.texture_quality.psnr_db);
  }
  EXPECT_GE(textures, 2);  // texture_quality_every 2 and the last frame
  EXPECT_EQ(behind.mean_vertex_error_mm, inline_.mean_vertex_error_mm);
  EXPECT_EQ(behind.mean_joint_error_mm, inline_.mean_joint_error_mm);
  EXPECT_EQ(behind.max_vertex_error_mm, inline_.max_vertex_error_mm);
  EXPECT_EQ(behind.mean_novel_view_psnr_db, inline_.mean_novel_view_psnr_db);
  EXPECT_EQ(behind.novel_view_psnr_db, inline_.novel_view_psnr_db);
  EXPECT_EQ(behind.lost_frames, inline_.lost_frames);
  EXPECT_EQ(behind.lost_fraction, inline_.lost_fraction);
  const fs::path root = TestData().root;
  // (frames.csv differs in its timing columns.)
  for (const char* file : {"joint_errors.csv", "poses.csv", "texture.png"}) {
    EXPECT_EQ(ReadFileBytes(root / "evaluate_behind" / file),
              ReadFileBytes(root / "evaluate_inline" / file))
        << file;
  }

  config.Set("pipeline.evaluation_queue_depth", "0");
  EXPECT_THROW(LoadPipelineOptions(config), Error);
}

// A frame whose ground truth cannot be read fails the run with the file named, as in the output
// stage, although it is found on the evaluation's thread.
TEST(PipelinedTrackingTest, BackgroundEvaluationReportsAMissingGroundTruthFile) {
  const fs::path copy = TestData().root / "missing_truth_sequence";
  if (!fs::exists(copy / "frames.csv")) {
    fs::copy(TestData().sequence, copy, fs::copy_options::recursive);
  }
  const fs::path vertices = copy / "groundtruth" / "vertices";
  ASSERT_TRUE(fs::is_directory(vertices));
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(vertices)) files.push_back(e.path());
  ASSERT_GE(files.size(), 3u);
  std::sort(files.begin(), files.end());
  fs::remove(files[2]);
  const PipelineOptions options = LoadPipelineOptions(BaseConfig());
  ASSERT_TRUE(options.realtime.evaluate_in_background);
  try {
    RunPipeline(copy.string(), TestData().template_path, options, BaseConfig(),
                (TestData().root / "missing_truth").string());
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(files[2].filename().string()), std::string::npos)
        << e.what();
  }
}

TEST(PipelinedTrackingTest, LiveModeAccountsForEveryFrame) {
  // A clock far faster than tracking: frames are dropped, never queued without bound.
  Config config = BaseConfig();
  config.Set("pipeline.live", "true");
  config.Set("pipeline.live_rate_hz", "1000");
  config.Set("pipeline.texture_quality_every", "0");
  for (const char* mode : {"pipelined", "sequential"}) {
    const PipelineResult r = RunWith(config, mode, std::string("live_") + mode);
    const RealtimeStats& s = r.realtime;
    EXPECT_TRUE(s.live);
    EXPECT_EQ(s.rate_hz, 1000.0);
    EXPECT_GE(s.frames_processed, 1) << mode;
    EXPECT_EQ(s.frames_processed + s.frames_dropped, kFrames) << mode;
    EXPECT_EQ(s.frames_offered, kFrames) << mode;
    EXPECT_EQ(static_cast<int>(r.frames.size()), s.frames_processed) << mode;
    for (size_t i = 1; i < r.frames.size(); ++i) EXPECT_LT(r.frames[i - 1].frame, r.frames[i].frame);
    // Frames left untextured because a newer one waited: counted, never the first, never in
    // the sequential schedule (one frame at a time).
    int untextured = 0;
    for (const FrameRecord& f : r.frames) untextured += f.texture_skipped;
    EXPECT_EQ(untextured, s.frames_texture_skipped) << mode;
    if (!r.frames.empty()) {
      EXPECT_FALSE(r.frames[0].texture_skipped);
    }
    if (std::string(mode) == "sequential") {
      EXPECT_EQ(untextured, 0);
    }
    EXPECT_LE(s.latency_median_ms, s.latency_p95_ms);
    EXPECT_LE(s.latency_p95_ms, s.latency_max_ms);
  }
}

TEST(PipelinedTrackingTest, LiveBacklogTracksTheFramesThatArriveDuringTheInitialisation) {
  // At 40 Hz the 6 frames arrive within 125 ms, while the first frame is initialised (~200 ms
  // here). With room for all of them (pipeline.live_init_queue_depth) every frame read is
  // tracked, in order; those with a newer frame waiting are left untextured, never the first
  // or the last. Without the option only the first, the frame read during the initialisation
  // and the newest after it are processed. Exact counts need a reader that decodes a frame
  // within its 25 ms period and an initialisation longer than the arrivals, which the run
  // measures (a sanitizer's slowdown can break the first); the accounting holds always.
  Config config = BaseConfig();
  config.Set("pipeline.live", "true");
  config.Set("pipeline.live_rate_hz", "40");
  config.Set("pipeline.texture_quality_every", "0");
  config.Set("pipeline.live_init_queue_depth", std::to_string(kFrames));
  const PipelineResult all = RunWith(config, "pipelined", "live_backlog_all");
  const RealtimeStats& s = all.realtime;
  EXPECT_EQ(s.frames_processed + s.frames_dropped, kFrames);
  ASSERT_EQ(static_cast<int>(all.frames.size()), s.frames_processed);
  ASSERT_GE(s.frames_processed, 2);
  int untextured = 0;
  for (size_t i = 0; i < all.frames.size(); ++i) {
    if (i > 0) {
      EXPECT_LT(all.frames[i - 1].frame, all.frames[i].frame);
    }
    untextured += all.frames[i].texture_skipped;
  }
  EXPECT_EQ(untextured, s.frames_texture_skipped);
  EXPECT_FALSE(all.frames.front().texture_skipped);
  EXPECT_FALSE(all.frames.back().texture_skipped);
  double read_seconds_per_frame = 1.0;
  for (const StageTiming& stage : s.stages) {
    if (stage.name == "read") read_seconds_per_frame = stage.busy_seconds / stage.frames;
  }
  const double arrivals_seconds = (kFrames - 1) / 40.0;
  if (read_seconds_per_frame < 0.02 && all.frames[0].init_seconds > arrivals_seconds + 0.02) {
    EXPECT_EQ(s.frames_processed, kFrames) << "read " << read_seconds_per_frame << " s/frame";
    EXPECT_EQ(s.frames_dropped, 0);
    EXPECT_GE(untextured, 1);
    EXPECT_EQ(all.gap_refits, 0);
  } else {
    std::cout << "[ INFO ] exact counts not checked: read " << read_seconds_per_frame
              << " s/frame, first frame's initialisation " << all.frames[0].init_seconds << " s\n";
  }

  config.Set("pipeline.live_init_queue_depth", "0");
  const PipelineResult none = RunWith(config, "pipelined", "live_backlog_none");
  EXPECT_EQ(none.realtime.frames_processed + none.realtime.frames_dropped, kFrames);
  ASSERT_FALSE(none.frames.empty());
  if (none.frames[0].init_seconds > arrivals_seconds + 0.02) {
    EXPECT_LE(none.realtime.frames_processed, 3);
  }

  config.Set("pipeline.live_init_queue_depth", "-1");
  EXPECT_THROW(LoadPipelineOptions(config), Error);
  config.Set("pipeline.live_init_queue_depth", "12");
  config.Set("pipeline.live_init_drain_every", "0");
  EXPECT_THROW(LoadPipelineOptions(config), Error);
}

// The fixture's sequence without frames 1-3 (as if a live reader had dropped them): frame 4
// follows frame 0 after a gap of 3 frames.
std::string SequenceWithAGap() {
  const fs::path gap = TestData().root / "gap_sequence";
  if (!fs::exists(gap / "frames.csv")) {
    fs::copy(TestData().sequence, gap, fs::copy_options::recursive);
    std::ifstream in(gap / "frames.csv");
    std::string line, kept;
    std::getline(in, line);
    kept = line + "\n";
    for (int row = 0; std::getline(in, line); ++row) {
      if (row < 1 || row > 3) kept += line + "\n";
    }
    in.close();
    std::ofstream(gap / "frames.csv", std::ios::trunc) << kept;
  }
  return gap.string();
}

TEST(PipelinedTrackingTest, FramesAfterAGapAreRefitted) {
  for (const int refit_after : {3, 4, 0}) {
    Config config = BaseConfig();
    config.Set("pipeline.gap_refit_frames", std::to_string(refit_after));
    const PipelineOptions options = LoadPipelineOptions(config);
    const std::string name = "gap" + std::to_string(refit_after);
    const PipelineResult r = RunPipeline(SequenceWithAGap(), TestData().template_path, options,
                                         config, (TestData().root / name).string());
    ASSERT_EQ(r.frames.size(), 3u);
    EXPECT_EQ(r.frames[0].gap_frames, 0);
    EXPECT_EQ(r.frames[1].gap_frames, 3);
    EXPECT_EQ(r.frames[2].gap_frames, 0);
    const bool refitted = refit_after == 3;
    EXPECT_EQ(r.frames[1].gap_refit, refitted) << name;
    EXPECT_FALSE(r.frames[2].gap_refit);
    EXPECT_EQ(r.gap_refits, refitted ? 1 : 0);
    EXPECT_TRUE(r.frames[1].fit.ok()) << name;
    EXPECT_NE(r.frames[1].quality.label, FitQualityLabel::kLost) << name;
    EXPECT_FALSE(r.frames[1].reinitialised) << name;
    // frames.csv says which frame was refitted after how long a gap.
    std::ifstream csv(TestData().root / name / "frames.csv");
    std::string header, first, second;
    std::getline(csv, header);
    std::getline(csv, first);
    std::getline(csv, second);
    EXPECT_NE(header.find(",gap_frames,gap_refit,texture_skipped,texture_not_due"),
              std::string::npos);
    EXPECT_EQ(second.substr(second.size() - 8), refitted ? ",3,1,0,0" : ",3,0,0,0") << second;
  }
}

TEST(PipelinedTrackingTest, RejectsInvalidOptions) {
  for (const auto& [key, value] :
       std::vector<std::pair<std::string, std::string>>{{"pipeline.queue_depth", "0"},
                                                        {"pipeline.max_frames_in_flight", "-1"},
                                                        {"pipeline.live_queue_depth", "0"},
                                                        {"pipeline.live_rate_hz", "-1"},
                                                        {"pipeline.colour_delay_frames", "-1"},
                                                        {"pipeline.gap_refit_frames", "-1"},
                                                        {"pipeline.texture_every", "0"},
                                                        {"pipeline.threads", "-1"},
                                                        {"pipeline.blas_threads", "-1"},
                                                        {"pipeline.gap_refit_radii", "[0.05, 0]"},
                                                        {"pipeline.gap_refit_iterations_per_stage", "0"}}) {
    Config config = BaseConfig();
    config.Set(key, value);
    try {
      LoadPipelineOptions(config);
      ADD_FAILURE() << key << "=" << value << " accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
    }
  }
  Config config = BaseConfig();
  config.Set("pipeline.concurrency", "parallel");
  EXPECT_ANY_THROW(LoadPipelineOptions(config));
}

TEST(ConcurrentQueueTest, KeepsOrderBetweenThreadsAndBoundsItsSize) {
  BoundedQueue<int> queue(3);
  constexpr int kItems = 2000;
  std::thread producer([&] {
    for (int i = 0; i < kItems; ++i) ASSERT_TRUE(queue.Push(int(i)));
    queue.Close();
  });
  std::vector<int> got;
  int item = 0;
  while (queue.Pop(&item)) got.push_back(item);
  producer.join();
  ASSERT_EQ(static_cast<int>(got.size()), kItems);
  for (int i = 0; i < kItems; ++i) EXPECT_EQ(got[i], i);
  EXPECT_FALSE(queue.Push(1));  // closed
}

TEST(ConcurrentQueueTest, DroppingOldestKeepsTheNewest) {
  BoundedQueue<int> queue(2);
  EXPECT_EQ(queue.PushDroppingOldest(1), 0);
  EXPECT_EQ(queue.PushDroppingOldest(2), 0);
  EXPECT_EQ(queue.PushDroppingOldest(3), 1);
  EXPECT_FALSE(queue.TryPush(4));
  int item = 0;
  ASSERT_TRUE(queue.Pop(&item));
  EXPECT_EQ(item, 2);
  ASSERT_TRUE(queue.Pop(&item));
  EXPECT_EQ(item, 3);
  queue.Close();
  EXPECT_FALSE(queue.Pop(&item));
  EXPECT_EQ(queue.PushDroppingOldest(5), 1);
}

TEST(ConcurrentQueueTest, ALimitBelowTheCapacityKeepsFewer) {
  BoundedQueue<int> queue(4);
  EXPECT_EQ(queue.PushDroppingOldest(1, 4), 0);
  EXPECT_EQ(queue.PushDroppingOldest(2, 4), 0);
  EXPECT_EQ(queue.PushDroppingOldest(3, 4), 0);
  EXPECT_EQ(queue.PushDroppingOldest(4, 2), 2);  // 1 and 2 dropped: room for one under 2
  EXPECT_EQ(queue.size(), 2u);
  EXPECT_EQ(queue.PushDroppingOldest(5, 9), 0);  // a limit above the capacity is the capacity
  EXPECT_EQ(queue.PushDroppingOldest(6, 9), 0);
  EXPECT_EQ(queue.PushDroppingOldest(7, 9), 1);  // 3 dropped
  int item = 0;
  for (int expected : {4, 5, 6}) {
    ASSERT_TRUE(queue.Pop(&item));
    EXPECT_EQ(item, expected);
  }
  EXPECT_EQ(queue.size(), 1u);  // 7
  EXPECT_TRUE(queue.WaitUntilBelow(2));  // returns at once: 1 < 2
  std::atomic<bool> returned{false};
  std::thread waiter([&] { returned = queue.WaitUntilBelow(1); });
  ASSERT_TRUE(queue.Pop(&item));
  EXPECT_EQ(item, 7);
  waiter.join();
  EXPECT_TRUE(returned.load());
}

TEST(ConcurrentQueueTest, CloseWakesABlockedProducer) {
  BoundedQueue<int> queue(1);
  ASSERT_TRUE(queue.Push(1));
  std::atomic<bool> refused{false};
  std::thread producer([&] { refused = !queue.Push(2); });
  queue.Close();
  producer.join();
  EXPECT_TRUE(refused.load());
}

// The live backlog's room: init_depth until the first frame is tracked, then never more than
// the frames waiting plus one, falling by one every drain_every frames read, over once it is
// down to live_depth.
TEST(ConcurrentQueueTest, LiveBacklogShrinksUntilTheTrackerCatchesUp) {
  // A tracker that does not catch up (9 frames always waiting): the room falls by one every
  // third frame read and the backlog ends within init_depth * drain_every reads.
  LiveBacklog slow(1, 12, 3);
  ASSERT_TRUE(slow.active());
  for (int i = 0; i < 5; ++i) EXPECT_EQ(slow.Room(false, 12), 12u);  // initialising
  std::vector<std::size_t> rooms;
  while (slow.active() && rooms.size() < 100) rooms.push_back(slow.Room(true, 9));
  ASSERT_FALSE(slow.active());
  EXPECT_LE(rooms.size(), 36u);
  ASSERT_GE(rooms.size(), 4u);
  EXPECT_EQ(rooms[0], 10u);  // the frames waiting plus the one read
  EXPECT_EQ(rooms[1], 10u);
  EXPECT_EQ(rooms[2], 10u);
  EXPECT_EQ(rooms[3], 9u);  // the third read after the first
  for (std::size_t k = 1; k < rooms.size(); ++k) EXPECT_LE(rooms[k], rooms[k - 1]);
  EXPECT_EQ(rooms.back(), 1u);
  EXPECT_EQ(slow.Room(true, 9), 1u);  // over: live_depth from now on

  // drain_every 1: by one per frame read.
  LiveBacklog fast_drain(1, 12, 1);
  EXPECT_EQ(fast_drain.Room(true, 9), 10u);
  EXPECT_EQ(fast_drain.Room(true, 9), 9u);
  EXPECT_EQ(fast_drain.Room(true, 9), 8u);

  // A tracker that catches up: the room follows the frames waiting down and the backlog ends
  // as soon as none waits; it does not grow again when frames pile up later.
  LiveBacklog quick(1, 12, 3);
  EXPECT_EQ(quick.Room(true, 8), 9u);
  EXPECT_EQ(quick.Room(true, 4), 5u);
  EXPECT_EQ(quick.Room(true, 7), 5u);
  EXPECT_TRUE(quick.active());
  EXPECT_EQ(quick.Room(true, 0), 1u);
  EXPECT_FALSE(quick.active());

  // No backlog asked for (init_depth at most live_depth): never active.
  LiveBacklog none(2, 0, 3);
  EXPECT_FALSE(none.active());
  EXPECT_EQ(none.Room(false, 5), 2u);
}

// A producer acquires before each item and the consumer releases after it: never more than
// the limit out at once, the limit reached, and Close wakes a blocked Acquire.
TEST(ConcurrentQueueTest, InFlightLimitBoundsTheItemsOut) {
  InFlightLimit limit(2);
  BoundedQueue<int> queue(8);  // roomier than the limit: the limit alone bounds
  std::atomic<int> out{0}, most{0};
  constexpr int kItems = 500;
  std::thread producer([&] {
    for (int i = 0; i < kItems; ++i) {
      ASSERT_TRUE(limit.Acquire());
      const int now = ++out;
      int seen = most.load();
      while (now > seen && !most.compare_exchange_weak(seen, now)) {
      }
      ASSERT_TRUE(queue.Push(int(i)));
    }
    queue.Close();
  });
  int item = 0, count = 0;
  while (queue.Pop(&item)) {
    EXPECT_EQ(item, count++);
    --out;
    limit.Release();
  }
  producer.join();
  EXPECT_EQ(count, kItems);
  EXPECT_LE(most.load(), 2);
  EXPECT_LE(limit.peak(), 2u);

  // Two out: a third Acquire waits for a Release.
  InFlightLimit two(2);
  ASSERT_TRUE(two.Acquire());
  ASSERT_TRUE(two.Acquire());
  EXPECT_EQ(two.peak(), 2u);
  std::atomic<bool> third{false};
  std::thread waiter([&] { third = two.Acquire(); });
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_FALSE(third.load());
  two.Release();
  waiter.join();
  EXPECT_TRUE(third.load());
  EXPECT_EQ(two.peak(), 2u);

  InFlightLimit one(1);
  ASSERT_TRUE(one.Acquire());
  std::atomic<bool> refused{false};
  std::thread blocked([&] { refused = !one.Acquire(); });
  one.Close();
  blocked.join();
  EXPECT_TRUE(refused.load());

  InFlightLimit none(0);  // no limit
  for (int i = 0; i < 10; ++i) EXPECT_TRUE(none.Acquire());
  EXPECT_EQ(none.peak(), 10u);
}

// pipeline.blas_threads (experiments/blas_threads.h): where the process has OpenBLAS (the
// system BLAS that OpenCV's LAPACK links on Debian), one thread ends the pool it started when
// loaded: its threads leave the process. 0 changes nothing. (RunPipeline applies the option;
// a test run before this one in the same process leaves one thread and no pool.)
TEST(BlasThreadsTest, OneThreadEndsOpenBlasPool) {
  const int before = BlasThreads();
  if (before == 0) GTEST_SKIP() << "no OpenBLAS in this process";
  const auto threads = [] {
    return std::distance(fs::directory_iterator("/proc/self/task"), fs::directory_iterator());
  };
  EXPECT_FALSE(LimitBlasThreads(0));
  EXPECT_EQ(BlasThreads(), before);
  const long tasks = threads();
  ASSERT_TRUE(LimitBlasThreads(1));
  EXPECT_EQ(BlasThreads(), 1);
  // The pool had one thread per core beyond the caller's.
  EXPECT_LE(threads(), tasks - (before - 1)) << before << " OpenBLAS threads before";
}

TEST(ConcurrentColourMailboxTest, TakesTheNewestColoursUpToTheAskedFrame) {
  ColourMailbox mailbox;
  std::thread poster([&] {
    for (int n = 0; n < 50; ++n) {
      Eigen::MatrixX3d c = Eigen::MatrixX3d::Constant(2, 3, n);
      mailbox.Post(n, c, n % 3 == 0);  // colours change at 0, 3, 6, ...
    }
  });
  Eigen::MatrixX3d colours;
  ASSERT_TRUE(mailbox.WaitAndTake(4, &colours));  // waits for item 4: newest change is 3
  EXPECT_EQ(colours(0, 0), 3.0);
  EXPECT_FALSE(mailbox.WaitAndTake(5, &colours));  // nothing new up to 5
  ASSERT_TRUE(mailbox.WaitAndTake(49, &colours));
  EXPECT_EQ(colours(0, 0), 48.0);
  poster.join();
  mailbox.Abort();
  EXPECT_FALSE(mailbox.WaitAndTake(100, &colours));  // aborted: no wait
}

}  // namespace
}  // namespace artex
