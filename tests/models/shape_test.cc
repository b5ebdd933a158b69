#include "models/shape.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "models/error.h"
#include "models/skinning.h"
#include "models/so3.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

using testing_util::CoarseTemplate;

Pose RandomPose(int joints, std::mt19937* rng, double spread) {
  std::normal_distribution<double> n(0.0, spread);
  Pose p = Pose::Identity(joints);
  p.scale = 1.07;
  p.translation = Eigen::Vector3d(0.3, -0.1, 2.0);
  p.rotation = ExpSO3(Eigen::Vector3d(n(*rng), n(*rng), n(*rng)));
  for (auto& r : p.joint_rotations) r = ExpSO3(Eigen::Vector3d(n(*rng), n(*rng), n(*rng)));
  return p;
}

Eigen::VectorXd RandomShape(int q, std::mt19937* rng, double spread) {
  std::uniform_real_distribution<double> u(-spread, spread);
  Eigen::VectorXd x(q);
  for (int i = 0; i < q; ++i) x[i] = u(*rng);
  return x;
}

TEST(ShapeModelTest, ParameterCountsPerMode) {
  const Template& t = CoarseTemplate();
  EXPECT_EQ(ShapeModel(t, ShapeMode::kFixed, true).num_parameters(), 0);
  EXPECT_EQ(ShapeModel(t, ShapeMode::kScale, true).num_parameters(), 1);
  EXPECT_EQ(ShapeModel(t, ShapeMode::kBones, false).num_parameters(), 16);
  // 6 left/right bone pairs shared: pelvis..head 4 + 6 limbs.
  EXPECT_EQ(ShapeModel(t, ShapeMode::kBones, true).num_parameters(), 10);
  EXPECT_EQ(ShapeModel(t, ShapeMode::kBonesGirth, false).num_parameters(), 33);
  EXPECT_EQ(ShapeModel(t, ShapeMode::kBonesGirth, true).num_parameters(), 10 + 11);
  const ShapeModel m(t, ShapeMode::kBonesGirth, true);
  const BodyShape s = m.Expand(Eigen::VectorXd::LinSpaced(m.num_parameters(), 0.01, 0.21));
  EXPECT_EQ(s.bone_length[t.FindJoint("l_elbow")], s.bone_length[t.FindJoint("r_elbow")]);
  EXPECT_EQ(s.girth[t.FindJoint("l_knee")], s.girth[t.FindJoint("r_knee")]);
  EXPECT_NE(s.girth[t.FindJoint("l_knee")], s.girth[t.FindJoint("l_hip")]);
  EXPECT_THROW(m.Expand(Eigen::VectorXd::Zero(3)), Error);
}

TEST(ShapeModelTest, ZeroParametersGiveTheTemplate) {
  const Template& t = CoarseTemplate();
  const ShapeModel m(t, ShapeMode::kBonesGirth, false);
  const Template same = m.Apply(Eigen::VectorXd::Zero(m.num_parameters()));
  EXPECT_LT((same.vertices - t.vertices).cwiseAbs().maxCoeff(), 1e-12);
  for (int j = 0; j < t.num_joints(); ++j) {
    EXPECT_LT((same.joints[j].center - t.joints[j].center).norm(), 1e-12);
  }
  std::string error;
  EXPECT_TRUE(same.IsValid(&error)) << error;
}

