#include "models/skinning.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "models/error.h"
#include "models/so3.h"

namespace artex {
namespace {

constexpr double kPi = 3.14159265358979323846;

double Uniform(std::mt19937_64& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

Eigen::Vector3d RandomVector(std::mt19937_64& rng, double half_extent) {
  return Eigen::Vector3d(Uniform(rng, -half_extent, half_extent),
                         Uniform(rng, -half_extent, half_extent),
                         Uniform(rng, -half_extent, half_extent));
}

Eigen::Vector3d RandomUnit(std::mt19937_64& rng) {
  Eigen::Vector3d v;
  do {
    v = RandomVector(rng, 1.0);
  } while (v.norm() < 0.1 || v.norm() > 1.0);
  return v.normalized();
}

// Unit vector perpendicular to `a`.
Eigen::Vector3d RandomPerpendicular(std::mt19937_64& rng, const Eigen::Vector3d& a) {
  Eigen::Vector3d v;
  do {
    v = RandomVector(rng, 1.0);
    v -= a * a.dot(v);
  } while (v.norm() < 0.1);
  return v.normalized();
}

Eigen::Matrix3d Rot(const Eigen::Vector3d& axis, double angle) {
  return Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
}

// A small synthetic rigged template: a joint tree mixing chains and branches
// (0 <- 1 <- 2 <- 3, 0 <- 4 <- 5, 0 <- 6), random centres and twist axes, vertices scattered
// around their joint with random w_l, tau (or the fixed values when given, >= 0).
Template MakeTemplate(std::uint64_t seed, int vertices_per_joint, double fixed_lbs = -1.0,
                      double fixed_tau = -1.0) {
  std::mt19937_64 rng(seed);
  Template t;
  const std::vector<int> parents = {-1, 0, 1, 2, 0, 4, 0};
  for (size_t j = 0; j < parents.size(); ++j) {
    Joint joint;
    joint.name = "j" + std::to_string(j);
    joint.parent = parents[j];
    joint.center = RandomVector(rng, 1.0);
    joint.twist_axis = RandomUnit(rng);
    t.joints.push_back(joint);
  }
  const int num_joints = t.num_joints();
  const int num_vertices = num_joints * vertices_per_joint;
  t.vertices.resize(num_vertices, 3);
  t.vertex_joint.resize(num_vertices);
  t.lbs_weight.resize(num_vertices);
  t.slerp_tau.resize(num_vertices);
  for (int v = 0; v < num_vertices; ++v) {
    const int k = v % num_joints;
    t.vertex_joint[v] = k;
    t.vertices.row(v) = (t.joints[k].center + RandomVector(rng, 0.5)).transpose();
    t.lbs_weight[v] = fixed_lbs >= 0.0 ? fixed_lbs : Uniform(rng, 0.0, 1.0);
    t.slerp_tau[v] = fixed_tau >= 0.0 ? fixed_tau : Uniform(rng, 0.0, 1.0);
  }
  // A few extreme skinning constants.
  t.lbs_weight[0] = fixed_lbs >= 0.0 ? fixed_lbs : 0.0;
  t.slerp_tau[1] = fixed_tau >= 0.0 ? fixed_tau : 1.0;
  t.triangles.resize(num_vertices / 3, 3);
  for (int f = 0; f < t.triangles.rows(); ++f) t.triangles.row(f) << 3 * f, 3 * f + 1, 3 * f + 2;
  std::string error;
  EXPECT_TRUE(t.IsValid(&error)) << error;
  return t;
}

// Twist angles exercising the special cases: zero, tiny, near +-pi/2, generic.
double PickTwist(std::mt19937_64& rng) {
  const double choices[] = {0.0,      1e-9,           -1e-7,           3e-5, kPi / 2,
                            -kPi / 2, kPi / 2 - 1e-4, -kPi / 2 + 1e-3, 2.0,  -2.2};
  const int n = sizeof(choices) / sizeof(choices[0]);
  const int i = std::uniform_int_distribution<int>(0, n)(rng);
  return i < n ? choices[i] : Uniform(rng, -2.5, 2.5);
}

// Moderate random pose: swing up to ~70 degrees about an axis perpendicular to a_j, twist
// from PickTwist, random global similarity.
Pose RandomPose(const Template& t, std::mt19937_64& rng) {
  Pose pose = Pose::Identity(t.num_joints());
  pose.scale = Uniform(rng, 0.6, 1.8);
  pose.translation = RandomVector(rng, 1.0);
  pose.rotation = ExpSO3(RandomVector(rng, 1.5));
  for (int j = 0; j < t.num_joints(); ++j) {
    const Eigen::Vector3d& a = t.joints[j].twist_axis;
    const Eigen::Vector3d swing = RandomPerpendicular(rng, a) * Uniform(rng, -1.2, 1.2);
    pose.joint_rotations[j] = ExpSO3(swing) * Rot(a, PickTwist(rng));
  }
  return pose;
}

// Independent forward kinematics of the rigid chain (4x4 homogeneous matrices):
// x' = S R0 * prod_{i in chain(k)} (Trans(t_i) R_i Trans(-t_i)) * x.
Eigen::Vector3d RigidChainReference(const Template& t, const Pose& pose, int vertex) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = pose.scale * pose.rotation;
  m.topRightCorner<3, 1>() = pose.translation;
  std::vector<int> chain;
  for (int j = t.vertex_joint[vertex]; j >= 0; j = t.joints[j].parent)
    chain.insert(chain.begin(), j);
  for (int j : chain) {
    Eigen::Matrix4d to_origin = Eigen::Matrix4d::Identity();
    Eigen::Matrix4d rotate = Eigen::Matrix4d::Identity();
    Eigen::Matrix4d back = Eigen::Matrix4d::Identity();
    to_origin.topRightCorner<3, 1>() = -t.joints[j].center;
    rotate.topLeftCorner<3, 3>() = pose.joint_rotations[j];
    back.topRightCorner<3, 1>() = t.joints[j].center;
    m = m * back * rotate * to_origin;
  }
  const Eigen::Vector4d x(t.vertices(vertex, 0), t.vertices(vertex, 1), t.vertices(vertex, 2), 1.0);
  return (m * x).head<3>();
}

// Literal eq. 1-2 of docs/design.md with the SLERP weights w_s, wbar_s (no cylinder shortcut).
Eigen::Vector3d LiteralReference(const Template& t, const Pose& pose, int vertex) {
  const int k = t.vertex_joint[vertex];
  const Joint& joint = t.joints[k];
  const Eigen::Vector3d a = joint.twist_axis;
  const Eigen::Vector3d v = t.vertices.row(vertex).transpose();
  const Eigen::Vector3d foot = joint.center + a * a.dot(v - joint.center);
  const SwingTwist st = DecomposeSwingTwist(pose.joint_rotations[k], a);
  double w_s, wbar_s;
  TwistSlerpWeights(st.twist_angle, t.slerp_tau[vertex], &w_s, &wbar_s);
  const double w_l = t.lbs_weight[vertex];
  Eigen::Vector3d x = (w_l * st.swing + (1.0 - w_l) * Eigen::Matrix3d::Identity()) *
                          ((w_s * st.twist + wbar_s * Eigen::Matrix3d::Identity()) * (v - foot) +
                           foot - joint.center) +
                      joint.center;
  for (int i = joint.parent; i >= 0; i = t.joints[i].parent) {
    x = pose.joint_rotations[i] * (x - t.joints[i].center) + t.joints[i].center;
  }
  return pose.scale * pose.rotation * x + pose.translation;
}

TEST(SkinningTest, IdentityPoseGivesRestMesh) {
  const Template t = MakeTemplate(1, 20);
  const Skinning skinning(t);
  Eigen::MatrixX3d posed;
  skinning.Apply(Pose::Identity(t.num_joints()), &posed);
  ASSERT_EQ(posed.rows(), t.num_vertices());
  EXPECT_LT((posed - t.vertices).cwiseAbs().maxCoeff(), 1e-14);
}

TEST(SkinningTest, MatchesLiteralEquation) {
  const Template t = MakeTemplate(2, 15);
  const Skinning skinning(t);
  std::mt19937_64 rng(20);
  for (int trial = 0; trial < 20; ++trial) {
    const Pose pose = RandomPose(t, rng);
    Eigen::MatrixX3d posed;
    skinning.Apply(pose, &posed);
    for (int v = 0; v < t.num_vertices(); ++v) {
      const Eigen::Vector3d expected = LiteralReference(t, pose, v);
      EXPECT_LT((posed.row(v).transpose() - expected).norm(), 1e-11) << "vertex " << v;
    }
  }
}

TEST(SkinningTest, SlerpWeightsInterpolateOnTheCylinder) {
  std::mt19937_64 rng(3);
  for (double theta : {0.0, 1e-12, -1e-6, 0.99e-4, 1.01e-4, 0.3, -1.4, 2.9, -3.1}) {
    for (double tau : {0.0, 0.25, 0.5, 1.0}) {
      double w_s, wbar_s;
      TwistSlerpWeights(theta, tau, &w_s, &wbar_s);
      const Eigen::Vector3d a = RandomUnit(rng);
      const Eigen::Vector3d d = RandomPerpendicular(rng, a) * 0.7;
      const Eigen::Vector3d lhs = (w_s * Rot(a, theta) + wbar_s * Eigen::Matrix3d::Identity()) * d;
      const Eigen::Vector3d rhs = Rot(a, tau * theta) * d;
      EXPECT_LT((lhs - rhs).norm(), 1e-12) << "theta " << theta << " tau " << tau;
    }
  }
  // Series limit.
  double w_s, wbar_s;
  TwistSlerpWeights(0.0, 0.3, &w_s, &wbar_s);
  EXPECT_DOUBLE_EQ(w_s, 0.3);
  EXPECT_DOUBLE_EQ(wbar_s, 0.7);
}

TEST(SkinningTest, PureTwistPreservesCylinderAndRotatesByTauTheta) {
  const Template t = MakeTemplate(4, 30);
  const Skinning skinning(t);
  const int k = 2;
  const Joint& joint = t.joints[k];
  const Eigen::Vector3d& a = joint.twist_axis;
  for (double theta : {0.0, 1e-7, 0.7, -1.3, kPi / 2, 3.0}) {
    Pose pose = Pose::Identity(t.num_joints());
    pose.joint_rotations[k] = Rot(a, theta);
    Eigen::MatrixX3d posed;
    skinning.Apply(pose, &posed);
    int checked = 0;
    for (int v = 0; v < t.num_vertices(); ++v) {
      const Eigen::Vector3d x = t.vertices.row(v).transpose();
      const Eigen::Vector3d y = posed.row(v).transpose();
      if (t.vertex_joint[v] != k) {
        // Joints outside k's subtree do not move; the subtree of k (joint 3) moves rigidly.
        if (t.vertex_joint[v] == 3) {
          const Eigen::Vector3d rigid = Rot(a, theta) * (x - joint.center) + joint.center;
          EXPECT_LT((y - rigid).norm(), 1e-12);
        } else {
          EXPECT_LT((y - x).norm(), 1e-14);
        }
        continue;
      }
      const Eigen::Vector3d foot = joint.center + a * a.dot(x - joint.center);
      const Eigen::Vector3d d = x - foot;
      const Eigen::Vector3d e = y - foot;
      EXPECT_NEAR(a.dot(e), 0.0, 1e-12);       // stays in the plane through t'
      EXPECT_NEAR(e.norm(), d.norm(), 1e-12);  // same distance from the axis
      const double angle = std::atan2(a.dot(d.cross(e)), d.dot(e));
      EXPECT_NEAR(angle, t.slerp_tau[v] * theta, 1e-10) << "vertex " << v;
      ++checked;
    }
    EXPECT_EQ(checked, 30);
  }
}

TEST(SkinningTest, FullWeightsReduceToRigidForwardKinematics) {
  const Template t = MakeTemplate(5, 12, /*fixed_lbs=*/1.0, /*fixed_tau=*/1.0);
  const Skinning skinning(t);
  std::mt19937_64 rng(50);
  for (int trial = 0; trial < 20; ++trial) {
    const Pose pose = RandomPose(t, rng);
    Eigen::MatrixX3d posed;
    skinning.Apply(pose, &posed);
    for (int v = 0; v < t.num_vertices(); ++v) {
      EXPECT_LT((posed.row(v).transpose() - RigidChainReference(t, pose, v)).norm(), 1e-12)
          << "vertex " << v;
    }
  }
}

TEST(SkinningTest, PartialWeightsDifferFromRigid) {
  // Guards the previous test against a blend that ignores w_l / tau.
  const Template t = MakeTemplate(5, 12, /*fixed_lbs=*/0.5, /*fixed_tau=*/0.5);
  const Skinning skinning(t);
  std::mt19937_64 rng(51);
  const Pose pose = RandomPose(t, rng);
  Eigen::MatrixX3d posed;
  skinning.Apply(pose, &posed);
  double max_difference = 0.0;
  for (int v = 0; v < t.num_vertices(); ++v) {
    max_difference = std::max(max_difference,
                              (posed.row(v).transpose() - RigidChainReference(t, pose, v)).norm());
  }
  EXPECT_GT(max_difference, 1e-2);
}

TEST(SkinningTest, GlobalSimilarity) {
  const Template t = MakeTemplate(6, 10);
  const Skinning skinning(t);
  std::mt19937_64 rng(60);
  Pose local = RandomPose(t, rng);
  local.scale = 1.0;
  local.translation.setZero();
  local.rotation.setIdentity();
  Pose global = local;
  global.scale = 1.7;
  global.translation = Eigen::Vector3d(0.3, -2.0, 5.0);
  global.rotation = ExpSO3(Eigen::Vector3d(0.4, -1.1, 0.8));
  Eigen::MatrixX3d posed_local, posed_global;
  skinning.Apply(local, &posed_local);
  skinning.Apply(global, &posed_global);
  for (int v = 0; v < t.num_vertices(); ++v) {
    const Eigen::Vector3d expected =
        global.scale * global.rotation * posed_local.row(v).transpose() + global.translation;
    EXPECT_LT((posed_global.row(v).transpose() - expected).norm(), 1e-12);
  }
}

TEST(SkinningTest, PosedJointCentersFollowTheirParentChain) {
  Template t = MakeTemplate(7, 6);
  // Vertex at each joint centre belonging to that joint (any w_l, tau), and one at each
  // non-root joint centre belonging to its parent with w_l = tau = 1 (rigid parent transform).
  const int base = t.num_vertices();
  const int num_joints = t.num_joints();
  const int extra = 2 * num_joints;
  t.vertices.conservativeResize(base + extra, 3);
  t.vertex_joint.conservativeResize(base + extra);
  t.lbs_weight.conservativeResize(base + extra);
  t.slerp_tau.conservativeResize(base + extra);
  for (int j = 0; j < num_joints; ++j) {
    const int own = base + 2 * j;
    const int parent = own + 1;
    t.vertices.row(own) = t.joints[j].center.transpose();
    t.vertex_joint[own] = j;
    t.lbs_weight[own] = 0.3;
    t.slerp_tau[own] = 0.6;
    t.vertices.row(parent) = t.joints[j].center.transpose();
    t.vertex_joint[parent] = std::max(t.joints[j].parent, 0);
    t.lbs_weight[parent] = 1.0;
    t.slerp_tau[parent] = 1.0;
  }
  const Skinning skinning(t);
  std::mt19937_64 rng(70);
  for (int trial = 0; trial < 10; ++trial) {
    const Pose pose = RandomPose(t, rng);
    Eigen::MatrixX3d posed, centers;
    skinning.Apply(pose, &posed);
    skinning.PosedJointCenters(pose, &centers);
    ASSERT_EQ(centers.rows(), num_joints);
    for (int j = 0; j < num_joints; ++j) {
      EXPECT_LT((posed.row(base + 2 * j) - centers.row(j)).norm(), 1e-12) << "joint " << j;
      if (j > 0) {
        EXPECT_LT((posed.row(base + 2 * j + 1) - centers.row(j)).norm(), 1e-12) << "joint " << j;
      }
    }
    // The root centre only moves with the global similarity.
    const Eigen::Vector3d root = pose.scale * pose.rotation * t.joints[0].center + pose.translation;
    EXPECT_LT((centers.row(0).transpose() - root).norm(), 1e-12);
  }
}

// Central differences through Pose::Retracted, all P columns.
Eigen::MatrixXd NumericJacobian(const Skinning& skinning, const Pose& pose, double step) {
  const int p = pose.num_parameters();
  const int n = skinning.model().num_vertices();
  Eigen::MatrixXd jac(3 * n, p);
  Eigen::MatrixX3d plus, minus;
  for (int c = 0; c < p; ++c) {
    Eigen::VectorXd delta = Eigen::VectorXd::Zero(p);
    delta[c] = step;
    skinning.Apply(pose.Retracted(delta), &plus);
    skinning.Apply(pose.Retracted(-delta), &minus);
    const Eigen::MatrixX3d diff = (plus - minus) / (2.0 * step);
    for (int v = 0; v < n; ++v) jac.block<3, 1>(3 * v, c) = diff.row(v).transpose();
  }
  return jac;
}

TEST(SkinningTest, JacobianMatchesCentralDifferences) {
  constexpr double kStep = 1e-6;
  double worst = 0.0;
  int poses = 0;
  for (std::uint64_t seed = 100; seed < 104; ++seed) {
    const Template t = MakeTemplate(seed, 8);
    const Skinning skinning(t);
    std::mt19937_64 rng(seed * 7);
    for (int trial = 0; trial < 15; ++trial, ++poses) {
      const Pose pose = RandomPose(t, rng);
      Eigen::MatrixX3d posed, reference;
      SkinningJacobian jacobian;
      skinning.ApplyWithJacobian(pose, &posed, &jacobian);
      skinning.Apply(pose, &reference);
      EXPECT_LT((posed - reference).cwiseAbs().maxCoeff(), 1e-15);
      ASSERT_EQ(jacobian.num_vertices(), t.num_vertices());
      ASSERT_EQ(jacobian.num_parameters(), t.num_pose_parameters());
      const Eigen::MatrixXd analytic = jacobian.ToDense();
      const Eigen::MatrixXd numeric = NumericJacobian(skinning, pose, kStep);
      for (int v = 0; v < t.num_vertices(); ++v) {
        const double error = (analytic.middleRows<3>(3 * v) - numeric.middleRows<3>(3 * v)).norm() /
                             numeric.middleRows<3>(3 * v).norm();
        worst = std::max(worst, error);
        EXPECT_LT(error, 1e-6) << "seed " << seed << " trial " << trial << " vertex " << v
                               << "\nanalytic\n"
                               << analytic.middleRows<3>(3 * v) << "\nnumeric\n"
                               << numeric.middleRows<3>(3 * v);
      }
    }
  }
  RecordProperty("worst_relative_error", std::to_string(worst));
  std::printf("worst relative Jacobian error over %d poses: %.3g\n", poses, worst);
  EXPECT_EQ(poses, 60);
}

TEST(SkinningTest, TwistGradientNearZeroAndQuarterTurn) {
  // One joint, pure twists near the special angles plus a swing; all vertices at joint 0.
  Template t = MakeTemplate(8, 20);
  for (int v = 0; v < t.num_vertices(); ++v) t.vertex_joint[v] = 0;
  const Skinning skinning(t);
  const Eigen::Vector3d a = t.joints[0].twist_axis;
  std::mt19937_64 rng(80);
  for (double theta : {0.0, 1e-10, -1e-5, kPi / 2, -kPi / 2, kPi / 2 + 1e-6, 3.0}) {
    for (double swing_angle : {0.0, 0.4}) {
      Pose pose = Pose::Identity(t.num_joints());
      pose.joint_rotations[0] = ExpSO3(RandomPerpendicular(rng, a) * swing_angle) * Rot(a, theta);
      Eigen::MatrixX3d posed;
      SkinningJacobian jacobian;
      skinning.ApplyWithJacobian(pose, &posed, &jacobian);
      const Eigen::MatrixXd analytic = jacobian.ToDense();
      const Eigen::MatrixXd numeric = NumericJacobian(skinning, pose, 1e-6);
      const double error = (analytic - numeric).norm() / numeric.norm();
      EXPECT_LT(error, 1e-6) << "theta " << theta << " swing " << swing_angle;
    }
  }
}

TEST(SkinningTest, JacobianLayoutAndSparseForm) {
  const Template t = MakeTemplate(9, 5);
  const Skinning skinning(t);
  std::mt19937_64 rng(90);
  SkinningJacobian jacobian;
  Eigen::MatrixX3d posed;
  for (int trial = 0; trial < 2; ++trial) {  // second call reuses the storage
    const Pose pose = RandomPose(t, rng);
    skinning.ApplyWithJacobian(pose, &posed, &jacobian);
    for (int v = 0; v < t.num_vertices(); ++v) {
      const std::vector<int>& cols = jacobian.Columns(v);
      const std::vector<int> chain = t.Chain(t.vertex_joint[v]);
      ASSERT_EQ(cols.size(), 7 + 3 * chain.size());
      for (int c = 0; c < 7; ++c) EXPECT_EQ(cols[c], c);
      for (size_t i = 0; i < chain.size(); ++i) {
        for (int c = 0; c < 3; ++c)
          EXPECT_EQ(cols[7 + 3 * i + c], JointParameterIndex(chain[i]) + c);
      }
      EXPECT_TRUE(std::is_sorted(cols.begin(), cols.end()));
      EXPECT_EQ(jacobian.Block(v).cols(), static_cast<Eigen::Index>(cols.size()));
      EXPECT_TRUE(jacobian.Block(v).middleCols<3>(1).isIdentity(0.0));
    }
    const Eigen::MatrixXd dense = jacobian.ToDense();
    const Eigen::MatrixXd from_sparse = Eigen::MatrixXd(jacobian.ToSparse());
    EXPECT_EQ((dense - from_sparse).cwiseAbs().maxCoeff(), 0.0);
  }
}

TEST(SkinningTest, ParallelMatchesSerial) {
  const Template t = MakeTemplate(10, 50);
  SkinningOptions serial_options;
  serial_options.parallel = false;
  SkinningOptions parallel_options;
  parallel_options.parallel = true;
  parallel_options.grain_size = 7;
  const Skinning serial(t, serial_options);
  const Skinning parallel(t, parallel_options);
  std::mt19937_64 rng(100);
  const Pose pose = RandomPose(t, rng);
  Eigen::MatrixX3d a, b;
  SkinningJacobian ja, jb;
  serial.ApplyWithJacobian(pose, &a, &ja);
  parallel.ApplyWithJacobian(pose, &b, &jb);
  EXPECT_EQ((a - b).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ((ja.ToDense() - jb.ToDense()).cwiseAbs().maxCoeff(), 0.0);
}

TEST(SkinningTest, RejectsBadInput) {
  Template t = MakeTemplate(11, 3);
  const Skinning skinning(t);
  Eigen::MatrixX3d posed;
  EXPECT_THROW(skinning.Apply(Pose::Identity(t.num_joints() - 1), &posed), Error);
  SkinningJacobian jacobian;
  EXPECT_THROW(skinning.ApplyWithJacobian(Pose::Identity(t.num_joints() + 1), &posed, &jacobian),
               Error);
  SkinningOptions bad_options;
  bad_options.grain_size = 0;
  EXPECT_THROW(Skinning(t, bad_options), Error);
  t.lbs_weight[0] = 2.0;
  try {
    Skinning bad(t);
    ADD_FAILURE() << "an invalid template was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("lbs_weight"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace artex
