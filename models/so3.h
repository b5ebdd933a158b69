// Rotation helpers on SO(3): exponential/logarithm maps and the swing-twist split.
// Angles in radians; rotation vectors are axis * angle.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace artex {

// Skew-symmetric matrix [w]x with [w]x v = w x v.
Eigen::Matrix3d Skew(const Eigen::Vector3d& w);

// Rodrigues' formula; exact at w = 0.
Eigen::Matrix3d ExpSO3(const Eigen::Vector3d& w);

// Inverse of ExpSO3 for a proper rotation matrix; |result| in [0, pi].
Eigen::Vector3d LogSO3(const Eigen::Matrix3d& r);

// Splits r = swing * twist, where twist is a rotation about the unit axis `axis` and swing
// rotates about an axis perpendicular to it (quaternion swing-twist decomposition).
// The twist angle is returned in (-pi, pi]; a 180-degree swing (singular) yields twist = 0.
struct SwingTwist {
  Eigen::Matrix3d swing;
  Eigen::Matrix3d twist;
  double twist_angle = 0.0;  // signed angle about `axis`
};
SwingTwist DecomposeSwingTwist(const Eigen::Matrix3d& r, const Eigen::Vector3d& axis);

// Nearest rotation (SVD projection, det = +1) to an arbitrary 3x3 matrix.
Eigen::Matrix3d ProjectToRotation(const Eigen::Matrix3d& m);

}  // namespace artex
