// RunPipeline's section shape end to end on a short synthetic sequence (experiments/pipeline.h,
// docs/shape.md): the subject's template and summary, the surface detail, warnings, the shape
// solve's own joint limits and free-space maps, the floor, and shape.retrack. The other outputs:
// pipeline_test.cc.
#include "experiments/pipeline.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "experiments/config.h"
#include "experiments/pose_csv.h"
#include "models/error.h"
#include "models/skinning.h"
#include "models/template_generator.h"
#include "models/template_io.h"
#include "sensors/sequence.h"
#include "tests/error_of.h"
#include "tests/experiments/pipeline_test_util.h"
#include "tests/solvers/virtual_kinect_scans.h"
#include "tests/testing_util.h"

namespace artex {
namespace pipeline_test {
const char* FixtureName() { return "pipeline_shape_test"; }
}  // namespace pipeline_test

namespace {

namespace fs = std::filesystem;
using namespace pipeline_test;  // NOLINT: the shared set-up

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

// The shape's scan mask reads the free-space maps of the frames the estimator keeps: it builds
// them for those frames only (TrackStage::FeedShape), so the preprocessing builds them for every
// frame only for the silhouette term (unless preprocess.silhouette.enabled says). The maps
// built either way are the same: the poses agree bit for bit.
TEST(PipelineTest, ShapeScanMaskBuildsTheFreeSpaceMapsItNeeds) {
  const auto built = [](const std::string& yaml) {
    const Config config = Config::FromString(yaml, "shape.yaml");
    return LoadPipelineOptions(config).preprocess.silhouette.enabled;
  };
  EXPECT_FALSE(built("shape:\n  mode: bones_girth\n"));
  EXPECT_TRUE(built("fitting:\n  silhouette:\n    weight: 1.0\n"));
  EXPECT_FALSE(built("fitting:\n  silhouette:\n    weight: 1.0\n"
                     "preprocess:\n  silhouette:\n    enabled: false\n"));
  EXPECT_FALSE(built("shape:\n  mode: bones_girth\n  bias_scan_mask: true\n"));
  const PipelineOptions o = LoadPipelineOptions(Config::FromString(
      "shape:\n  bias_mask_tolerance: 0.05\n  bias_mask_radius_px: 2\n", "shape.yaml"));
  EXPECT_EQ(o.shape.bias_mask_tolerance, 0.05);
  EXPECT_EQ(o.shape.bias_mask_radius_px, 2);
  const Config bad = Config::FromString("shape:\n  bias_mask_radius_px: 9\n", "s.yaml");
  EXPECT_NE(ErrorOf([&] { LoadPipelineOptions(bad); }).find("bias_mask_radius_px"),
            std::string::npos);

  Config lazy = SmallShapeConfig();  // the mask is on by default
  Config every = lazy;
  every.Set("preprocess.silhouette.enabled", "true");
  const ShapeRun a = RunShape("mask_lazy", lazy), b = RunShape("mask_every", every);
  ASSERT_TRUE(a.shape.at("calibrated").get<bool>());
  EXPECT_EQ(a.rows, b.rows);
  Config off = SmallShapeConfig();
  off.Set("shape.bias_scan_mask", "false");
  const ShapeRun c = RunShape("mask_off", off);
  EXPECT_NE(a.rows, c.rows) << "the mask changes the solve";
}

// The floor term's plane, found in the first frame: the synthetic scene's floor is y = 0.
TEST(PipelineTest, ShapeFindsTheFloor) {
  const ShapeRun run = RunShape("floor", SmallShapeConfig());
  const nlohmann::json& floor = run.shape.at("floor");
  ASSERT_TRUE(floor.is_object()) << run.shape.dump();
  EXPECT_NEAR(floor.at("normal")[1].get<double>(), 1.0, 1e-3);
  EXPECT_NEAR(floor.at("offset").get<double>(), 0.0, 0.01);
  EXPECT_FALSE(floor.at("contradicted").get<bool>());
  Config off = SmallShapeConfig();
  off.Set("shape.floor_weight", "0");
  EXPECT_TRUE(RunShape("floor_off", off).shape.at("floor").is_null());
}

// A bones_girth calibration swaps the subject's template in, which is written as subject.glb
// (same rig, vertex count and UVs) with its parameters in summary.json; a bad mode is an error
// naming the key.
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