TEST(ShapeModelTest, ScaleModeScalesAboutTheRoot) {
  const Template& t = CoarseTemplate();
  const ShapeModel m(t, ShapeMode::kScale, true);
  const Template big = m.Apply(Eigen::VectorXd::Constant(1, 0.1));
  const Eigen::RowVector3d root = t.joints[0].center.transpose();
  const Eigen::MatrixX3d expected = (1.1 * (t.vertices.rowwise() - root)).rowwise() + root;
  EXPECT_LT((big.vertices - expected).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(ShapeModelTest, BoneLengthsScaleJointOffsets) {
  const Template& t = CoarseTemplate();
  const ShapeModel m(t, ShapeMode::kBones, true);
  Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_parameters());
  const auto& names = m.parameter_names();
  const int elbow =
      static_cast<int>(std::find(names.begin(), names.end(), "bone:l_elbow") - names.begin());
  ASSERT_LT(elbow, m.num_parameters());
  q[elbow] = 0.2;
  const Template s = m.Apply(q);
  for (const char* side : {"l_", "r_"}) {
    const int e = t.FindJoint(std::string(side) + "elbow");
    const int sh = t.joints[e].parent;
    const int w = t.FindJoint(std::string(side) + "wrist");
    EXPECT_NEAR((s.joints[e].center - s.joints[sh].center).norm(),
                1.2 * (t.joints[e].center - t.joints[sh].center).norm(), 1e-12);
    // The wrist moves with the elbow (its own bone unchanged).
    EXPECT_NEAR((s.joints[w].center - s.joints[e].center).norm(),
                (t.joints[w].center - t.joints[e].center).norm(), 1e-12);
  }
}

// The analytic Jacobian of the posed vertices w.r.t. the shape parameters against central
// differences of Skinning(Apply(q)).Apply(pose), with and without symmetry, with and without
// the leaf lengths and fork widths, at several poses.
TEST(ShapeModelTest, PosedJacobianMatchesFiniteDifferences) {
  const Template& t = CoarseTemplate();
  std::mt19937 rng(7);
  for (ShapeMode mode : {ShapeMode::kScale, ShapeMode::kBones, ShapeMode::kBonesGirth}) {
    for (int variant = 0; variant < 6; ++variant) {
      const bool symmetric = variant % 2 == 1, extended = variant >= 2, depth = variant >= 4;
      const ShapeModel m(t, mode, symmetric, extended, extended, depth);
      for (int trial = 0; trial < 2; ++trial) {
        const Pose pose = RandomPose(t.num_joints(), &rng, 0.6);
        const Eigen::VectorXd q = RandomShape(m.num_parameters(), &rng, 0.2);
        std::vector<int> vertices;
        for (int v = trial; v < t.num_vertices(); v += 7) vertices.push_back(v);
        Eigen::MatrixXd analytic;
        m.PosedJacobian(pose, vertices, &analytic);
        ASSERT_EQ(analytic.rows(), 3 * static_cast<int>(vertices.size()));
        ASSERT_EQ(analytic.cols(), m.num_parameters());
        const double h = 1e-6;
        double worst = 0.0, largest = 0.0;
        for (int p = 0; p < m.num_parameters(); ++p) {
          Eigen::VectorXd qp = q, qm = q;
          qp[p] += h;
          qm[p] -= h;
          Eigen::MatrixX3d xp, xm;
          Skinning(m.Apply(qp)).Apply(pose, &xp);
          Skinning(m.Apply(qm)).Apply(pose, &xm);
          for (size_t i = 0; i < vertices.size(); ++i) {
            const Eigen::Vector3d fd =
                (xp.row(vertices[i]) - xm.row(vertices[i])).transpose() / (2 * h);
            worst = std::max(worst, (fd - analytic.block<3, 1>(3 * i, p)).cwiseAbs().maxCoeff());
            largest = std::max(largest, fd.cwiseAbs().maxCoeff());
          }
        }
        EXPECT_GT(largest, 0.05) << ShapeModeName(mode);  // the columns are not all zero
        EXPECT_LT(worst, 1e-7) << ShapeModeName(mode) << " symmetric " << symmetric
                               << " leaf lengths and fork widths " << extended << " depth "
                               << depth;
      }
    }
  }
}

// With leaf lengths a foot keeps its length when the shank stretches (and has its own
// factor); with fork widths a shoulder moves across the chest's axis only.
TEST(ShapeModelTest, LeafLengthsAndForkWidths) {
  const Template& t = CoarseTemplate();
  const ShapeModel plain(t, ShapeMode::kBones, true);
  const ShapeModel m(t, ShapeMode::kBones, true, true, true);
  const auto index = [&](const ShapeModel& model, const std::string& name) {
    const auto& names = model.parameter_names();
    return static_cast<int>(std::find(names.begin(), names.end(), name) - names.begin());
  };
  // Symmetric leaves: head, hand, foot; forks: shoulder, hip.
  EXPECT_EQ(m.num_parameters(), plain.num_parameters() + 3 + 2);
  ASSERT_LT(index(m, "length:l_ankle"), m.num_parameters());
  ASSERT_LT(index(m, "width:l_shoulder"), m.num_parameters());
  ASSERT_LT(index(m, "width:l_hip"), m.num_parameters());
  EXPECT_EQ(index(m, "width:l_knee"), m.num_parameters());  // collinear with the thigh
  const int ankle = t.FindJoint("l_ankle");
  const auto foot_extent = [&](const Template& shaped) {
    const Eigen::Vector3d a = t.joints[ankle].twist_axis.normalized();
    double lo = 1e9, hi = -1e9;
    for (int v = 0; v < t.num_vertices(); ++v) {
      if (t.vertex_joint[v] != ankle) continue;
      const double x = a.dot(shaped.vertices.row(v).transpose() - shaped.joints[ankle].center);
      lo = std::min(lo, x);
      hi = std::max(hi, x);
    }
    return hi - lo;
  };
  Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_parameters());
  q[index(m, "bone:l_ankle")] = 0.3;
  EXPECT_NEAR(foot_extent(m.Apply(q)), foot_extent(t), 1e-12);
  Eigen::VectorXd qp = Eigen::VectorXd::Zero(plain.num_parameters());
  qp[index(plain, "bone:l_ankle")] = 0.3;
  EXPECT_NEAR(foot_extent(plain.Apply(qp)), 1.3 * foot_extent(t), 1e-9);
  q[index(m, "length:l_ankle")] = 0.1;
  EXPECT_NEAR(foot_extent(m.Apply(q)), 1.1 * foot_extent(t), 1e-9);
  // Fork width: the shoulder moves across the chest's twist axis, not along it.
  Eigen::VectorXd w = Eigen::VectorXd::Zero(m.num_parameters());
  w[index(m, "width:l_shoulder")] = 0.2;
  const Template wide = m.Apply(w);
  const int shoulder = t.FindJoint("l_shoulder");
  const Eigen::Vector3d axis = t.joints[t.joints[shoulder].parent].twist_axis.normalized();
  const Eigen::Vector3d moved = wide.joints[shoulder].center - t.joints[shoulder].center;
  EXPECT_GT(moved.norm(), 0.01);
  EXPECT_LT(std::abs(moved.dot(axis)), 1e-12);
}

