#include "sensors/motion.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "models/error.h"
#include "models/skinning.h"
#include "models/so3.h"
#include "models/template_generator.h"
#include "tests/sensors/test_skeleton.h"

namespace artex {
namespace {

constexpr double kDeg = M_PI / 180.0;
const std::vector<MotionType> kMoving = {MotionType::kWalk, MotionType::kArmRaise,
                                         MotionType::kTurn, MotionType::kBend};

const Template& Model() {
  static const Template t = testing_skeleton::MakeBoxTemplate();
  return t;
}

int J(const std::string& name) {
  const int j = Model().FindJoint(name);
  EXPECT_GE(j, 0) << name;
  return j;
}

std::vector<Pose> Generate(MotionType type, int frames = 90, double amplitude = 1.0) {
  MotionOptions options;
  options.type = type;
  options.frames = frames;
  options.amplitude = amplitude;
  return GenerateMotion(Model(), options);
}

double Angle(const Eigen::Matrix3d& r) { return LogSO3(r).norm(); }

// Mirror x -> -x of a rotation: M R M with M = diag(-1, 1, 1).
Eigen::Matrix3d Mirror(const Eigen::Matrix3d& r) {
  const Eigen::Matrix3d m = Eigen::Vector3d(-1, 1, 1).asDiagonal();
  return m * r * m;
}

TEST(MotionTest, NamesRoundTripAndUnknownNameListsValidOnes) {
  for (MotionType t : {MotionType::kWalk, MotionType::kArmRaise, MotionType::kTurn,
                       MotionType::kBend, MotionType::kStill, MotionType::kPunchKick}) {
    EXPECT_EQ(ParseMotionType(MotionTypeName(t)), t);
  }
  try {
    ParseMotionType("jog");
    FAIL() << "expected artex::Error";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("jog"), std::string::npos) << msg;
    EXPECT_NE(msg.find("arm_raise"), std::string::npos) << msg;
  }
}

TEST(MotionTest, InvalidOptionsAndTemplatesThrow) {
  MotionOptions options;
  options.frames = 0;
  EXPECT_THROW(GenerateMotion(Model(), options), Error);
  options = MotionOptions();
  options.amplitude = 2.0;
  std::string error;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("amplitude"), std::string::npos) << error;
  EXPECT_THROW(GenerateMotion(Model(), options), Error);
  options = MotionOptions();
  options.period_s = 0.0;
  EXPECT_THROW(GenerateMotion(Model(), options), Error);
  options = MotionOptions();
  options.frame_rate = -30.0;
  EXPECT_THROW(GenerateMotion(Model(), options), Error);

  Template renamed = Model();
  renamed.joints[J("l_knee")].name = "left_knee";
  try {
    GenerateMotion(renamed, MotionOptions());
    FAIL() << "expected artex::Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("l_knee"), std::string::npos) << e.what();
  }
}

TEST(MotionTest, EveryMotionHasFramesFiniteAndStartsAtRest) {
  for (MotionType type : kMoving) {
    SCOPED_TRACE(MotionTypeName(type));
    const std::vector<Pose> poses = Generate(type, 75);
    ASSERT_EQ(poses.size(), 75u);
    for (const Pose& p : poses) {
      ASSERT_TRUE(p.AllFinite());
      ASSERT_EQ(p.num_joints(), Model().num_joints());
      EXPECT_DOUBLE_EQ(p.scale, 1.0);
    }
    const Pose& first = poses[0];
    EXPECT_LT(Angle(first.rotation), 0.5 * kDeg);
    for (int j = 0; j < first.num_joints(); ++j) {
      EXPECT_LT(Angle(first.joint_rotations[j]), 0.5 * kDeg) << Model().joints[j].name;
    }
    EXPECT_LT(first.translation.norm(), 0.005);
  }
  const std::vector<Pose> still = Generate(MotionType::kStill, 10);
  for (const Pose& p : still) {
    EXPECT_LT(Pose::Identity(17).LocalCoordinates(p).norm(), 1e-9);
  }
}

