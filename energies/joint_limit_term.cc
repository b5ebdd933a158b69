#include "energies/joint_limit_term.h"

#include <cmath>
#include <sstream>

#include "models/so3.h"

namespace artex {

bool JointLimitOptions::IsValid(int num_joints, std::string* error) const {
  std::ostringstream msg;
  if (!(std::isfinite(weight) && weight >= 0.0)) {
    msg << "weight: expected a finite value >= 0, found " << weight;
  } else if (!per_joint_min.empty() && static_cast<int>(per_joint_min.size()) != num_joints) {
    msg << "per_joint_min: expected " << num_joints << " entries, found " << per_joint_min.size();
  } else if (per_joint_max.size() != per_joint_min.size()) {
    msg << "per_joint_max: expected " << per_joint_min.size() << " entries (as per_joint_min), found "
        << per_joint_max.size();
  } else if (!(default_min.array() <= default_max.array()).all()) {
    msg << "default_min/default_max: expected min <= max per component";
  } else {
    for (size_t j = 0; j < per_joint_min.size(); ++j) {
      if (!(per_joint_min[j].array() <= per_joint_max[j].array()).all()) {
        msg << "per_joint_min/max[" << j << "]: expected min <= max per component";
        break;
      }
    }
    if (msg.str().empty()) return true;
  }
  if (error) *error = msg.str();
  return false;
}

JointLimitTerm::JointLimitTerm(const JointLimitOptions& options, int num_joints)
    : sqrt_weight_(std::sqrt(options.weight)) {
  for (int j = 0; j < num_joints; ++j) {
    const bool own = !options.per_joint_min.empty();
    min_.push_back(own ? options.per_joint_min[j] : options.default_min);
    max_.push_back(own ? options.per_joint_max[j] : options.default_max);
  }
}

bool JointLimitTerm::Evaluate(const FitEvaluation& eval, double* residuals,
                              double* jacobian) const {
  const int num_joints = static_cast<int>(min_.size());
  const int p = static_cast<int>(eval.delta.size());
  Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> j(
      jacobian, jacobian != nullptr ? 3 * num_joints : 0, p);
  if (jacobian != nullptr) j.setZero();
  for (int k = 0; k < num_joints; ++k) {
    const Eigen::Vector3d phi = LogSO3(eval.pose.joint_rotations[k]);
    Eigen::Matrix3d d_phi;
    if (jacobian != nullptr) d_phi = LeftJacobianInverseSO3(phi) * eval.delta_to_local[k + 1];
    for (int c = 0; c < 3; ++c) {
      double excess = 0.0;
      if (phi[c] > max_[k][c]) excess = phi[c] - max_[k][c];
      if (phi[c] < min_[k][c]) excess = phi[c] - min_[k][c];
      residuals[3 * k + c] = sqrt_weight_ * excess;
      if (jacobian != nullptr && excess != 0.0) {
        j.block<1, 3>(3 * k + c, JointParameterIndex(k)) = sqrt_weight_ * d_phi.row(c);
      }
    }
  }
  if (!Eigen::Map<const Eigen::VectorXd>(residuals, 3 * num_joints).allFinite()) return false;
  return jacobian == nullptr || j.allFinite();
}

}  // namespace artex
