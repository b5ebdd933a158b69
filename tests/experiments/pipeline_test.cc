// RunPipeline and `artex track` end to end on a short synthetic sequence (experiments/pipeline.h):
// output files and their contents, determinism, configuration errors, unreadable frames, and
// the command line's exit status. Accuracy on full sequences: tracking_accuracy_test.cc.
#include "experiments/pipeline.h"

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "experiments/config.h"
#include "experiments/pose_csv.h"
#include "models/error.h"
#include "models/skinning.h"
#include "models/template_generator.h"
#include "models/template_io.h"
#include "sensors/sequence.h"
#include "sensors/virtual_kinect.h"
#include "tests/error_of.h"
#include "tests/solvers/virtual_kinect_scans.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
using testing_util::ReadFileBytes;

constexpr int kFrames = 6;
constexpr int kAtlasSize = 256;

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::stringstream s(text);
  std::string line;
  while (std::getline(s, line)) {
    if (!line.empty()) lines.push_back(line);
  }
  return lines;
}

std::vector<std::string> Fields(const std::string& line) {
  std::vector<std::string> fields;
  std::stringstream s(line);
  std::string f;
  while (std::getline(s, f, ',')) fields.push_back(f);
  return fields;
}

// Per-process fixture data: a 6-frame walk from the virtual Kinect (default noise, half-size
// depth camera, small colour camera, coarse subject) and a coarse tracking template, made once.
const testing_util::SequenceFixture& TestData() {
  static const testing_util::SequenceFixture data("pipeline_test",
                                                  testing_util::SmallSequenceOptions(kFrames));
  return data;
}

// The default configuration with a small texture atlas (texturing on).
Config SmallConfig() {
  Config config = Config::Load(std::string(ARTEX_SOURCE_DIR) + "/configs/default.yaml");
  config.Set("texture.atlas_size", std::to_string(kAtlasSize));
  config.Set("pipeline.texture", "true");
  return config;
}

PipelineResult Track(const std::string& sequence, const std::string& out,
                     const Config& config = SmallConfig()) {
  const PipelineOptions options = LoadPipelineOptions(config);
  return RunPipeline(sequence, TestData().template_path, options, config, out);
}

fs::path OutDir(const std::string& name) { return TestData().root / name; }

// One complete run, shared by the output checks.
const PipelineResult& FirstRun() {
  static const PipelineResult result = Track(TestData().sequence, OutDir("run_a").string());
  return result;
}

TEST(PipelineTest, ResultCoversEveryFrameWithFiniteErrors) {
  const PipelineResult& r = FirstRun();
  ASSERT_EQ(static_cast<int>(r.frames.size()), kFrames);
  EXPECT_EQ(r.skipped_frames, 0);
  EXPECT_TRUE(r.has_ground_truth);
  EXPECT_TRUE(r.warnings.empty());
  for (int i = 0; i < kFrames; ++i) {
    const FrameRecord& f = r.frames[i];
    EXPECT_EQ(f.frame, i);
    EXPECT_FALSE(f.skipped);
    EXPECT_GT(f.scan_points, 100);
    EXPECT_TRUE(f.fit.ok()) << f.fit.BriefReport();
    EXPECT_TRUE(std::isfinite(f.mean_vertex_error_mm));
    EXPECT_GE(f.max_vertex_error_mm, f.mean_vertex_error_mm);
    EXPECT_TRUE(std::isfinite(f.mean_joint_error_mm));
    EXPECT_GT(f.texture.pool_size, 0) << "frame " << i << ": " << f.quality.BriefReport()
                                      << ", error " << f.mean_vertex_error_mm << " mm";
    EXPECT_NE(f.quality.label, FitQualityLabel::kLost) << f.quality.BriefReport();
  }
  // Coarse template and subject, half-size depth: tracked, not lost.
  EXPECT_LT(r.mean_vertex_error_mm, 30.0);
  EXPECT_EQ(r.lost_fraction, 0.0);
  EXPECT_GT(r.mean_em_iterations, 0.0);
  EXPECT_GT(r.texture_ms_per_frame, 0.0);
  EXPECT_TRUE(std::isnan(r.stream_kbit_per_s));  // pipeline.stream_estimate is off
}

TEST(PipelineTest, StreamEstimateOnRequest) {
  Config config = SmallConfig();
  config.Set("pipeline.stream_estimate", "true");
  config.Set("pipeline.max_frames", "2");
  const PipelineResult r = Track(TestData().sequence, OutDir("stream_estimate").string(), config);
  EXPECT_GT(r.stream_kbit_per_s, 0.0);
  EXPECT_TRUE(std::isfinite(r.stream_kbit_per_s));
}

TEST(PipelineTest, PosesAndFramesCsvHaveOneRowPerFrame) {
  FirstRun();
  const fs::path out = OutDir("run_a");
  const std::vector<std::string> poses = Lines(ReadFileBytes(out / "poses.csv"));
  ASSERT_EQ(static_cast<int>(poses.size()), kFrames + 1);
  const std::vector<std::string> header = Fields(poses[0]);
  ASSERT_EQ(static_cast<int>(header.size()), 1 + 7 + 3 * kDefaultNumJoints);
  EXPECT_EQ(header[0], "frame");
  EXPECT_EQ(header[1], "scale");
  for (int i = 1; i <= kFrames; ++i) {
    const std::vector<std::string> row = Fields(poses[i]);
    ASSERT_EQ(row.size(), header.size()) << poses[i];
    EXPECT_EQ(std::stoi(row[0]), i - 1);
    Eigen::VectorXd v(static_cast<Eigen::Index>(row.size() - 1));
    for (size_t k = 1; k < row.size(); ++k) v[static_cast<Eigen::Index>(k - 1)] = std::stod(row[k]);
    EXPECT_TRUE(v.allFinite());
    EXPECT_GT(v[0], 0.5);  // scale
    EXPECT_NO_THROW(Pose::FromVector(v, kDefaultNumJoints));
  }

  const std::vector<std::string> frames = Lines(ReadFileBytes(out / "frames.csv"));
  ASSERT_EQ(static_cast<int>(frames.size()), kFrames + 1);
  const std::vector<std::string> columns = Fields(frames[0]);
  int error_column = -1;
  for (size_t c = 0; c < columns.size(); ++c) {
    if (columns[c] == "mean_vertex_error_mm") error_column = static_cast<int>(c);
  }
  ASSERT_GE(error_column, 0);
  for (int i = 1; i <= kFrames; ++i) {
    const std::vector<std::string> row = Fields(frames[i]);
    ASSERT_EQ(row.size(), columns.size()) << frames[i];
    EXPECT_EQ(std::stoi(row[0]), i - 1);
    EXPECT_NEAR(std::stod(row[error_column]), FirstRun().frames[i - 1].mean_vertex_error_mm, 1e-3);
  }
}