TEST(MotionTest, ConsecutiveFramesChangeLittleAndSmoothly) {
  const Skinning skinning(Model());
  for (MotionType type : kMoving) {
    SCOPED_TRACE(MotionTypeName(type));
    const std::vector<Pose> poses = Generate(type, 120);
    double max_step = 0.0, max_accel = 0.0, max_vertex_step = 0.0;
    Eigen::MatrixX3d prev, cur;
    skinning.Apply(poses[0], &prev);
    for (size_t f = 1; f < poses.size(); ++f) {
      const Eigen::VectorXd d = poses[f - 1].LocalCoordinates(poses[f]);
      for (int k = 0; k < 1 + poses[f].num_joints(); ++k) {
        max_step = std::max(max_step, d.segment<3>(kGlobalRotationIndex + 3 * k).norm());
      }
      if (f + 1 < poses.size()) {
        // Second difference of the tangent trajectory (C2-like smoothness).
        const Eigen::VectorXd d2 = poses[f].LocalCoordinates(poses[f + 1]) - d;
        for (int k = 0; k < 1 + poses[f].num_joints(); ++k) {
          max_accel = std::max(max_accel, d2.segment<3>(kGlobalRotationIndex + 3 * k).norm());
        }
      }
      skinning.Apply(poses[f], &cur);
      max_vertex_step = std::max(max_vertex_step, (cur - prev).rowwise().norm().maxCoeff());
      prev = cur;
    }
    EXPECT_LT(max_step, 5.0 * kDeg);
    EXPECT_GT(max_step, 0.5 * kDeg);  // it moves
    EXPECT_LT(max_accel, 1.0 * kDeg);
    EXPECT_LT(max_vertex_step, 0.06);  // metres per frame at 30 Hz
  }
}

TEST(MotionTest, JointAnglesStayWithinPlausibleLimits) {
  const std::map<std::string, double> limit_deg = {
      {"pelvis", 30},     {"spine", 30},   {"chest", 30},  {"neck", 30},       {"head", 30},
      {"l_shoulder", 90}, {"l_elbow", 70}, {"l_wrist", 1}, {"r_shoulder", 90}, {"r_elbow", 70},
      {"r_wrist", 1},     {"l_hip", 40},   {"l_knee", 70}, {"l_ankle", 25},    {"r_hip", 40},
      {"r_knee", 70},     {"r_ankle", 25}};
  for (MotionType type : kMoving) {
    SCOPED_TRACE(MotionTypeName(type));
    for (const Pose& p : Generate(type, 90)) {
      EXPECT_LT(Angle(p.rotation), 50 * kDeg);
      for (const auto& [name, limit] : limit_deg) {
        EXPECT_LE(Angle(p.joint_rotations[J(name)]), limit * kDeg) << name;
      }
      // Knees only flex (rotation about +x moves the shank backwards), never hyperextend.
      for (const char* knee : {"l_knee", "r_knee"}) {
        EXPECT_GE(LogSO3(p.joint_rotations[J(knee)]).x(), -1e-9) << knee;
      }
    }
  }
}

TEST(MotionTest, WalkMovesLegsAndArmsInAntiphaseWithMirrorSymmetry) {
  const std::vector<Pose> poses = Generate(MotionType::kWalk, 120);
  auto range = [&](const std::string& joint) {
    double lo = 1e9, hi = -1e9;
    for (const Pose& p : poses) {
      // Signed flexion angle about the left-right axis.
      const double a = LogSO3(p.joint_rotations[J(joint)]).x();
      lo = std::min(lo, a);
      hi = std::max(hi, a);
    }
    return hi - lo;
  };
  EXPECT_GT(range("l_hip"), 20 * kDeg);
  EXPECT_GT(range("r_hip"), 20 * kDeg);
  EXPECT_GT(range("l_knee"), 20 * kDeg);
  EXPECT_GT(Angle(poses[45].joint_rotations[J("pelvis")]), 2 * kDeg);
  // Half a cycle (period 2 s at 30 Hz = 60 frames) later the right side mirrors the left.
  const int half = 30;
  for (int f = 30; f + half < 120; ++f) {
    for (const auto& [l, r] :
         std::vector<std::pair<std::string, std::string>>{{"l_hip", "r_hip"},
                                                          {"l_knee", "r_knee"},
                                                          {"l_ankle", "r_ankle"},
                                                          {"l_shoulder", "r_shoulder"},
                                                          {"l_elbow", "r_elbow"}}) {
      const Eigen::Matrix3d left = poses[f].joint_rotations[J(l)];
      const Eigen::Matrix3d right = poses[f + half].joint_rotations[J(r)];
      EXPECT_LT(Angle(left.transpose() * Mirror(right)), 1e-6) << l << " frame " << f;
    }
  }
  // Arm swing opposes the same side's hip: left hip flexed (forward) <=> left arm back.
  const Eigen::Matrix3d hip = poses[75].joint_rotations[J("l_hip")];
  const Eigen::Matrix3d shoulder = poses[75].joint_rotations[J("l_shoulder")];
  const Eigen::Vector3d thigh = hip * Eigen::Vector3d(0, -1, 0);
  const Eigen::Vector3d arm = shoulder * Model().joints[J("l_shoulder")].twist_axis;
  EXPECT_GT(thigh.z(), 0.2);  // phase 2.5 pi: left thigh forward
  EXPECT_LT(arm.z(), -0.1);   // left arm backward
}

