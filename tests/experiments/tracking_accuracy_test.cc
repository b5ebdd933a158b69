// End-to-end tracking accuracy on the virtual Kinect (docs/design.md "Ground truth";
// docs/results-tracking.md): for each built-in motion (walk, arm_raise, turn, bend) a 60-frame
// sequence with default sensor noise and a subject shaped differently from the template is
// synthesised once per process and tracked by RunPipeline with configs/default.yaml (texturing
// off): Gauss-Newton and Ceres LM must stay within 15 mm mean vertex error without a lost frame
// (mean vertex error > 50 mm); the one-to-one (articulated ICP) baseline is run and reported.
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "experiments/config.h"
#include "experiments/pipeline.h"
#include "models/template_generator.h"
#include "sensors/motion.h"
#include "sensors/virtual_kinect.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

constexpr int kFrames = 60;
constexpr double kMaxMeanErrorMm = 15.0;

// The synthesis of the test sequences: the default virtual Kinect (640 x 480 depth, default
// noise, default subject shape), except a small colour camera (same aspect as the default
// 800 x 1016) and subject texture, since tracking runs with texturing off and never reads them.
SynthOptions TestSynthOptions(const std::string& motion) {
  SynthOptions options;
  options.motion.type = ParseMotionType(motion);
  options.motion.frames = kFrames;
  options.kinect.SetNoiseLevel(NoiseLevel::kDefault);
  options.kinect.color_width = 160;
  options.kinect.color_height = 204;
  options.texture.size = 512;
  return options;
}

// One row of the results table.
struct Measurement {
  std::string motion, variant;
  PipelineResult result;
  double seconds = 0.0;
};

// Per-process temporary folder with lazily synthesised sequences (one per motion, shared by all
// tests of the process) and the collected measurements, printed as a table at the end.
class TrackingEnvironment : public ::testing::Environment {
 public:
  void TearDown() override {
    if (!measurements_.empty()) {
      std::printf(
          "\n| motion | variant | mean vertex error (mm) | max (mm) | joint error (mm) | "
          "lost | EM iterations | fit ms/frame | run s |\n|---|---|---|---|---|---|---|---|---|\n");
      for (const Measurement& m : measurements_) {
        std::printf("| %s | %s | %.2f | %.1f | %.1f | %.1f%% | %.1f | %.0f | %.1f |\n",
                    m.motion.c_str(), m.variant.c_str(), m.result.mean_vertex_error_mm,
                    m.result.max_vertex_error_mm, m.result.mean_joint_error_mm,
                    100.0 * m.result.lost_fraction, m.result.mean_em_iterations,
                    m.result.fit_ms_per_frame, m.seconds);
      }
      std::fflush(stdout);
    }
    std::error_code ec;
    if (!root_.empty()) fs::remove_all(root_, ec);
  }

  const fs::path& root() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (root_.empty()) {
      root_ = fs::temp_directory_path() / ("artex_tracking_accuracy_" + std::to_string(::getpid()));
      fs::remove_all(root_);
      fs::create_directories(root_);
    }
    return root_;
  }

  // The sequence folder of `motion`, synthesised on first use.
  std::string Sequence(const std::string& motion) {
    const fs::path dir = root() / ("seq_" + motion);
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = sequences_.find(motion);
    if (it != sequences_.end()) return it->second;
    const SynthSummary summary = SynthesizeSequence(TestSynthOptions(motion), dir.string());
    std::printf("[synth] %s: %d frames in %.1f s (%.0f ms/frame)\n", motion.c_str(), summary.frames,
                summary.total_seconds, summary.ms_per_frame());
    sequences_[motion] = dir.string();
    return dir.string();
  }

  void Record(const Measurement& m) {
    std::lock_guard<std::mutex> lock(mutex_);
    measurements_.push_back(m);
  }

 private:
  std::mutex mutex_;
  fs::path root_;
  std::map<std::string, std::string> sequences_;
  std::vector<Measurement> measurements_;
};

TrackingEnvironment* const g_env =
    static_cast<TrackingEnvironment*>(::testing::AddGlobalTestEnvironment(new TrackingEnvironment));

// configs/default.yaml with texturing off and the given overrides ("key=value").
Config DefaultConfig(const std::vector<std::pair<std::string, std::string>>& overrides) {
  Config config = Config::Load(std::string(ARTEX_SOURCE_DIR) + "/configs/default.yaml");
  config.Set("pipeline.texture", "false");
  for (const auto& [key, value] : overrides) config.Set(key, value);
  return config;
}

