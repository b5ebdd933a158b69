#include "energies/unobserved_joint_term.h"

#include <cmath>
#include <sstream>

namespace artex {

bool UnobservedJointOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (!(std::isfinite(weight) && weight >= 0.0)) {
    msg << "weight: expected a finite value >= 0 (per rad^2), found " << weight;
  } else if (!(min_observed_fraction >= 0.0 && min_observed_fraction <= 1.0)) {
    msg << "min_observed_fraction: expected a value in [0, 1], found " << min_observed_fraction;
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

std::vector<int> UnobservedJoints(const Eigen::VectorXi& vertex_joint,
                                  const Eigen::VectorXd& matched, int num_joints,
                                  double fraction) {
  std::vector<int> total(num_joints, 0), hit(num_joints, 0);
  const int n = static_cast<int>(std::min<Eigen::Index>(vertex_joint.size(), matched.size()));
  for (int i = 0; i < n; ++i) {
    const int j = vertex_joint[i];
    if (j < 0 || j >= num_joints) continue;
    ++total[j];
    if (matched[i] > 0.0) ++hit[j];
  }
  std::vector<int> out;
  for (int j = 0; j < num_joints; ++j) {
    if (total[j] > 0 && hit[j] < fraction * total[j]) out.push_back(j);
  }
  return out;
}

UnobservedJointTerm::UnobservedJointTerm(const Pose* reference, const std::vector<int>& joints,
                                         double weight)
    : reference_(reference) {
  sqrt_weights_.setZero(reference->num_parameters());
  const double sw = std::sqrt(weight);
  for (int j : joints) sqrt_weights_.segment<3>(JointParameterIndex(j)).setConstant(sw);
}

bool UnobservedJointTerm::Evaluate(const FitEvaluation& eval, double* residuals,
                                   double* jacobian) const {
  return ReferencePoseResidual(*reference_, sqrt_weights_, eval, residuals, jacobian);
}

}  // namespace artex