TEST(PipelineTest, MetricsAndSummaryJsonParse) {
  const PipelineResult& r = FirstRun();
  const fs::path out = OutDir("run_a");
  const nlohmann::json metrics = nlohmann::json::parse(ReadFileBytes(out / "metrics.json"));
  EXPECT_EQ(metrics.at("frames").get<int>(), kFrames);
  EXPECT_EQ(metrics.at("skipped_frames").get<int>(), 0);
  EXPECT_TRUE(metrics.at("has_ground_truth").get<bool>());
  for (const char* key : {"mean_vertex_error_mm", "max_vertex_error_mm", "mean_joint_error_mm",
                          "lost_fraction", "fit_ms_per_frame", "texture_ms_per_frame"}) {
    ASSERT_TRUE(metrics.at(key).is_number()) << key;
    EXPECT_TRUE(std::isfinite(metrics.at(key).get<double>())) << key;
  }
  EXPECT_NEAR(metrics.at("mean_vertex_error_mm").get<double>(), r.mean_vertex_error_mm, 1e-9);

  const nlohmann::json summary = nlohmann::json::parse(ReadFileBytes(out / "summary.json"));
  ASSERT_EQ(static_cast<int>(summary.at("frames").size()), kFrames);
  EXPECT_TRUE(summary.at("frames")[0].contains("texture"));
  // The resolved configuration reloads to the same options.
  const Config resolved = Config::Load((out / "config.yaml").string());
  const PipelineOptions options = LoadPipelineOptions(resolved);
  EXPECT_EQ(options.texturing.atlas_size, kAtlasSize);
  EXPECT_TRUE(options.texture);
}

