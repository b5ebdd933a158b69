// Soft joint-angle limits: a box per joint on the rotation-vector components phi_j = Log(R_j)
// (R_j relative to the rest pose, rest frame, radians). Hinge-squared penalty per component:
//   r_jc = sqrt(w) * (max(0, phi_jc - max_jc) + min(0, phi_jc - min_jc))     (3 J residuals)
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "energies/fitting_term.h"

namespace artex {

struct JointLimitOptions {
  double weight = 0.0;  // w (cost units per rad^2); 0 disables the prior
  // Box applied to every joint without an entry in `per_joint_min/max` (rad).
  Eigen::Vector3d default_min = Eigen::Vector3d::Constant(-2.5);
  Eigen::Vector3d default_max = Eigen::Vector3d::Constant(2.5);
  // Optional per-joint boxes: empty, or one entry per template joint.
  std::vector<Eigen::Vector3d> per_joint_min;
  std::vector<Eigen::Vector3d> per_joint_max;

  // Checks weight >= 0, min <= max and the per-joint sizes against `num_joints`.
  bool IsValid(int num_joints, std::string* error) const;
};

class JointLimitTerm : public FittingTerm {
 public:
  JointLimitTerm(const JointLimitOptions& options, int num_joints);

  std::string name() const override { return "joint_limits"; }
  int num_residuals() const override { return 3 * static_cast<int>(min_.size()); }
  bool Evaluate(const FitEvaluation& eval, double* residuals, double* jacobian) const override;

 private:
  double sqrt_weight_;
  std::vector<Eigen::Vector3d> min_, max_;
};

}  // namespace artex