PipelineResult Track(const std::string& motion, const std::string& variant,
                     const std::vector<std::pair<std::string, std::string>>& overrides) {
  const std::string sequence = g_env->Sequence(motion);
  const Config config = DefaultConfig(overrides);
  const PipelineOptions options = LoadPipelineOptions(config);
  const fs::path out = g_env->root() / ("out_" + motion + "_" + variant);
  const auto start = std::chrono::steady_clock::now();
  Measurement m;
  m.motion = motion;
  m.variant = variant;
  m.result = RunPipeline(sequence, "", options, config, out.string());
  m.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "[track] %-9s %-12s mean %.2f mm, max %.1f mm, joints %.1f mm, lost %.1f%%, "
      "%.1f EM iterations, %.0f ms/frame fitting\n",
      motion.c_str(), variant.c_str(), m.result.mean_vertex_error_mm, m.result.max_vertex_error_mm,
      m.result.mean_joint_error_mm, 100.0 * m.result.lost_fraction, m.result.mean_em_iterations,
      m.result.fit_ms_per_frame);
  std::fflush(stdout);
  g_env->Record(m);
  ::testing::Test::RecordProperty(variant + "_mean_vertex_error_mm",
                                  std::to_string(m.result.mean_vertex_error_mm));
  ::testing::Test::RecordProperty(variant + "_lost_fraction",
                                  std::to_string(m.result.lost_fraction));
  return m.result;
}

// Every frame read, fitted and evaluated against the ground truth.
void ExpectComplete(const PipelineResult& r) {
  EXPECT_TRUE(r.has_ground_truth);
  EXPECT_EQ(static_cast<int>(r.frames.size()), kFrames);
  EXPECT_EQ(r.skipped_frames, 0);
  for (const FrameRecord& f : r.frames) {
    EXPECT_FALSE(f.skipped) << "frame " << f.frame;
    EXPECT_TRUE(std::isfinite(f.mean_vertex_error_mm)) << "frame " << f.frame;
  }
}

void ExpectTracked(const PipelineResult& r) {
  ExpectComplete(r);
  EXPECT_LE(r.mean_vertex_error_mm, kMaxMeanErrorMm);
  EXPECT_EQ(r.lost_fraction, 0.0);
  for (const FrameRecord& f : r.frames) {
    EXPECT_LE(f.mean_vertex_error_mm, 50.0) << "frame " << f.frame << " lost";
    EXPECT_TRUE(f.fit.ok()) << "frame " << f.frame << " flagged: " << f.fit.BriefReport();
  }
}

TEST(TrackingSetupTest, SubjectShapeDiffersFromTheTemplate) {
  const BodyShapeOptions subject = DefaultSubjectShape();
  const BodyShapeOptions tmpl;
  EXPECT_NE(subject.height, tmpl.height);
  EXPECT_NE(subject.girth, tmpl.girth);
  const SynthOptions options = TestSynthOptions("walk");
  EXPECT_EQ(options.kinect.depth_intrinsics.width, 640);
  EXPECT_EQ(options.kinect.depth_intrinsics.height, 480);
  EXPECT_EQ(options.motion.frames, kFrames);
  // The default noise preset is the one synthesised.
  VirtualKinectOptions preset;
  preset.SetNoiseLevel(NoiseLevel::kDefault);
  EXPECT_EQ(options.kinect.depth_noise.disparity_noise_px, preset.depth_noise.disparity_noise_px);
  EXPECT_GT(options.kinect.depth_noise.disparity_noise_px, 0.0);
  EXPECT_TRUE(options.kinect.depth_noise.projector_shadow);
}

class TrackingAccuracyTest : public ::testing::TestWithParam<std::string> {};

TEST_P(TrackingAccuracyTest, GaussNewtonAndCeresTrackOneToOneIsReported) {
  const std::string motion = GetParam();
  {
    SCOPED_TRACE(motion + ", default configuration (Gauss-Newton)");
    ExpectTracked(Track(motion, "gauss_newton", {}));
  }
  {
    SCOPED_TRACE(motion + ", fitting.solver: ceres_lm");
    ExpectTracked(Track(motion, "ceres_lm", {{"fitting.solver", "ceres_lm"}}));
  }
  {
    // The baseline is measured, not required to track (docs/results-tracking.md).
    SCOPED_TRACE(motion + ", fitting.correspondence: one_to_one");
    const PipelineResult r =
        Track(motion, "one_to_one", {{"fitting.correspondence", "one_to_one"}});
    ExpectComplete(r);
    EXPECT_TRUE(std::isfinite(r.mean_vertex_error_mm));
    EXPECT_GE(r.lost_fraction, 0.0);
    EXPECT_LE(r.lost_fraction, 1.0);
  }
}

INSTANTIATE_TEST_SUITE_P(Motions, TrackingAccuracyTest,
                         ::testing::Values("walk", "arm_raise", "turn", "bend"),
                         [](const ::testing::TestParamInfo<std::string>& info) {
                           return info.param;
                         });

}  // namespace
}  // namespace artex
