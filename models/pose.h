// Pose parameters theta of the paper (eq. 1, 5): a global similarity (scale s0, translation
// t0, rotation R0) and one rotation R_j per template joint. Rotations are kept as matrices and
// updated on the manifold by left multiplication, R <- Exp(w) R (paper eq. 5).
//
// Tangent (perturbation) layout, used by every Jacobian in artex, P = 7 + 3 J entries:
//   [0] ds   [1..3] dt0 (m)   [4..6] w0 (rad)   [7+3j .. 9+3j] w_j (rad)
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

namespace artex {

constexpr int kScaleIndex = 0;
constexpr int kTranslationIndex = 1;
constexpr int kGlobalRotationIndex = 4;
constexpr int kNumGlobalParameters = 7;
inline int JointParameterIndex(int joint) { return kNumGlobalParameters + 3 * joint; }

struct Pose {
  double scale = 1.0;
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  std::vector<Eigen::Matrix3d> joint_rotations;  // R_1 .. R_J, rest frame

  static Pose Identity(int num_joints);

  int num_joints() const { return static_cast<int>(joint_rotations.size()); }
  int num_parameters() const { return kNumGlobalParameters + 3 * num_joints(); }

  // theta <- theta (+) delta: s += ds, t += dt, R <- Exp(w) R for every rotation.
  // delta has num_parameters() entries.
  void Retract(const Eigen::VectorXd& delta);
  Pose Retracted(const Eigen::VectorXd& delta) const;

  // Tangent vector d with this.Retracted(d) == other (rotations via Log(R_other R_this^T)).
  Eigen::VectorXd LocalCoordinates(const Pose& other) const;

  // Flat vector [s, t(3), r0(3), r_1(3) ... r_J(3)] with rotation vectors (axis * angle);
  // used for CSV/ground-truth files. FromVector throws artex::Error on a wrong length or a
  // non-finite entry, naming `what` (e.g. "frame 12 of poses.csv").
  Eigen::VectorXd ToVector() const;
  static Pose FromVector(const Eigen::VectorXd& v, int num_joints,
                         const std::string& what = "pose vector");

  bool AllFinite() const;
};

}  // namespace artex
