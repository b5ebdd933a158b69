#include "models/template.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <random>
#include <string>

#include "models/error.h"
#include "models/pose.h"
#include "models/so3.h"

namespace artex {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Four joints (root, a chain of two, a branch), a tetrahedron's worth of triangles.
Template SmallTemplate() {
  Template t;
  const int parents[] = {-1, 0, 1, 0};
  const char* names[] = {"pelvis", "spine", "chest", "l_hip"};
  for (int j = 0; j < 4; ++j) {
    Joint joint;
    joint.name = names[j];
    joint.parent = parents[j];
    joint.center = Eigen::Vector3d(0.1 * j, 1.0 + 0.2 * j, 0.0);
    joint.twist_axis = j == 3 ? Eigen::Vector3d(0, -1, 0) : Eigen::Vector3d(0, 1, 0);
    t.joints.push_back(joint);
  }
  t.vertices.resize(6, 3);
  t.vertices << 0, 0, 0,  //
      1, 0, 0,            //
      0, 1, 0,            //
      0, 0, 1,            //
      1, 1, 0,            //
      0, 1, 1;
  t.triangles.resize(4, 3);
  t.triangles << 0, 2, 1,  //
      0, 1, 3,             //
      0, 3, 2,             //
      1, 2, 3;
  t.uvs = Eigen::MatrixX2d::Constant(4, 2, 0.5);
  t.uv_triangles = Eigen::MatrixX3i::Zero(4, 3);
  t.vertex_joint.resize(6);
  t.vertex_joint << 0, 1, 2, 3, 1, 2;
  t.lbs_weight = Eigen::VectorXd::Constant(6, 0.5);
  t.slerp_tau = Eigen::VectorXd::Constant(6, 0.25);
  return t;
}

// Applies `corrupt` to a valid template and expects IsValid to fail with an error message
// containing `field`.
void ExpectInvalid(const std::function<void(Template*)>& corrupt, const std::string& field) {
  Template t = SmallTemplate();
  corrupt(&t);
  std::string error;
  EXPECT_FALSE(t.IsValid(&error)) << "accepted; expected a complaint about " << field;
  EXPECT_NE(error.find(field), std::string::npos) << "message: " << error;
  EXPECT_FALSE(t.IsValid(nullptr));
}

TEST(TemplateTest, ValidTemplatePasses) {
  const Template t = SmallTemplate();
  std::string error;
  EXPECT_TRUE(t.IsValid(&error)) << error;
  EXPECT_EQ(t.num_pose_parameters(), 7 + 3 * 4);
  EXPECT_TRUE(t.has_uvs());
}

TEST(TemplateTest, ChainAndFindJoint) {
  const Template t = SmallTemplate();
  EXPECT_EQ(t.Chain(2), (std::vector<int>{0, 1, 2}));
  EXPECT_EQ(t.Chain(3), (std::vector<int>{0, 3}));
  EXPECT_EQ(t.Chain(0), (std::vector<int>{0}));
  EXPECT_EQ(t.FindJoint("chest"), 2);
  EXPECT_EQ(t.FindJoint("head"), -1);
}

TEST(TemplateTest, RejectsBadJointTree) {
  // Cycle / parent listed after its child.
  ExpectInvalid([](Template* t) { t->joints[1].parent = 2; }, "joints[1]");
  ExpectInvalid([](Template* t) { t->joints[2].parent = 2; }, "joints[2]");
  ExpectInvalid([](Template* t) { t->joints[3].parent = 7; }, "joints[3]");
  ExpectInvalid([](Template* t) { t->joints[3].parent = -1; }, "joints[3]");
  ExpectInvalid([](Template* t) { t->joints[0].parent = 1; }, "joints[0]");
  ExpectInvalid([](Template* t) { t->joints.clear(); }, "joints");
}

TEST(TemplateTest, RejectsOutOfRangeIndices) {
  ExpectInvalid([](Template* t) { t->triangles(2, 1) = 6; }, "triangles");
  ExpectInvalid([](Template* t) { t->triangles(0, 0) = -1; }, "triangles");
  ExpectInvalid([](Template* t) { t->vertex_joint[4] = 4; }, "vertex_joint");
  ExpectInvalid([](Template* t) { t->vertex_joint[0] = -1; }, "vertex_joint");
  ExpectInvalid([](Template* t) { t->uv_triangles(1, 1) = 4; }, "uv_triangles");
  ExpectInvalid([](Template* t) { t->uv_triangles.resize(3, 3); }, "uv_triangles");
  ExpectInvalid([](Template* t) { t->triangle_chart = Eigen::VectorXi::Zero(2); },
                "triangle_chart");
}

TEST(TemplateTest, RejectsNonFiniteValues) {
  ExpectInvalid([](Template* t) { t->vertices(3, 1) = kNaN; }, "vertices");
  ExpectInvalid([](Template* t) { t->vertices(0, 2) = std::numeric_limits<double>::infinity(); },
                "vertices");
  ExpectInvalid([](Template* t) { t->joints[2].center.x() = kNaN; }, "joints[2]");
  ExpectInvalid([](Template* t) { t->uvs(0, 0) = kNaN; }, "uvs");
  ExpectInvalid([](Template* t) { t->lbs_weight[1] = kNaN; }, "lbs_weight[1]");
  ExpectInvalid([](Template* t) { t->slerp_tau[5] = kNaN; }, "slerp_tau[5]");
}

TEST(TemplateTest, RejectsSkinningConstantsOutsideUnitInterval) {
  ExpectInvalid([](Template* t) { t->lbs_weight[2] = 1.0 + 1e-9; }, "lbs_weight[2]");
  ExpectInvalid([](Template* t) { t->lbs_weight[0] = -0.1; }, "lbs_weight[0]");
  ExpectInvalid([](Template* t) { t->slerp_tau[3] = 1.5; }, "slerp_tau[3]");
  ExpectInvalid([](Template* t) { t->slerp_tau[3] = -1e-6; }, "slerp_tau[3]");
  // Boundary values are valid.
  Template t = SmallTemplate();
  t.lbs_weight[0] = 0.0;
  t.lbs_weight[1] = 1.0;
  t.slerp_tau[0] = 0.0;
  t.slerp_tau[1] = 1.0;
  EXPECT_TRUE(t.IsValid(nullptr));
}

TEST(TemplateTest, RejectsShapeMismatchAndBadAxes) {
  ExpectInvalid([](Template* t) { t->lbs_weight.resize(5); }, "lbs_weight");
  ExpectInvalid([](Template* t) { t->vertex_joint.resize(7); }, "vertex_joint");
  ExpectInvalid([](Template* t) { t->vertices.resize(0, 3); }, "vertices");
  ExpectInvalid([](Template* t) { t->triangles.resize(0, 3); }, "triangles");
  ExpectInvalid([](Template* t) { t->joints[1].twist_axis = Eigen::Vector3d(0, 2, 0); },
                "joints[1]");
  ExpectInvalid([](Template* t) { t->joints[1].twist_axis.setZero(); }, "joints[1]");
}

TEST(PoseTest, IdentityAndSizes) {
  const Pose pose = Pose::Identity(17);
  EXPECT_EQ(pose.num_joints(), 17);
  EXPECT_EQ(pose.num_parameters(), 58);
  EXPECT_EQ(pose.scale, 1.0);
  EXPECT_TRUE(pose.AllFinite());
  EXPECT_EQ(JointParameterIndex(0), 7);
  EXPECT_EQ(JointParameterIndex(16), 55);
}

Pose RandomPose(int num_joints, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  auto vec = [&](double s) -> Eigen::Vector3d {
    return Eigen::Vector3d(u(rng), u(rng), u(rng)) * s;
  };
  Pose pose = Pose::Identity(num_joints);
  pose.scale = 1.0 + 0.5 * u(rng);
  pose.translation = vec(2.0);
  pose.rotation = ExpSO3(vec(1.7));
  for (auto& r : pose.joint_rotations) r = ExpSO3(vec(1.7));
  return pose;
}

TEST(PoseTest, VectorRoundTrip) {
  std::mt19937_64 rng(1);
  for (int trial = 0; trial < 20; ++trial) {
    const Pose pose = RandomPose(5, rng);
    const Eigen::VectorXd v = pose.ToVector();
    ASSERT_EQ(v.size(), pose.num_parameters());
    EXPECT_EQ(v[0], pose.scale);
    const Pose back = Pose::FromVector(v, 5);
    EXPECT_EQ(back.scale, pose.scale);
    EXPECT_LT((back.translation - pose.translation).norm(), 1e-15);
    EXPECT_LT((back.rotation - pose.rotation).norm(), 1e-12);
    ASSERT_EQ(back.num_joints(), 5);
    for (int j = 0; j < 5; ++j) {
      EXPECT_LT((back.joint_rotations[j] - pose.joint_rotations[j]).norm(), 1e-12);
    }
    EXPECT_LT((back.ToVector() - v).norm(), 1e-12);
  }
}

TEST(PoseTest, FromVectorRejectsBadInput) {
  const Eigen::VectorXd good = Pose::Identity(3).ToVector();
  EXPECT_NO_THROW(Pose::FromVector(good, 3));
  try {
    Pose::FromVector(good, 4, "frame 12 of poses.csv");
    ADD_FAILURE() << "wrong length accepted";
  } catch (const Error& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("frame 12 of poses.csv"), std::string::npos) << message;
    EXPECT_NE(message.find("19"), std::string::npos) << message;  // expected 7 + 3 x 4
    EXPECT_NE(message.find("16"), std::string::npos) << message;  // found
  }
  Eigen::VectorXd nan = good;
  nan[9] = kNaN;
  EXPECT_THROW(Pose::FromVector(nan, 3), Error);
  Eigen::VectorXd zero_scale = good;
  zero_scale[0] = 0.0;
  EXPECT_THROW(Pose::FromVector(zero_scale, 3), Error);
  zero_scale[0] = -1.0;
  EXPECT_THROW(Pose::FromVector(zero_scale, 3), Error);
}

TEST(PoseTest, RetractAndLocalCoordinatesAreInverse) {
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  for (int trial = 0; trial < 20; ++trial) {
    const Pose pose = RandomPose(4, rng);
    Eigen::VectorXd delta(pose.num_parameters());
    for (int i = 0; i < delta.size(); ++i) delta[i] = u(rng);
    const Pose moved = pose.Retracted(delta);
    EXPECT_LT((pose.LocalCoordinates(moved) - delta).norm(), 1e-12);
    // Left-multiplicative update: R <- Exp(w) R.
    EXPECT_LT((moved.joint_rotations[2] -
               ExpSO3(delta.segment<3>(JointParameterIndex(2))) * pose.joint_rotations[2])
                  .norm(),
              1e-15);
    EXPECT_NEAR(moved.scale, pose.scale + delta[kScaleIndex], 1e-15);
  }
}

TEST(PoseTest, AllFiniteDetectsNaN) {
  Pose pose = Pose::Identity(2);
  pose.joint_rotations[1](0, 0) = kNaN;
  EXPECT_FALSE(pose.AllFinite());
  pose = Pose::Identity(2);
  pose.translation.y() = kNaN;
  EXPECT_FALSE(pose.AllFinite());
}

}  // namespace
}  // namespace artex
