#include "models/pose.h"

#include <sstream>

#include "models/error.h"
#include "models/so3.h"

namespace artex {

Pose Pose::Identity(int num_joints) {
  Pose pose;
  pose.joint_rotations.assign(num_joints, Eigen::Matrix3d::Identity());
  return pose;
}

void Pose::Retract(const Eigen::VectorXd& delta) {
  scale += delta[kScaleIndex];
  translation += delta.segment<3>(kTranslationIndex);
  rotation = ExpSO3(delta.segment<3>(kGlobalRotationIndex)) * rotation;
  for (int j = 0; j < num_joints(); ++j) {
    joint_rotations[j] = ExpSO3(delta.segment<3>(JointParameterIndex(j))) * joint_rotations[j];
  }
}

Pose Pose::Retracted(const Eigen::VectorXd& delta) const {
  Pose p = *this;
  p.Retract(delta);
  return p;
}

Eigen::VectorXd Pose::LocalCoordinates(const Pose& other) const {
  Eigen::VectorXd d(num_parameters());
  d[kScaleIndex] = other.scale - scale;
  d.segment<3>(kTranslationIndex) = other.translation - translation;
  d.segment<3>(kGlobalRotationIndex) = LogSO3(other.rotation * rotation.transpose());
  for (int j = 0; j < num_joints(); ++j) {
    d.segment<3>(JointParameterIndex(j)) =
        LogSO3(other.joint_rotations[j] * joint_rotations[j].transpose());
  }
  return d;
}

Eigen::VectorXd Pose::ToVector() const {
  Eigen::VectorXd v(num_parameters());
  v[0] = scale;
  v.segment<3>(1) = translation;
  v.segment<3>(4) = LogSO3(rotation);
  for (int j = 0; j < num_joints(); ++j) v.segment<3>(JointParameterIndex(j)) = LogSO3(joint_rotations[j]);
  return v;
}

Pose Pose::FromVector(const Eigen::VectorXd& v, int num_joints, const std::string& what) {
  const int expected = kNumGlobalParameters + 3 * num_joints;
  if (v.size() != expected) {
    std::ostringstream msg;
    msg << what << ": expected " << expected << " pose parameters (7 + 3 x " << num_joints
        << " joints), found " << v.size();
    throw Error(msg.str());
  }
  if (!v.allFinite()) throw Error(what + ": found a non-finite pose parameter");
  if (!(v[0] > 0.0)) {
    std::ostringstream msg;
    msg << what << ": expected a positive scale, found " << v[0];
    throw Error(msg.str());
  }
  Pose p;
  p.scale = v[0];
  p.translation = v.segment<3>(1);
  p.rotation = ExpSO3(v.segment<3>(4));
  p.joint_rotations.resize(num_joints);
  for (int j = 0; j < num_joints; ++j) p.joint_rotations[j] = ExpSO3(v.segment<3>(JointParameterIndex(j)));
  return p;
}

bool Pose::AllFinite() const {
  if (!std::isfinite(scale) || !translation.allFinite() || !rotation.allFinite()) return false;
  for (const auto& r : joint_rotations) {
    if (!r.allFinite()) return false;
  }
  return true;
}

}  // namespace artex
