// BVH export of a tracked motion (sensors/bvh_export.h), read back by artex's own BVH importer
// (sensors/bvh.h): joint world positions equal the posed joint centres, world rotations the
// accumulated joint rotations, frame count and rate survive.
#include "sensors/bvh_export.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <sstream>

#include "models/error.h"
#include "models/skinning.h"
#include "models/template_generator.h"
#include "sensors/bvh.h"
#include "sensors/motion.h"

namespace artex {
namespace {

TEST(BvhExportTest, ImporterReproducesJointCentresAndRotations) {
  BodyShapeOptions shape;
  shape.resolution = 0;
  const Template tmpl = GenerateTemplate(shape);
  MotionOptions motion;
  motion.frames = 40;
  std::vector<Pose> poses = GenerateMotion(tmpl, motion);
  // A yaw and scale as tracking produces them.
  for (Pose& p : poses) {
    p.scale = 0.97;
    p.rotation = Eigen::AngleAxisd(2.5, Eigen::Vector3d::UnitY()).toRotationMatrix() * p.rotation;
    p.translation += Eigen::Vector3d(0.3, 0.0, 2.0);
  }
  const std::string text = EncodeBvh(tmpl, poses, 30.0);
  std::istringstream in(text);
  const BvhClip clip = ParseBvh(in, "exported.bvh");
  ASSERT_EQ(clip.num_frames(), 40);
  EXPECT_NEAR(clip.frame_time, 1.0 / 30.0, 1e-6);
  const Skinning skinning(tmpl);
  double max_position_error = 0.0, max_rotation_error = 0.0;
  for (int f = 0; f < clip.num_frames(); ++f) {
    std::vector<Eigen::Matrix3d> rotations;
    Eigen::MatrixX3d positions;
    BvhForwardKinematics(clip, BvhFrameAt(clip, f), &rotations, &positions);
    Eigen::MatrixX3d centres;
    skinning.PosedJointCenters(poses[f], &centres);
    std::vector<Eigen::Matrix3d> world(tmpl.num_joints());
    for (int j = 0; j < tmpl.num_joints(); ++j) {
      const int b = clip.FindJoint(tmpl.joints[j].name);
      ASSERT_GE(b, 0) << tmpl.joints[j].name;
      const int parent = tmpl.joints[j].parent;
      world[j] = (parent >= 0 ? world[parent] : poses[f].rotation) * poses[f].joint_rotations[j];
      max_position_error =
          std::max(max_position_error, (positions.row(b) / 100.0 - centres.row(j)).norm());
      max_rotation_error =
          std::max(max_rotation_error, (rotations[b] - world[j]).cwiseAbs().maxCoeff());
    }
  }
  EXPECT_LT(max_position_error, 1e-5);  // 6 decimals of cm
  EXPECT_LT(max_rotation_error, 1e-5);
  // Leaves end in an End Site along their twist axis.
  EXPECT_NE(text.find("End Site"), std::string::npos);
}

TEST(BvhExportTest, EulerAnglesStayContinuous) {
  BodyShapeOptions shape;
  shape.resolution = 0;
  const Template tmpl = GenerateTemplate(shape);
  // A full turn of the root in 1-degree steps: no angle jumps by more than a few degrees.
  std::vector<Pose> poses;
  for (int f = 0; f <= 360; ++f) {
    Pose p = Pose::Identity(tmpl.num_joints());
    p.rotation =
        Eigen::AngleAxisd(f * 3.14159265358979 / 180.0, Eigen::Vector3d(0.2, 1, 0.1).normalized())
            .toRotationMatrix();
    poses.push_back(p);
  }
  std::istringstream in(EncodeBvh(tmpl, poses, 30.0));
  const BvhClip clip = ParseBvh(in, "turn.bvh");
  for (int f = 1; f < clip.num_frames(); ++f) {
    EXPECT_LT((clip.values.row(f).segment(3, 3) - clip.values.row(f - 1).segment(3, 3))
                  .cwiseAbs()
                  .maxCoeff(),
              5.0)
        << "frame " << f;
  }
}

TEST(BvhExportTest, RejectsBadInput) {
  BodyShapeOptions shape;
  shape.resolution = 0;
  const Template tmpl = GenerateTemplate(shape);
  const std::vector<Pose> poses = {Pose::Identity(tmpl.num_joints())};
  BvhExportOptions bad;
  bad.rotation_order = "XXZ";
  EXPECT_THROW(EncodeBvh(tmpl, poses, 30.0, bad), Error);
  EXPECT_THROW(EncodeBvh(tmpl, {}, 30.0), Error);
  EXPECT_THROW(EncodeBvh(tmpl, poses, 0.0), Error);
  EXPECT_THROW(EncodeBvh(tmpl, {Pose::Identity(3)}, 30.0), Error);
}

}  // namespace
}  // namespace artex
