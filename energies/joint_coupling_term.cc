#include "energies/joint_coupling_term.h"

#include <cmath>

#include "models/so3.h"

namespace artex {

bool JointCouplingOptions::IsValid(std::string* error) const {
  const auto fail = [error](const std::string& m) {
    if (error != nullptr) *error = m;
    return false;
  };
  if (!(std::isfinite(weight) && weight >= 0.0)) {
    return fail("weight: expected a finite value >= 0, found " + std::to_string(weight));
  }
  for (const auto& [a, b] : pairs) {
    if (a == b) return fail("pairs: expected two different joints, found " + a + " twice");
  }
  return true;
}

namespace {
int JointIndex(const std::vector<std::string>& joint_names, const std::string& name) {
  for (std::size_t j = 0; j < joint_names.size(); ++j) {
    if (joint_names[j] == name) return static_cast<int>(j);
  }
  return -1;
}
}  // namespace

JointCouplingTerm::JointCouplingTerm(const JointCouplingOptions& options,
                                     const std::vector<std::string>& joint_names)
    : sqrt_weight_(std::sqrt(options.weight)) {
  for (const auto& [a, b] : options.pairs) {
    const int ia = JointIndex(joint_names, a), ib = JointIndex(joint_names, b);
    if (ia >= 0 && ib >= 0) pairs_.emplace_back(ia, ib);
  }
}

std::string JointCouplingTerm::MissingJoints(const JointCouplingOptions& options,
                                             const std::vector<std::string>& joint_names) {
  std::string missing;
  for (const auto& [a, b] : options.pairs) {
    for (const std::string& name : {a, b}) {
      if (JointIndex(joint_names, name) < 0) missing += (missing.empty() ? "" : ", ") + name;
    }
  }
  return missing;
}

bool JointCouplingTerm::Evaluate(const FitEvaluation& eval, double* residuals,
                                 double* jacobian) const {
  const int n = num_residuals();
  const int p = static_cast<int>(eval.delta.size());
  Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> j(
      jacobian, jacobian != nullptr ? n : 0, p);
  if (jacobian != nullptr) j.setZero();
  for (std::size_t k = 0; k < pairs_.size(); ++k) {
    const auto [a, b] = pairs_[k];
    const Eigen::Vector3d phi_a = LogSO3(eval.pose.joint_rotations[a]);
    const Eigen::Vector3d phi_b = LogSO3(eval.pose.joint_rotations[b]);
    const int row = 3 * static_cast<int>(k);
    Eigen::Map<Eigen::Vector3d>(residuals + row) = sqrt_weight_ * (phi_a - phi_b);
    if (jacobian != nullptr) {
      // d phi / d delta of a joint: J_l(phi)^-1 times the joint's delta-to-local map.
      j.block<3, 3>(row, JointParameterIndex(a)) +=
          sqrt_weight_ * LeftJacobianInverseSO3(phi_a) * eval.delta_to_local[a + 1];
      j.block<3, 3>(row, JointParameterIndex(b)) -=
          sqrt_weight_ * LeftJacobianInverseSO3(phi_b) * eval.delta_to_local[b + 1];
    }
  }
  if (!Eigen::Map<const Eigen::VectorXd>(residuals, n).allFinite()) return false;
  return jacobian == nullptr || j.allFinite();
}

}  // namespace artex