// A depth factor scales a segment's cross-section front to back (+Z for the trunk and limbs,
// +Y for the feet) and leaves its width; girth scales both; without girth_depth the model is
// bones_girth as before.
TEST(ShapeModelTest, DepthFactorScalesTheCrossSectionFrontToBack) {
  const Template& t = CoarseTemplate();
  const ShapeModel plain(t, ShapeMode::kBonesGirth, true, true, true);
  const ShapeModel m(t, ShapeMode::kBonesGirth, true, true, true, true);
  EXPECT_EQ(m.num_parameters(), plain.num_parameters() + 11);
  EXPECT_EQ(ShapeModel(t, ShapeMode::kBones, true, true, true, true).num_parameters(),
            ShapeModel(t, ShapeMode::kBones, true, true, true).num_parameters());
  const auto& names = m.parameter_names();
  const auto index = [&](const std::string& name) {
    return static_cast<int>(std::find(names.begin(), names.end(), name) - names.begin());
  };
  ASSERT_LT(index("depth:l_knee"), m.num_parameters());
  for (int p = 0; p < m.num_parameters(); ++p) {
    EXPECT_EQ(m.IsGirthParameter(p),
              names[p].rfind("girth:", 0) == 0 || names[p].rfind("depth:", 0) == 0)
        << names[p];
    EXPECT_EQ(m.IsDepthParameter(p), names[p].rfind("depth:", 0) == 0) << names[p];
  }
  // The same bones_girth parameters give the same template.
  std::mt19937 rng(5);
  const Eigen::VectorXd qp = RandomShape(plain.num_parameters(), &rng, 0.2);
  Eigen::VectorXd q = Eigen::VectorXd::Zero(m.num_parameters());
  q.head(plain.num_parameters()) = qp;
  EXPECT_LT((m.Apply(q).vertices - plain.Apply(qp).vertices).cwiseAbs().maxCoeff(), 1e-12);
  // Extent of a segment's vertices (those of weight 1: no blending) along an axis through its
  // centre.
  const auto extent = [&](const Template& shaped, int joint, const Eigen::Vector3d& axis) {
    double lo = 1e9, hi = -1e9;
    for (int v = 0; v < t.num_vertices(); ++v) {
      if (t.vertex_joint[v] != joint || t.lbs_weight[v] < 1.0) continue;
      const double x = axis.dot(shaped.vertices.row(v).transpose() - shaped.joints[joint].center);
      lo = std::min(lo, x);
      hi = std::max(hi, x);
    }
    return hi - lo;
  };
  const int chest = t.FindJoint("chest"), ankle = t.FindJoint("l_ankle");
  Eigen::VectorXd d = Eigen::VectorXd::Zero(m.num_parameters());
  d[index("depth:chest")] = 0.25;
  d[index("depth:l_ankle")] = -0.2;
  const Template deep = m.Apply(d);
  EXPECT_NEAR(extent(deep, chest, Eigen::Vector3d::UnitZ()),
              1.25 * extent(t, chest, Eigen::Vector3d::UnitZ()), 1e-9);
  EXPECT_NEAR(extent(deep, chest, Eigen::Vector3d::UnitX()),
              extent(t, chest, Eigen::Vector3d::UnitX()), 1e-9);
  // The foot points forwards (and a little down): its depth axis is +Y across its twist axis.
  const Eigen::Vector3d a = t.joints[ankle].twist_axis.normalized();
  const Eigen::Vector3d up = (Eigen::Vector3d::UnitY() - a.y() * a).normalized();
  EXPECT_NEAR(extent(deep, ankle, up), 0.8 * extent(t, ankle, up), 1e-9);
  EXPECT_NEAR(extent(deep, ankle, a.cross(up)), extent(t, ankle, a.cross(up)), 1e-9);
  EXPECT_NEAR(extent(deep, ankle, a), extent(t, ankle, a), 1e-9);
  for (int j = 0; j < t.num_joints(); ++j) {
    EXPECT_EQ(deep.joints[j].center, t.joints[j].center);  // joints stay
  }
}