TEST(MotionTest, ArmRaiseLiftsWristsAboveShoulders) {
  const Skinning skinning(Model());
  const std::vector<Pose> poses = Generate(MotionType::kArmRaise, 60);
  Eigen::MatrixX3d centers;
  skinning.PosedJointCenters(poses[30], &centers);  // mid cycle: highest
  for (const char* side : {"l_", "r_"}) {
    const std::string s(side);
    EXPECT_GT(centers(J(s + "wrist"), 1), centers(J(s + "shoulder"), 1) + 0.1) << side;
    EXPECT_GT(Angle(poses[30].joint_rotations[J(s + "shoulder")]), 60 * kDeg);
    EXPECT_GT(Angle(poses[30].joint_rotations[J(s + "elbow")]), 30 * kDeg);
  }
  // Mirror symmetry between the arms at every frame; the legs do not move.
  for (const Pose& p : poses) {
    EXPECT_LT(Angle(p.joint_rotations[J("l_elbow")].transpose() *
                    Mirror(p.joint_rotations[J("r_elbow")])),
              1e-6);
    EXPECT_LT(Angle(p.joint_rotations[J("l_hip")]), 1e-12);
  }
}

TEST(MotionTest, TurnRotatesAboutTheVerticalAndTheHeadFollows) {
  const std::vector<Pose> poses = Generate(MotionType::kTurn, 120);
  double lo = 1e9, hi = -1e9;
  for (const Pose& p : poses) {
    const Eigen::Vector3d w = LogSO3(p.rotation);
    EXPECT_LT(std::hypot(w.x(), w.z()), 1e-9);  // about Y only
    lo = std::min(lo, w.y());
    hi = std::max(hi, w.y());
    // The pelvis stays on its vertical line.
    const Eigen::Vector3d c = Model().joints[0].center;
    const Eigen::Vector3d posed = p.rotation * c + p.translation;
    EXPECT_LT(std::hypot(posed.x() - c.x(), posed.z() - c.z()), 1e-9);
    // Head yaw has the sign of the body yaw.
    EXPECT_GE(LogSO3(p.joint_rotations[J("neck")]).y() * w.y(), 0.0);
  }
  EXPECT_GT(hi - lo, 60 * kDeg);
  EXPECT_LT(std::max(hi, -lo), 46 * kDeg);
}

TEST(MotionTest, BendFlexesSpineAndHipsWhileLegsStayPut) {
  const Skinning skinning(Model());
  const std::vector<Pose> poses = Generate(MotionType::kBend, 60);
  const Pose& deepest = poses[30];
  const double trunk = LogSO3(deepest.joint_rotations[J("pelvis")]).x() +
                       LogSO3(deepest.joint_rotations[J("spine")]).x() +
                       LogSO3(deepest.joint_rotations[J("chest")]).x();
  EXPECT_GT(trunk, 45 * kDeg);
  EXPECT_GT(LogSO3(deepest.joint_rotations[J("spine")]).x() +
                LogSO3(deepest.joint_rotations[J("chest")]).x(),
            30 * kDeg);
  Eigen::MatrixX3d rest, bent;
  skinning.PosedJointCenters(poses[0], &rest);
  skinning.PosedJointCenters(deepest, &bent);
  EXPECT_GT(bent(J("head"), 2) - rest(J("head"), 2), 0.3);  // head forward
  EXPECT_LT(bent(J("head"), 1), rest(J("head"), 1) - 0.1);  // and down
  for (const char* ankle : {"l_ankle", "r_ankle"}) {
    EXPECT_LT((bent.row(J(ankle)) - rest.row(J(ankle))).norm(), 0.05) << ankle;
  }
  // Arms hang: the upper arms point more downwards in the world than in the A-pose.
  const Eigen::Vector3d arm = (bent.row(J("l_elbow")) - bent.row(J("l_shoulder"))).normalized();
  EXPECT_LT(arm.y(), -0.8);
}

