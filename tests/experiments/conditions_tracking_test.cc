// Tracking under the conditions of real recordings (docs/real-data.md, docs/synthesis.md
// "Conditions"), on the virtual Kinect with ground truth: no background frames, the camera
// frame as world frame (the world frame and the foreground are then inferred), clutter and a
// second person, a subject facing away at the start, upper-body framing, a rolled or high
// camera. (A subject seen from the side at the start is not yet tracked reliably: its facing is
// ambiguous in depth; docs/real-data.md.) Each
// condition: a 30-frame walk with default noise and a subject shaped unlike the template, tracked
// with the built-in defaults (texturing off): upright, mean vertex error <= 20 mm, no lost frame.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <ostream>
#include <string>
#include <vector>

#include "experiments/config.h"
#include "experiments/pipeline.h"
#include "experiments/pose_csv.h"
#include "models/normals.h"
#include "models/skinning.h"
#include "models/template_generator.h"
#include "models/template_io.h"
#include "sensors/calibration.h"
#include "sensors/sequence.h"
#include "sensors/synth_conditions.h"
#include "sensors/virtual_kinect.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

constexpr int kFrames = 30;
constexpr double kMaxMeanErrorMm = 20.0;

struct Condition {
  std::string name;
  std::vector<SynthCondition> presets;  // applied in order on top of the "room" basics
  bool full_body = true;                // joints of the whole body are observed
  // The joint error and the good fraction are checked from this frame on: seen from the side,
  // facing left or right is ambiguous in the first frame (a wrong start stays doubtful and is
  // initialised again after pipeline.reinitialise_after_doubtful frames).
  int settle_frames = 0;
};

void PrintTo(const Condition& c, std::ostream* os) { *os << c.name; }

// The basics of every case: what a user's recording has (no empty-scene frames, the camera as
// world frame); the presets add the rest.
SynthOptions ConditionOptions(const Condition& c) {
  SynthOptions o;
  o.motion.type = MotionType::kWalk;
  o.motion.frames = kFrames;
  o.kinect.SetNoiseLevel(NoiseLevel::kDefault);
  o.kinect.color_width = 160;
  o.kinect.color_height = 204;
  o.texture.size = 512;
  o.background_frames = 0;
  o.world_frame = WorldFrame::kDepthCamera;
  for (SynthCondition p : c.presets) ApplySynthCondition(p, &o);
  return o;
}

Eigen::MatrixX3d TransformRows(const Eigen::Isometry3d& t, const Eigen::MatrixX3d& points) {
  return ((points * t.linear().transpose()).rowwise() + t.translation().transpose()).eval();
}

// Mean distance (mm) from the true surface the depth camera sees (subject vertices projecting
// into the image, in front of it; every fourth) to the tracked surface: the distance to the
// nearest tracked vertex, refined to its tangent plane. The fit is judged on what was observed.
double SeenSurfaceErrorMm(const Eigen::MatrixX3d& truth, const PinholeCamera& camera,
                          const Eigen::MatrixX3d& tracked, const Eigen::MatrixX3i& triangles) {
  Eigen::MatrixX3d normals;
  ComputeVertexNormals(tracked, triangles, &normals);
  double sum = 0.0;
  int n = 0;
  for (Eigen::Index v = 0; v < truth.rows(); v += 4) {
    const Eigen::Vector3d p = truth.row(v).transpose();
    double z = 0.0;
    const Eigen::Vector2d px = camera.Project(p, &z);
    if (!(z > 0.0 && px.x() >= 0 && px.y() >= 0 && px.x() < camera.width &&
          px.y() < camera.height)) {
      continue;
    }
    Eigen::Index nearest = 0;
    const double d2 = (tracked.rowwise() - p.transpose()).rowwise().squaredNorm().minCoeff(&nearest);
    const Eigen::Vector3d q = tracked.row(nearest).transpose();
    const Eigen::Vector3d normal = normals.row(nearest).transpose();
    sum += std::min(std::sqrt(d2), std::abs(normal.dot(p - q)));
    ++n;
  }
  return n > 0 ? 1000.0 * sum / n : 0.0;
}

class ConditionsTrackingTest : public ::testing::TestWithParam<Condition> {
 protected:
  static fs::path Root() {
    static const fs::path root = testing_util::FreshTempDir("conditions");
    return root;
  }
};