TEST(ShapeModelTest, SetRestGeometryEqualsANewSkinning) {
  const Template& t = CoarseTemplate();
  const ShapeModel m(t, ShapeMode::kBonesGirth, true);
  std::mt19937 rng(3);
  const Template shaped = m.Apply(RandomShape(m.num_parameters(), &rng, 0.15));
  Skinning updated(t);
  Eigen::MatrixX3d centers(t.num_joints(), 3);
  for (int j = 0; j < t.num_joints(); ++j) centers.row(j) = shaped.joints[j].center.transpose();
  updated.SetRestGeometry(shaped.vertices, centers);
  const Pose pose = RandomPose(t.num_joints(), &rng, 0.5);
  Eigen::MatrixX3d a, b;
  SkinningJacobian ja, jb;
  updated.ApplyWithJacobian(pose, &a, &ja);
  Skinning(shaped).ApplyWithJacobian(pose, &b, &jb);
  EXPECT_LT((a - b).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((ja.ToDense() - jb.ToDense()).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_THROW(updated.SetRestGeometry(shaped.vertices.topRows(10), centers), Error);
  Eigen::MatrixX3d bad = shaped.vertices;
  bad(0, 0) = std::nan("");
  EXPECT_THROW(updated.SetRestGeometry(bad, centers), Error);
}

}  // namespace
}  // namespace artex