TEST(MotionTest, FeetStayOnTheFloor) {
  const Skinning skinning(Model());
  for (MotionType type : kMoving) {
    SCOPED_TRACE(MotionTypeName(type));
    for (const Pose& p : Generate(type, 90)) {
      Eigen::MatrixX3d posed;
      skinning.Apply(p, &posed);
      EXPECT_NEAR(posed.col(1).minCoeff(), 0.0, 0.02);
      EXPECT_NEAR(LowestFootHeight(Model(), p), 0.0, 1e-9);
    }
  }
  // Floor modes: kKeep leaves y alone; kClipMinimum shifts every frame equally.
  MotionOptions options;
  options.frames = 60;
  options.floor = FloorMode::kKeep;
  const std::vector<Pose> kept = GenerateMotion(Model(), options);
  options.floor = FloorMode::kClipMinimum;
  const std::vector<Pose> clip = GenerateMotion(Model(), options);
  double lowest = 1e9;
  for (size_t f = 0; f < kept.size(); ++f) {
    EXPECT_EQ(kept[f].translation.y(), 0.0);
    EXPECT_NEAR(clip[f].translation.y() - clip[0].translation.y(), 0.0, 1e-12);
    lowest = std::min(lowest, LowestFootHeight(Model(), clip[f]));
  }
  EXPECT_NEAR(lowest, 0.0, 1e-12);
  // In double support (both hips at +-25 degrees) the body is lowered to keep the feet down.
  options.floor = FloorMode::kPerFrame;
  options.frames = 90;
  EXPECT_LT(GenerateMotion(Model(), options)[75].translation.y(), -0.02);
}

TEST(MotionTest, AmplitudeScalesAnglesAndGenerationIsDeterministic) {
  for (MotionType type : kMoving) {
    SCOPED_TRACE(MotionTypeName(type));
    const std::vector<Pose> a = Generate(type, 60, 1.0);
    const std::vector<Pose> b = Generate(type, 60, 1.0);
    const std::vector<Pose> half = Generate(type, 60, 0.5);
    const std::vector<Pose> zero = Generate(type, 60, 0.0);
    double full_max = 0.0, half_max = 0.0;
    for (size_t f = 0; f < a.size(); ++f) {
      EXPECT_EQ(a[f].ToVector(), b[f].ToVector());
      EXPECT_LT(Pose::Identity(17).LocalCoordinates(zero[f]).norm(), 1e-12);
      const Eigen::VectorXd va = a[f].ToVector().tail(3 * 18);
      const Eigen::VectorXd vh = half[f].ToVector().tail(3 * 18);
      full_max = std::max(full_max, va.cwiseAbs().maxCoeff());
      half_max = std::max(half_max, vh.cwiseAbs().maxCoeff());
    }
    EXPECT_NEAR(half_max, 0.5 * full_max, 0.05 * full_max);
  }
}

TEST(MotionTest, LowestFootHeightFollowsTheGlobalTransform) {
  Pose p = Pose::Identity(17);
  EXPECT_NEAR(LowestFootHeight(Model(), p), 0.0, 1e-12);
  p.translation = Eigen::Vector3d(0.3, 0.25, -1.0);
  EXPECT_NEAR(LowestFootHeight(Model(), p), 0.25, 1e-12);
  // Flexing a knee by 90 degrees lifts that foot; the other foot stays lowest.
  p = Pose::Identity(17);
  p.joint_rotations[J("l_knee")] = ExpSO3(Eigen::Vector3d(M_PI / 2, 0, 0));
  EXPECT_NEAR(LowestFootHeight(Model(), p), 0.0, 1e-12);
  p.joint_rotations[J("r_knee")] = ExpSO3(Eigen::Vector3d(M_PI / 2, 0, 0));
  EXPECT_GT(LowestFootHeight(Model(), p), 0.3);
  EXPECT_THROW(LowestFootHeight(Model(), Pose::Identity(3)), Error);
}