TEST(PipelineTest, TextureAndTrackedGlbAreReadable) {
  FirstRun();
  const fs::path out = OutDir("run_a");
  const cv::Mat atlas = cv::imread((out / "texture.png").string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(atlas.empty());
  EXPECT_EQ(atlas.cols, kAtlasSize);
  EXPECT_EQ(atlas.rows, kAtlasSize);
  // Something was textured: not a single flat colour.
  cv::Scalar mean, stddev;
  cv::meanStdDev(atlas, mean, stddev);
  EXPECT_GT(stddev[0] + stddev[1] + stddev[2], 5.0);
  EXPECT_FALSE(cv::imread((out / "labels.png").string(), cv::IMREAD_UNCHANGED).empty());

  GlbTexture texture;
  const Template tracked = ReadTemplateGlb((out / "tracked.glb").string(), &texture);
  EXPECT_EQ(tracked.num_vertices(), testing_util::CoarseTemplate().num_vertices());
  EXPECT_EQ(tracked.num_joints(), kDefaultNumJoints);
  ASSERT_FALSE(texture.png.empty());
  const cv::Mat embedded = cv::imdecode(texture.png, cv::IMREAD_COLOR);
  ASSERT_FALSE(embedded.empty());
  EXPECT_EQ(embedded.cols, kAtlasSize);
  EXPECT_EQ(cv::norm(embedded, atlas, cv::NORM_INF), 0.0);
  // No per-frame meshes unless asked.
  EXPECT_FALSE(fs::exists(out / "meshes"));
}

TEST(PipelineTest, TwoRunsGiveIdenticalPoses) {
  FirstRun();
  Track(TestData().sequence, OutDir("run_b").string());
  const std::string a = ReadFileBytes(OutDir("run_a") / "poses.csv");
  const std::string b = ReadFileBytes(OutDir("run_b") / "poses.csv");
  ASSERT_FALSE(a.empty());
  EXPECT_EQ(a, b);
  EXPECT_EQ(ReadFileBytes(OutDir("run_a") / "texture.png"),
            ReadFileBytes(OutDir("run_b") / "texture.png"));
}

TEST(PipelineTest, BuiltInDefaultsAreConfigsDefaultYaml) {
  // `artex track` without -c must behave as the README's `-c configs/default.yaml`.
  Config none;
  none.Set("texture.atlas_size", std::to_string(kAtlasSize));
  Track(TestData().sequence, OutDir("run_builtin").string(), none);
  FirstRun();
  EXPECT_EQ(ReadFileBytes(OutDir("run_builtin") / "poses.csv"),
            ReadFileBytes(OutDir("run_a") / "poses.csv"));
  EXPECT_EQ(ReadFileBytes(OutDir("run_builtin") / "texture.png"),
            ReadFileBytes(OutDir("run_a") / "texture.png"));
}

TEST(PipelineTest, MissingSequenceFolderNamesIt) {
  const std::string missing = (TestData().root / "no_such_sequence").string();
  const std::string msg = ErrorOf([&] { Track(missing, OutDir("run_missing").string()); });
  EXPECT_NE(msg.find("no_such_sequence"), std::string::npos) << msg;
  EXPECT_FALSE(fs::exists(OutDir("run_missing") / "metrics.json"));
}

TEST(PipelineTest, UnknownConfigKeyListsTheValidKeys) {
  {
    const Config c = Config::FromString("fitting:\n  solverr: ceres_lm\n", "bad.yaml");
    const std::string msg = ErrorOf([&] { LoadPipelineOptions(c); });
    EXPECT_NE(msg.find("solverr"), std::string::npos) << msg;
    EXPECT_NE(msg.find("bad.yaml"), std::string::npos) << msg;
    for (const char* valid : {"solver", "correspondence", "tracking_radii", "scale_mode"})
      EXPECT_NE(msg.find(valid), std::string::npos) << valid << " missing in: " << msg;
  }
  {
    const Config c = Config::FromString("fiting:\n  solver: ceres_lm\n", "top.yaml");
    const std::string msg = ErrorOf([&] { LoadPipelineOptions(c); });
    EXPECT_NE(msg.find("fiting"), std::string::npos) << msg;
    for (const char* valid : {"preprocess", "fitting", "texture", "pipeline"})
      EXPECT_NE(msg.find(valid), std::string::npos) << valid << " missing in: " << msg;
  }
}

TEST(PipelineTest, InitialisationAndQualityKeysAreRead) {
  Config config = Config::Load(std::string(ARTEX_SOURCE_DIR) + "/configs/default.yaml");
  const PipelineOptions defaults = LoadPipelineOptions(config);
  // configs/default.yaml spells out the built-in defaults of these sections.
  EXPECT_EQ(defaults.initializer.yaws_deg, InitializerOptions().yaws_deg);
  EXPECT_EQ(defaults.initializer.arm_angles_deg, InitializerOptions().arm_angles_deg);
  EXPECT_EQ(defaults.initializer.em_candidates, InitializerOptions().em_candidates);
  EXPECT_EQ(defaults.initializer.icp.max_scan_points, InitializerOptions().icp.max_scan_points);
  EXPECT_EQ(defaults.quality.lost_max_depth_residual, FitQualityOptions().lost_max_depth_residual);
  EXPECT_EQ(defaults.fitting.scale_estimation_frames, EMFitterOptions().scale_estimation_frames);
  EXPECT_EQ(defaults.fitting.icp.scale_from_extent, false);
  EXPECT_EQ(defaults.initializer.world_up, Eigen::Vector3d::UnitY());
  config.Set("fitting.init.world_up", "[0, -1, 0]");
  config.Set("fitting.init.em_candidates", "3");
  config.Set("fitting.init.icp.max_iterations", "12");
  config.Set("fitting.quality.inlier_distance", "0.03");
  config.Set("fitting.icp_init.scale_from_extent", "true");
  config.Set("fitting.scale_estimator", "em");
  const PipelineOptions o = LoadPipelineOptions(config);
  EXPECT_EQ(o.initializer.em_candidates, 3);
  EXPECT_EQ(o.initializer.world_up, Eigen::Vector3d(0, -1, 0));
  EXPECT_EQ(o.initializer.icp.max_iterations, 12);
  EXPECT_EQ(o.quality.inlier_distance, 0.03);
  EXPECT_EQ(o.initializer.quality.inlier_distance, 0.03);  // ranks with the same options
  EXPECT_TRUE(o.fitting.icp.scale_from_extent);
  EXPECT_EQ(o.fitting.scale_estimator, ScaleEstimator::kEm);
  config.Set("fitting.init.em_candidates", "0");
  const std::string msg = ErrorOf([&] { LoadPipelineOptions(config); });
  EXPECT_NE(msg.find("em_candidates"), std::string::npos) << msg;
  const Config bad = Config::FromString("fitting:\n  quality:\n    inlier: 1\n", "q.yaml");
  const std::string msg2 = ErrorOf([&] { LoadPipelineOptions(bad); });
  EXPECT_NE(msg2.find("inlier_distance"), std::string::npos) << msg2;
}

// The shape's scan mask reads the frames' free-space maps, as the silhouette term does: the
// preprocessing builds them when either is on (the mask: shape estimated, bias correction on),
// unless preprocess.silhouette.enabled says.
TEST(PipelineTest, ShapeScanMaskBuildsTheFreeSpaceMaps) {
  const auto built = [](const std::string& yaml) {
    const Config config = Config::FromString(yaml, "shape.yaml");
    return LoadPipelineOptions(config).preprocess.silhouette.enabled;
  };
  EXPECT_FALSE(built("shape:\n  mode: bones_girth\n"));
  EXPECT_TRUE(built("fitting:\n  silhouette:\n    weight: 1.0\n"));
  EXPECT_FALSE(built("fitting:\n  silhouette:\n    weight: 1.0\n"
                     "preprocess:\n  silhouette:\n    enabled: false\n"));
  EXPECT_TRUE(built("shape:\n  mode: bones_girth\n  bias_scan_mask: true\n"));
  EXPECT_FALSE(built("shape:\n  mode: fixed\n  bias_scan_mask: true\n"));
  EXPECT_FALSE(
      built("shape:\n  mode: bones\n  bias_scan_mask: true\n  bias_correction: false\n"));
  EXPECT_FALSE(built("shape:\n  mode: bones\n  bias_scan_mask: true\n"
                     "preprocess:\n  silhouette:\n    enabled: false\n"));
  const PipelineOptions o = LoadPipelineOptions(Config::FromString(
      "shape:\n  bias_mask_tolerance: 0.05\n  bias_mask_radius_px: 2\n", "shape.yaml"));
  EXPECT_EQ(o.shape.bias_mask_tolerance, 0.05);
  EXPECT_EQ(o.shape.bias_mask_radius_px, 2);
  const Config bad = Config::FromString("shape:\n  bias_mask_radius_px: 9\n", "s.yaml");
  EXPECT_NE(ErrorOf([&] { LoadPipelineOptions(bad); }).find("bias_mask_radius_px"),
            std::string::npos);
}

TEST(PipelineTest, PredictionKeysAreReadAndTheOlderKeyMaps) {
  Config config = Config::Load(std::string(ARTEX_SOURCE_DIR) + "/configs/default.yaml");
  const PipelineOptions defaults = LoadPipelineOptions(config);
  // configs/default.yaml spells out the built-in prediction defaults.
  const PredictionOptions builtin;
  EXPECT_EQ(defaults.fitting.prediction.model, builtin.model);
  EXPECT_EQ(defaults.fitting.prediction.kalman.process_noise.joints,
            builtin.kalman.process_noise.joints);
  EXPECT_EQ(defaults.fitting.prediction.kalman.information_scale, builtin.kalman.information_scale);
  EXPECT_EQ(defaults.fitting.prediction.particle.step_scales, builtin.particle.step_scales);
  EXPECT_EQ(defaults.fitting.prediction.particle.hypotheses, builtin.particle.hypotheses);
  EXPECT_EQ(defaults.fitting.prediction.particle.accept_margin, builtin.particle.accept_margin);
  EXPECT_EQ(defaults.fitting.prediction.particle.trigger, builtin.particle.trigger);
  config.Set("fitting.prediction", "particle");
  config.Set("fitting.particle.base", "kalman");
  config.Set("fitting.particle.hypotheses", "7");
  config.Set("fitting.kalman.acceleration", "true");
  config.Set("fitting.kalman.process_noise.joints", "0.2");
  const PipelineOptions o = LoadPipelineOptions(config);
  EXPECT_EQ(o.fitting.prediction.model, PredictionModel::kParticle);
  EXPECT_EQ(o.fitting.prediction.particle.base, PredictionModel::kKalman);
  EXPECT_EQ(o.fitting.prediction.particle.hypotheses, 7);
  EXPECT_TRUE(o.fitting.prediction.kalman.acceleration);
  EXPECT_EQ(o.fitting.prediction.kalman.process_noise.joints, 0.2);
  // The older boolean: false = previous pose, true = constant velocity; a contradiction fails.
  const Config old =
      Config::FromString("fitting:\n  constant_velocity_prediction: false\n", "o.yaml");
  EXPECT_EQ(LoadPipelineOptions(old).fitting.prediction.model, PredictionModel::kPrevious);
  const Config both = Config::FromString(
      "fitting:\n  constant_velocity_prediction: true\n  prediction: kalman\n", "b.yaml");
  const std::string msg = ErrorOf([&] { LoadPipelineOptions(both); });
  EXPECT_NE(msg.find("constant_velocity_prediction"), std::string::npos) << msg;
  const Config bad = Config::FromString("fitting:\n  prediction: magic\n", "p.yaml");
  const std::string msg2 = ErrorOf([&] { LoadPipelineOptions(bad); });
  EXPECT_NE(msg2.find("kalman"), std::string::npos) << msg2;
  const Config base = Config::FromString("fitting:\n  particle: {base: particle}\n", "q.yaml");
  const std::string msg3 = ErrorOf([&] { LoadPipelineOptions(base); });
  EXPECT_NE(msg3.find("particle.base"), std::string::npos) << msg3;
}

TEST(PipelineTest, WrongTypeNamesFileAndKey) {
  const Config c = Config::FromString("texture:\n  atlas_size: large\n", "typed.yaml");
  const std::string msg = ErrorOf([&] { LoadPipelineOptions(c); });
  EXPECT_NE(msg.find("typed.yaml"), std::string::npos) << msg;
  EXPECT_NE(msg.find("texture.atlas_size"), std::string::npos) << msg;
  EXPECT_NE(msg.find("large"), std::string::npos) << msg;

  const Config b = Config::FromString("pipeline:\n  texture: [1, 2]\n", "typed.yaml");
  const std::string msg2 = ErrorOf([&] { LoadPipelineOptions(b); });
  EXPECT_NE(msg2.find("typed.yaml"), std::string::npos) << msg2;
  EXPECT_NE(msg2.find("pipeline.texture"), std::string::npos) << msg2;
}

TEST(PipelineTest, InvalidOptionValuesAreRejected) {
  {
    const Config c = Config::FromString("fitting:\n  solver: newton\n", "v.yaml");
    const std::string msg = ErrorOf([&] { LoadPipelineOptions(c); });
    EXPECT_NE(msg.find("newton"), std::string::npos) << msg;
    EXPECT_NE(msg.find("gauss_newton"), std::string::npos) << msg;
    EXPECT_NE(msg.find("ceres_lm"), std::string::npos) << msg;
  }
  {
    const Config c = Config::FromString("texture:\n  solver: simulated_annealing\n", "v.yaml");
    const std::string msg = ErrorOf([&] { LoadPipelineOptions(c); });
    EXPECT_NE(msg.find("simulated_annealing"), std::string::npos) << msg;
    EXPECT_NE(msg.find("alpha_expansion"), std::string::npos) << msg;
  }
  {
    const Config c = Config::FromString("pipeline:\n  lost_threshold_mm: -5\n", "v.yaml");
    const std::string msg = ErrorOf([&] { LoadPipelineOptions(c); });
    EXPECT_NE(msg.find("lost_threshold_mm"), std::string::npos) << msg;
    EXPECT_NE(msg.find("-5"), std::string::npos) << msg;
  }
  {
    const Config c = Config::FromString("fitting:\n  max_iterations: 0\n", "v.yaml");
    const std::string msg = ErrorOf([&] { LoadPipelineOptions(c); });
    EXPECT_NE(msg.find("max_iterations"), std::string::npos) << msg;
  }
  // Invalid options passed directly are rejected before any output is written.
  PipelineOptions options;
  options.max_frames = -1;
  const std::string msg = ErrorOf([&] {
    RunPipeline(TestData().sequence, "", options, Config(), OutDir("run_invalid").string());
  });
  EXPECT_NE(msg.find("max_frames"), std::string::npos) << msg;
  EXPECT_FALSE(fs::exists(OutDir("run_invalid")));
}

TEST(PipelineTest, UnreadableFramesAreSkippedWarnedAndCounted) {
  const fs::path copy = OutDir("sequence_damaged");
  fs::copy(TestData().sequence, copy, fs::copy_options::recursive);
  // Frame 2 without its colour image, frame 4 without its depth image (names from frames.csv).
  const std::vector<std::string> rows = Lines(ReadFileBytes(copy / "frames.csv"));
  ASSERT_EQ(static_cast<int>(rows.size()), kFrames + 1);
  const std::vector<std::string> header = Fields(rows[0]);
  ASSERT_EQ(header.size(), 5u);
  ASSERT_EQ(header[3], "depth_file");
  ASSERT_EQ(header[4], "color_file");
  const std::string color2 = Fields(rows[3])[4], depth4 = Fields(rows[5])[3];
  ASSERT_TRUE(fs::remove(copy / color2));
  ASSERT_TRUE(fs::remove(copy / depth4));

  const PipelineResult r = Track(copy.string(), OutDir("run_damaged").string());
  ASSERT_EQ(static_cast<int>(r.frames.size()), kFrames);
  EXPECT_EQ(r.skipped_frames, 2);
  ASSERT_EQ(r.warnings.size(), 2u);
  EXPECT_NE(r.warnings[0].find(fs::path(color2).filename().string()), std::string::npos)
      << r.warnings[0];
  EXPECT_NE(r.warnings[1].find(fs::path(depth4).filename().string()), std::string::npos)
      << r.warnings[1];
  for (const FrameRecord& f : r.frames) {
    EXPECT_EQ(f.skipped, f.frame == 2 || f.frame == 4) << "frame " << f.frame;
    if (!f.skipped) {
      EXPECT_TRUE(f.fit.ok()) << "frame " << f.frame;
      EXPECT_LT(f.mean_vertex_error_mm, 50.0) << "frame " << f.frame;
    }
  }
  EXPECT_EQ(r.lost_fraction, 0.0);
  const std::vector<std::string> poses = Lines(ReadFileBytes(OutDir("run_damaged") / "poses.csv"));
  ASSERT_EQ(static_cast<int>(poses.size()), 1 + kFrames - 2);
  std::vector<int> written;
  for (size_t i = 1; i < poses.size(); ++i) written.push_back(std::stoi(Fields(poses[i])[0]));
  EXPECT_EQ(written, (std::vector<int>{0, 1, 3, 5}));
  const nlohmann::json metrics =
      nlohmann::json::parse(ReadFileBytes(OutDir("run_damaged") / "metrics.json"));
  EXPECT_EQ(metrics.at("skipped_frames").get<int>(), 2);
  const nlohmann::json summary =
      nlohmann::json::parse(ReadFileBytes(OutDir("run_damaged") / "summary.json"));
  EXPECT_EQ(summary.at("warnings").size(), 2u);
}

// Runs a shell command; returns its exit status and its combined output in *output.
int RunCommand(const std::string& command, std::string* output) {
  const fs::path log = TestData().root / "command.log";
  const int status = std::system((command + " > '" + log.string() + "' 2>&1").c_str());
  *output = ReadFileBytes(log);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(PipelineTest, NobodyInViewIsLostAndTheReturnReinitialises) {
  // The person leaves the view in frames 2 and 3 (all depth zero) and comes back in frame 4.
  const fs::path copy = OutDir("sequence_empty");
  fs::copy(TestData().sequence, copy, fs::copy_options::recursive);
  const std::vector<std::string> rows = Lines(ReadFileBytes(copy / "frames.csv"));
  for (int f : {2, 3}) {
    const fs::path depth = copy / Fields(rows[f + 1])[3];
    const cv::Mat d = cv::imread(depth.string(), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(d.empty());
    ASSERT_TRUE(cv::imwrite(depth.string(), cv::Mat::zeros(d.size(), d.type())));
  }
  const PipelineResult r = Track(copy.string(), OutDir("run_empty").string());
  ASSERT_EQ(static_cast<int>(r.frames.size()), kFrames);
  EXPECT_EQ(r.skipped_frames, 0);
  EXPECT_EQ(r.failed_frames, 2);
  EXPECT_EQ(r.lost_frames, 2);
  EXPECT_EQ(r.initialisations, 2);  // the first frame and the return
  for (const FrameRecord& f : r.frames) {
    const bool empty = f.frame == 2 || f.frame == 3;
    EXPECT_EQ(f.quality.label == FitQualityLabel::kLost, empty) << "frame " << f.frame;
    EXPECT_EQ(f.fit.too_few_points, empty) << "frame " << f.frame;
    EXPECT_EQ(f.reinitialised, f.frame == 0 || f.frame == 4) << "frame " << f.frame;
    if (!empty) {
      EXPECT_LT(f.mean_vertex_error_mm, 50.0) << "frame " << f.frame;
    }
  }
  // Failed frames are not scored as tracked: their kept pose counts as lost and stays out of
  // the error averages (issue 20).
  EXPECT_NEAR(r.lost_fraction, 2.0 / kFrames, 1e-12);
  EXPECT_EQ(r.evaluated_frames, kFrames - 2);
  double sum = 0.0, worst = 0.0;
  for (const FrameRecord& f : r.frames) {
    if (f.frame == 2 || f.frame == 3) continue;
    sum += f.mean_vertex_error_mm;
    worst = std::max(worst, f.max_vertex_error_mm);
  }
  EXPECT_NEAR(r.mean_vertex_error_mm, sum / (kFrames - 2), 1e-9);
  EXPECT_EQ(r.max_vertex_error_mm, worst);
  const nlohmann::json metrics =
      nlohmann::json::parse(ReadFileBytes(OutDir("run_empty") / "metrics.json"));
  EXPECT_EQ(metrics.at("failed_frames").get<int>(), 2);
  EXPECT_EQ(metrics.at("lost_frames").get<int>(), 2);
  EXPECT_EQ(metrics.at("evaluated_frames").get<int>(), kFrames - 2);
}

// Every depth frame all zero: every fit fails. The run is an error that keeps each frame's
// reason, never a small error and 0 % lost (issue 20: it reported 6 mm and exited 0).
TEST(PipelineTest, NoUsableFrameIsAnErrorListingTheReasons) {
  const fs::path copy = OutDir("sequence_all_zero");
  fs::copy(TestData().sequence, copy, fs::copy_options::recursive);
  const std::vector<std::string> rows = Lines(ReadFileBytes(copy / "frames.csv"));
  for (int f = 0; f < kFrames; ++f) {
    const fs::path depth = copy / Fields(rows[f + 1])[3];
    const cv::Mat d = cv::imread(depth.string(), cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(d.empty());
    ASSERT_TRUE(cv::imwrite(depth.string(), cv::Mat::zeros(d.size(), d.type())));
  }
  ASSERT_TRUE(fs::remove(copy / Fields(rows[1])[4]));  // frame 0 unreadable too
  const std::string what = ErrorOf([&] { Track(copy.string(), OutDir("run_all_zero").string()); });
  EXPECT_NE(what.find("no usable frame"), std::string::npos) << what;
  EXPECT_NE(what.find(fs::path(Fields(rows[1])[4]).filename().string()), std::string::npos)
      << what;  // the unreadable frame's file
  for (int f = 1; f < kFrames; ++f)
    EXPECT_NE(what.find("frame " + std::to_string(f) + ": fit failed"), std::string::npos) << what;
  EXPECT_NE(what.find("found 0"), std::string::npos) << what;

  const std::string binary = ARTEX_BINARY;
  std::string output;
  EXPECT_NE(RunCommand("'" + binary + "' track '" + copy.string() + "' -t '" +
                           TestData().template_path + "' -o '" + OutDir("cli_all_zero").string() +
                           "' -q --set texture.atlas_size=" + std::to_string(kAtlasSize),
                       &output),
            0)
      << output;
  EXPECT_NE(output.find("frame 3: fit failed"), std::string::npos) << output;
  EXPECT_EQ(output.find("mean vertex error"), std::string::npos) << output;
}

TEST(PipelineTest, TrackCommandExitStatus) {
  const testing_util::SequenceFixture& data = TestData();
  const std::string binary = ARTEX_BINARY;
  ASSERT_TRUE(fs::exists(binary)) << binary;
  const fs::path config = data.root / "small.yaml";
  {
    std::ofstream out(config);
    out << "texture:\n  atlas_size: " << kAtlasSize << "\n";
  }
  std::string output;
  const std::string missing = (data.root / "missing_sequence").string();
  EXPECT_NE(RunCommand("'" + binary + "' track '" + missing + "' -o '" +
                           (data.root / "cli_missing").string() + "' -q",
                       &output),
            0);
  EXPECT_NE(output.find("missing_sequence"), std::string::npos) << output;

  const fs::path out = data.root / "cli_out";
  EXPECT_EQ(RunCommand("'" + binary + "' track '" + data.sequence + "' -c '" + config.string() +
                           "' -t '" + data.template_path + "' -o '" + out.string() + "' -q",
                       &output),
            0)
      << output;
  EXPECT_NE(output.find("mean vertex error"), std::string::npos) << output;
  EXPECT_EQ(static_cast<int>(Lines(ReadFileBytes(out / "poses.csv")).size()), kFrames + 1);
  EXPECT_TRUE(fs::exists(out / "tracked.glb"));

  // A configuration with an unknown key fails and names the file.
  const fs::path bad = data.root / "bad_config.yaml";
  {
    std::ofstream o(bad);
    o << "fitting:\n  radius: 0.1\n";
  }
  EXPECT_NE(RunCommand("'" + binary + "' track '" + data.sequence + "' -c '" + bad.string() +
                           "' -o '" + (data.root / "cli_bad").string() + "' -q",
                       &output),
            0);
  EXPECT_NE(output.find("bad_config.yaml"), std::string::npos) << output;
  EXPECT_NE(output.find("radius"), std::string::npos) << output;
}

// Section shape: a bones_girth calibration swaps the subject's template in, which is written as
// subject.glb (same rig, vertex count and UVs) with its parameters in summary.json; a bad mode
// is an error naming the key.
// A bones_girth calibration after one frame of one round, with few iterations.
Config SmallShapeConfig() {
  Config config = SmallConfig();
  config.Set("shape.mode", "bones_girth");
  config.Set("shape.calibration_frames", "1");
  config.Set("shape.calibration_rounds", "1");
  config.Set("shape.iterations_per_stage", "2");
  config.Set("fitting.scale_estimation_frames", "2");
  return config;
}

// A run of `config` into OutDir(name): summary.json's shape and poses.csv's rows.
struct ShapeRun {
  nlohmann::json shape;
  std::vector<std::string> rows;
  fs::path out;
};
ShapeRun RunShape(const std::string& name, const Config& config) {
  ShapeRun run;
  run.out = OutDir(name);
  Track(TestData().sequence, run.out.string(), config);
  std::ifstream in(run.out / "summary.json");
  run.shape = nlohmann::json::parse(in).at("shape");
  std::ifstream poses(run.out / "poses.csv");
  for (std::string line; std::getline(poses, line);) run.rows.push_back(line);
  return run;
}

TEST(PipelineTest, ShapeCalibrationWritesTheSubjectTemplate) {
  Config config = SmallShapeConfig();
  const fs::path out = OutDir("run_shape");
  const PipelineResult r = Track(TestData().sequence, out.string(), config);
  EXPECT_EQ(static_cast<int>(r.frames.size()), kFrames);
  std::ifstream in(out / "summary.json");
  const nlohmann::json summary = nlohmann::json::parse(in);
  ASSERT_TRUE(summary.contains("shape"));
  const nlohmann::json& shape = summary.at("shape");
  EXPECT_EQ(shape.at("mode").get<std::string>(), "bones_girth");
  EXPECT_TRUE(shape.at("calibrated").get<bool>());
  EXPECT_GE(shape.at("calibrated_after_frame").get<int>(), 1);
  // 10 bone lengths, 11 girths, 3 leaf lengths (head, hand, foot), 2 fork widths (shoulder, hip).
  EXPECT_EQ(shape.at("parameters").size(), 26u);
  EXPECT_GT(shape.at("calibration").at("iterations").get<int>(), 0);
  ASSERT_TRUE(fs::exists(out / "subject.glb"));
  const Template subject = ReadTemplateGlb((out / "subject.glb").string());
  const Template base = ReadTemplateGlb(TestData().template_path);
  EXPECT_EQ(subject.num_vertices(), base.num_vertices());
  EXPECT_EQ(subject.num_joints(), base.num_joints());
  EXPECT_EQ(subject.uvs.rows(), base.uvs.rows());
  EXPECT_GT((subject.vertices - base.vertices).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_TRUE(shape.at("parameters_held_unseen").is_array());
  EXPECT_TRUE(shape.at("parameters_at_bounds").is_array());

  Config bad = SmallConfig();
  bad.Set("shape.mode", "sculpted");
  const std::string msg = ErrorOf([&] { LoadPipelineOptions(bad); });
  EXPECT_NE(msg.find("shape.mode"), std::string::npos) << msg;
}

// Section shape.detail: the surface detail follows the last round after detail.frames more
// frames and is swapped in (subject.glb carries it; the frames before the swap are tracked as
// without it), or, when the sequence ends first, is estimated at the end (no frame tracked with
// it); off, summary.json has no detail.
TEST(PipelineTest, ShapeDetailFollowsTheCalibration) {
  const auto run = [&](const std::string& name, const std::string& enabled,
                       const std::string& frames) {
    Config config = SmallShapeConfig();
    config.Set("shape.detail.enabled", enabled);
    config.Set("shape.detail.frames", frames);
    const ShapeRun r = RunShape(name, config);
    const Template subject = ReadTemplateGlb((r.out / "subject.glb").string());
    return std::make_tuple(r.shape, r.rows, subject);
  };
  const auto [off, off_rows, off_subject] = run("run_detail_off", "false", "1");
  const auto [on, on_rows, on_subject] = run("run_detail_on", "true", "1");
  const auto [end, end_rows, end_subject] = run("run_detail_end", "true", "100");
  EXPECT_FALSE(off.contains("detail"));
  EXPECT_TRUE(off.at("calibrated").get<bool>());

  const nlohmann::json& detail = on.at("detail");
  EXPECT_TRUE(detail.at("estimated").get<bool>());
  EXPECT_EQ(detail.at("frames").get<int>(), 2);  // the round's frame and one more
  const int swap = detail.at("after_frame").get<int>();
  EXPECT_GT(swap, on.at("final_calibration_after_frame").get<int>());
  EXPECT_LT(swap, kFrames - 1);
  EXPECT_GT(detail.at("observations").get<int>(), 0);
  EXPECT_TRUE(detail.at("segments").contains("chest"));
  EXPECT_TRUE(on.contains("mean_vertex_error_mm_after_detail"));
  ASSERT_EQ(on_rows.size(), off_rows.size());
  for (int f = 0; f <= swap; ++f) EXPECT_EQ(on_rows[1 + f], off_rows[1 + f]) << f;
  EXPECT_EQ(on_subject.num_vertices(), off_subject.num_vertices());
  EXPECT_EQ(on_subject.uvs, off_subject.uvs);
  EXPECT_GT((on_subject.vertices - off_subject.vertices).cwiseAbs().maxCoeff(), 1e-5);

  const nlohmann::json& late = end.at("detail");
  EXPECT_TRUE(late.at("estimated").get<bool>());
  EXPECT_EQ(late.at("after_frame").get<int>(), -1);
  EXPECT_EQ(end_rows, off_rows);
  EXPECT_GT((end_subject.vertices - off_subject.vertices).cwiseAbs().maxCoeff(), 1e-5);
}

// A parameter the solve pushes against its bound is named in a warning and in summary.json
// (girth bounds of 1: every girth sits at them).
TEST(PipelineTest, ShapeWarnsOfParametersAtTheirBounds) {
  Config config = SmallShapeConfig();
  config.Set("shape.girth_min", "1");
  config.Set("shape.girth_max", "1");
  const fs::path out = OutDir("run_shape_bounds");
  const PipelineResult r = Track(TestData().sequence, out.string(), config);
  std::string warning;
  for (const std::string& w : r.warnings) {
    if (w.find("parameters at their bounds") != std::string::npos) warning = w;
  }
  EXPECT_EQ(warning.rfind("shape: ", 0), 0u) << warning;
  EXPECT_NE(warning.find("girth:chest"), std::string::npos) << warning;
  EXPECT_EQ(warning.find("bone:"), std::string::npos) << warning;
  std::ifstream in(out / "summary.json");
  const nlohmann::json summary = nlohmann::json::parse(in);
  const auto bounded =
      summary.at("shape").at("parameters_at_bounds").get<std::vector<std::string>>();
  EXPECT_NE(std::find(bounded.begin(), bounded.end(), "girth:chest"), bounded.end());
  EXPECT_EQ(summary.at("warnings").size(), r.warnings.size());
}

// shape.joint_limits: limits added to the shape solve's pose priors only. The frames tracked
// before the calibration are the same with and without them; the solve's result is not.
TEST(PipelineTest, ShapeJointLimitsApplyToTheShapeSolveOnly) {
  const auto run = [&](const std::string& name, bool limits) {
    Config config = SmallShapeConfig();
    if (limits) {
      config.Set("shape.joint_limits",
                 "{weight: 0.1, joints: {neck: {min_deg: [0, 0, 0], max_deg: [0, 0, 0]},"
                 " head: {min_deg: [0, 0, 0], max_deg: [0, 0, 0]}}}");
    }
    const ShapeRun r = RunShape(name, config);
    return std::make_pair(r.shape, r.rows);
  };
  const auto [plain, plain_rows] = run("run_shape_plain", false);
  const auto [limited, limited_rows] = run("run_shape_limited", true);
  ASSERT_TRUE(plain.at("calibrated").get<bool>());
  ASSERT_TRUE(limited.at("calibrated").get<bool>());
  const int calibrated = plain.at("calibrated_after_frame").get<int>();
  EXPECT_EQ(limited.at("calibrated_after_frame").get<int>(), calibrated);
  ASSERT_GT(static_cast<int>(plain_rows.size()), calibrated + 1);
  ASSERT_EQ(limited_rows.size(), plain_rows.size());
  for (int row = 0; row <= calibrated + 1; ++row) {  // the header and the frames before
    EXPECT_EQ(limited_rows[row], plain_rows[row]) << "poses.csv row " << row;
  }
  EXPECT_NE(limited.at("parameters").dump(), plain.at("parameters").dump());

  Config bad = SmallShapeConfig();
  bad.Set("shape.joint_limits",
          "{weight: 0.1, joints: {neck: {min_deg: [10, 0, 0], max_deg: [0, 0, 0]}}}");
  const std::string msg =
      ErrorOf([&] { Track(TestData().sequence, OutDir("run_shape_bad").string(), bad); });
  EXPECT_NE(msg.find("shape.joint_limits"), std::string::npos) << msg;
}

// The ground-truth joint error after a shape swap is scored with the subject's joint centres
// (the shaped template the poses were fitted with), not the template's rest centres: each
// frame's figure is recomputed here from poses.csv, subject.glb and the sequence's ground
// truth, and the same recomputation with the template's centres differs (a template with
// short legs and long arms, so the calibration moves its joints by centimetres). The summary's
// windows: after the first swap and after the last round's (here the same, one round).
TEST(PipelineTest, ShapeJointErrorIsScoredWithTheSubjectsJoints) {
  BodyShapeOptions short_legs;
  short_legs.resolution = 0;
  short_legs.leg_length = 0.8;
  short_legs.arm_length = 1.2;
  const Template base = GenerateTemplate(short_legs);
  const fs::path template_path = OutDir("short_legs.glb");
  WriteTemplateGlb(template_path.string(), base);
  const Config config = SmallShapeConfig();
  const fs::path out = OutDir("run_shape_joints");
  const PipelineResult r = RunPipeline(TestData().sequence, template_path.string(),
                                       LoadPipelineOptions(config), config, out.string());
  ASSERT_GE(r.shape_calibrated_frame, 0);
  EXPECT_EQ(r.shape_final_frame, r.shape_calibrated_frame);  // one round
  const Template subject = ReadTemplateGlb((out / "subject.glb").string());
  double moved = 0.0;  // how far the calibration moved a rest joint centre (m)
  for (int j = 0; j < base.num_joints(); ++j) {
    moved = std::max(moved, (subject.joints[j].center - base.joints[j].center).norm());
  }
  ASSERT_GT(moved, 0.01);

  const SequenceReader reader(TestData().sequence);
  const Template truth = ReadTemplateGlb(reader.GroundTruthSubjectPath());
  const Skinning truth_skinning(truth), subject_skinning(subject), base_skinning(base);
  const auto poses = ReadPoseCsv((out / "poses.csv").string(), base.num_joints());
  // Mean distance (mm) of the posed joints of `skinning` to the truth's, by name.
  const auto joint_error = [&](const Skinning& skinning, const Pose& pose, const Pose& true_pose) {
    Eigen::MatrixX3d ours, theirs;
    skinning.PosedJointCenters(pose, &ours);
    truth_skinning.PosedJointCenters(true_pose, &theirs);
    double sum = 0.0;
    int n = 0;
    for (int j = 0; j < base.num_joints(); ++j) {
      const int t = truth.FindJoint(base.joints[j].name);
      if (t < 0) continue;
      sum += (ours.row(j) - theirs.row(t)).norm();
      ++n;
    }
    return 1000.0 * sum / n;
  };
  int checked = 0;
  double vertex = 0.0, joint = 0.0, largest_difference = 0.0;
  for (const FrameRecord& record : r.frames) {
    if (record.skipped || !record.fit.ok() || record.frame <= r.shape_calibrated_frame) continue;
    const auto row = std::find_if(poses.begin(), poses.end(),
                                  [&](const auto& p) { return p.first == record.frame; });
    ASSERT_NE(row, poses.end()) << record.frame;
    const Pose true_pose = reader.ReadGroundTruth(record.frame).pose;
    const double with_subject = joint_error(subject_skinning, row->second, true_pose);
    const double with_base = joint_error(base_skinning, row->second, true_pose);
    EXPECT_NEAR(record.mean_joint_error_mm, with_subject, 1e-3) << "frame " << record.frame;
    largest_difference = std::max(largest_difference, std::abs(with_subject - with_base));
    vertex += record.mean_vertex_error_mm;
    joint += record.mean_joint_error_mm;
    ++checked;
  }
  ASSERT_GT(checked, 0);
  EXPECT_GT(largest_difference, 1.0);  // the template's centres would score differently

  std::ifstream in(out / "summary.json");
  const nlohmann::json shape = nlohmann::json::parse(in).at("shape");
  EXPECT_EQ(shape.at("rounds").get<int>(), 1);
  EXPECT_EQ(shape.at("final_calibration_after_frame").get<int>(), r.shape_final_frame);
  EXPECT_EQ(shape.at("frames_after_final_calibration").get<int>(), checked);
  EXPECT_NEAR(shape.at("mean_joint_error_mm_after_final_calibration").get<double>(),
              joint / checked, 1e-9);
  EXPECT_NEAR(shape.at("mean_vertex_error_mm_after_final_calibration").get<double>(),
              vertex / checked, 1e-9);
  EXPECT_NEAR(shape.at("mean_joint_error_mm_after_calibration").get<double>(), joint / checked,
              1e-9);
  // Per joint by name: every joint has a true one here, so their mean is the mean joint error.
  const nlohmann::json& by_joint = shape.at("joint_errors_mm_after_final_calibration");
  ASSERT_EQ(static_cast<int>(by_joint.size()), base.num_joints());
  double sum = 0.0;
  for (const Joint& j : base.joints) sum += by_joint.at(j.name).get<double>();
  EXPECT_NEAR(sum / base.num_joints(), joint / checked, 1e-9);
}

// shape.retrack: the first pass (fitting only) calibrates the subject into shape_pass/, the
// second tracks every frame with that template; a live run cannot be tracked twice.
TEST(PipelineTest, ShapeRetrackTracksAgainWithTheSubject) {
  Config config = SmallShapeConfig();
  config.Set("shape.retrack", "true");
  const fs::path out = OutDir("run_retrack");
  const PipelineResult r = Track(TestData().sequence, out.string(), config);
  EXPECT_EQ(static_cast<int>(r.frames.size()), kFrames);
  EXPECT_GE(r.shape_calibrated_frame, 1);
  ASSERT_TRUE(fs::exists(out / "shape_pass" / "subject.glb"));
  ASSERT_TRUE(fs::exists(out / "shape_pass" / "frames.csv"));
  EXPECT_FALSE(fs::exists(out / "shape_pass" / "texture.png"));  // the first pass fits only
  EXPECT_TRUE(fs::exists(out / "poses.csv"));
  ASSERT_FALSE(r.warnings.empty());
  EXPECT_NE(r.warnings[0].find("shape.retrack"), std::string::npos) << r.warnings[0];
  // The second pass keeps the subject's shape fixed: no second calibration in its summary.
  std::ifstream in(out / "summary.json");
  const nlohmann::json summary = nlohmann::json::parse(in);
  if (summary.contains("shape")) {
    EXPECT_EQ(summary.at("shape").at("mode").get<std::string>(), "fixed");
  }
  // Named relative to the run (it was written into a temporary sibling; artex overlay reads it).
  EXPECT_EQ(summary.at("template").get<std::string>(), "shape_pass/subject.glb");

  Config live = config;
  live.Set("pipeline.live", "true");
  const std::string msg = ErrorOf([&] { LoadPipelineOptions(live); });
  EXPECT_NE(msg.find("shape.retrack"), std::string::npos) << msg;
}

}  // namespace
}  // namespace artex