TEST_P(ConditionsTrackingTest, UprightAccurateAndNeverLost) {
  const Condition& c = GetParam();
  const fs::path seq = Root() / ("seq_" + c.name);
  SynthesizeSequence(ConditionOptions(c), seq.string());
  Config config;
  config.Set("pipeline.texture", "false");
  config.Set("pipeline.export_glb", "false");
  const PipelineOptions options = LoadPipelineOptions(config);
  const PipelineResult r =
      RunPipeline(seq.string(), "", options, config, (Root() / ("run_" + c.name)).string());
  std::printf(
      "[%s] mean vertex error %.2f mm (max %.1f), joint %.1f mm, good %d, doubtful %d, "
      "lost %d, initialisations %d, fit %.1f ms/frame, init %.0f ms\n",
      c.name.c_str(), r.mean_vertex_error_mm, r.max_vertex_error_mm, r.mean_joint_error_mm,
      r.good_frames, r.doubtful_frames, r.lost_frames, r.initialisations, r.fit_ms_per_frame,
      r.init_ms_per_initialisation);
  ASSERT_EQ(static_cast<int>(r.frames.size()), kFrames);
  // With the whole body in view, the whole template is scored; otherwise the surface the camera
  // saw (below): the legs below an upper-body view are nobody's measurement.
  if (c.full_body) {
    EXPECT_LE(r.mean_vertex_error_mm, kMaxMeanErrorMm);
    EXPECT_EQ(r.lost_fraction, 0.0);  // mean vertex error <= 50 mm in every frame
  }
  EXPECT_EQ(r.lost_frames, 0);  // by the quality measure
  // Seen from the side, the quality drops after the first frames and pipeline.reinitialise_on
  // auto tries again in place (measured: 3 initialisations, every frame good from then on).
  EXPECT_LE(r.initialisations, c.settle_frames > 0 ? 3 : 1);
  // Upright in every frame: the tracked chest -> head direction, taken into the sequence's
  // frame, within 25 degrees of the truth's (the pelvis may be out of view).
  const fs::path run = Root() / ("run_" + c.name);
  const Calibration sequence_calibration = ReadCalibration((seq / "calibration.yaml").string());
  const Calibration run_calibration = ReadCalibration((run / "calibration.yaml").string());
  const Eigen::Isometry3d to_sequence =
      sequence_calibration.depth.world_to_camera.inverse() * run_calibration.depth.world_to_camera;
  SequenceReader reader(seq.string());
  const Template tmpl = GenerateTemplate();
  const Template subject = ReadTemplateGlb(reader.GroundTruthSubjectPath());
  const Skinning tracked_skinning(tmpl), subject_skinning(subject);
  const auto axis = [](const Template& t, const Eigen::MatrixX3d& joints) {
    return Eigen::Vector3d(joints.row(t.FindJoint("head")) - joints.row(t.FindJoint("chest")))
        .normalized();
  };
  const auto poses = ReadPoseCsv((run / "poses.csv").string(), kDefaultNumJoints);
  ASSERT_EQ(static_cast<int>(poses.size()), kFrames);
  double seen_sum = 0.0;
  for (const auto& [frame, pose] : poses) {
    Eigen::MatrixX3d ours, theirs;
    tracked_skinning.PosedJointCenters(pose, &ours);
    const GroundTruthFrame truth = reader.ReadGroundTruth(frame);
    subject_skinning.PosedJointCenters(truth.pose, &theirs);
    if (!c.full_body) {
      Eigen::MatrixX3d posed;
      tracked_skinning.Apply(pose, &posed);
      seen_sum += SeenSurfaceErrorMm(truth.vertices, sequence_calibration.depth,
                                     TransformRows(to_sequence, posed), tmpl.triangles);
    }
    const Eigen::Vector3d tracked_up = to_sequence.linear() * axis(tmpl, ours);
    const Eigen::Vector3d true_up = axis(subject, theirs);
    const double angle = std::acos(std::clamp(tracked_up.dot(true_up), -1.0, 1.0)) * 180 / M_PI;
    EXPECT_LT(angle, 25.0) << "frame " << frame;
  }
  // The right way round: with the whole body in view, the mean joint error stays at the vertex
  // error's order (upside down or left/right swapped puts joints tens of centimetres off).
  int good = 0, settled = 0;
  double joint_sum = 0.0;
  for (const FrameRecord& f : r.frames) {
    if (f.frame < c.settle_frames) continue;
    ++settled;
    good += f.quality.label == FitQualityLabel::kGood;
    joint_sum += f.mean_joint_error_mm;
  }
  if (c.full_body) {
    EXPECT_LE(joint_sum / settled, 45.0);
  } else {
    const double seen = seen_sum / kFrames;
    std::printf("[%s] mean error of the surface in view %.2f mm\n", c.name.c_str(), seen);
    EXPECT_LE(seen, kMaxMeanErrorMm);
  }
  EXPECT_GE(good, settled * 8 / 10);
}

INSTANTIATE_TEST_SUITE_P(
    Conditions, ConditionsTrackingTest,
    ::testing::Values(Condition{"camera_frame", {}}, Condition{"room", {SynthCondition::kRoom}},
                      Condition{"facing_away", {SynthCondition::kFacingAway}},
                      Condition{"sideways", {SynthCondition::kSideways}, true, 15},
                      Condition{"upper_body", {SynthCondition::kUpperBody}, false},
                      Condition{"rolled", {SynthCondition::kRolled}},
                      Condition{"high_camera", {SynthCondition::kHighCamera}}),
    [](const ::testing::TestParamInfo<Condition>& info) { return info.param.name; });

}  // namespace
}  // namespace artex