// The generated body (coarse resolution): real skinning weights and proportions.
TEST(MotionTest, GeneratedTemplateKeepsFeetOnTheFloorWithSmallSteps) {
  BodyShapeOptions shape;
  shape.resolution = 0;
  const Template body = GenerateTemplate(shape);
  const Skinning skinning(body);
  for (MotionType type : kMoving) {
    SCOPED_TRACE(MotionTypeName(type));
    MotionOptions options;
    options.type = type;
    options.frames = 90;
    const std::vector<Pose> poses = GenerateMotion(body, options);
    Eigen::MatrixX3d prev, cur;
    double max_step = 0.0;
    for (size_t f = 0; f < poses.size(); ++f) {
      skinning.Apply(poses[f], &cur);
      EXPECT_NEAR(cur.col(1).minCoeff(), 0.0, 0.02) << "frame " << f;
      if (f > 0) max_step = std::max(max_step, (cur - prev).rowwise().norm().maxCoeff());
      prev = cur;
    }
    EXPECT_LT(max_step, 0.06);
  }
}

TEST(MotionTest, SpeedAndFrameStepResampleTheMotionInTime) {
  // Frame f at speed s with step n is frame f * s * n of the 1x motion (same time).
  MotionOptions base;
  base.type = MotionType::kWalk;
  base.frames = 61;
  const std::vector<Pose> slow = GenerateMotion(Model(), base);
  MotionOptions fast = base;
  fast.frames = 11;
  fast.speed = 2.0;
  fast.frame_step = 3;
  const std::vector<Pose> quick = GenerateMotion(Model(), fast);
  for (int f = 0; f < fast.frames; ++f) {
    EXPECT_LT(slow[6 * f].LocalCoordinates(quick[f]).norm(), 1e-9) << f;
  }
  MotionOptions bad = base;
  bad.speed = 0.0;
  EXPECT_THROW(GenerateMotion(Model(), bad), Error);
  bad = base;
  bad.frame_step = 0;
  EXPECT_THROW(GenerateMotion(Model(), bad), Error);
}

TEST(MotionTest, PunchKickPunchesKicksAndJumpsFast) {
  const Skinning skinning(Model());
  MotionOptions o;
  o.type = MotionType::kPunchKick;
  o.frames = 121;  // 4 moves of 1 s at 30 Hz = 120 frames
  const std::vector<Pose> poses = GenerateMotion(Model(), o);
  ASSERT_EQ(poses.size(), 121u);
  auto joint_angle = [&](int f, const char* joint) {
    return Angle(poses[f].joint_rotations[J(joint)]);
  };
  // Mid right punch (frame 15), mid left punch (45), mid kick (75), jump flight (105).
  EXPECT_GT(joint_angle(15, "r_shoulder"), 70 * kDeg);
  EXPECT_LT(joint_angle(15, "l_shoulder"), 1 * kDeg);
  EXPECT_GT(joint_angle(45, "l_shoulder"), 70 * kDeg);
  EXPECT_GT(joint_angle(75, "r_hip"), 60 * kDeg);
  const double floor_y = LowestFootHeight(Model(), poses[105]);
  EXPECT_GT(floor_y, 0.12);                                      // in the air
  EXPECT_NEAR(LowestFootHeight(Model(), poses[75]), 0.0, 1e-9);  // standing leg on the floor
  // Every move starts at rest.
  for (int f : {0, 30, 60, 90, 120}) {
    for (int j = 0; j < Model().num_joints(); ++j) {
      EXPECT_LT(Angle(poses[f].joint_rotations[j]), 0.5 * kDeg)
          << f << " " << Model().joints[j].name;
    }
  }
  // Fast: the wrist moves several times faster than in the walk's arm swing.
  double max_wrist_step = 0.0;
  Eigen::MatrixX3d prev, cur, pj, cj;
  for (int f = 1; f < 30; ++f) {
    skinning.PosedJointCenters(poses[f - 1], &pj);
    skinning.PosedJointCenters(poses[f], &cj);
    max_wrist_step = std::max(max_wrist_step, (cj.row(J("r_wrist")) - pj.row(J("r_wrist"))).norm());
  }
  EXPECT_GT(max_wrist_step, 0.04);  // m per frame at 30 Hz
  EXPECT_LT(max_wrist_step, 0.15);
}

}  // namespace
}  // namespace artex
