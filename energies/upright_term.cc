#include "energies/upright_term.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <Eigen/Geometry>

namespace artex {

bool UprightOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (!(std::isfinite(weight) && weight >= 0.0)) {
    msg << "weight: expected a finite value >= 0 (per rad^2), found " << weight;
  } else if (!(max_tilt_deg >= 0.0 && max_tilt_deg < 180.0)) {
    msg << "max_tilt_deg: expected degrees in [0, 180), found " << max_tilt_deg;
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

UprightTerm::UprightTerm(const UprightOptions& options, int pelvis_joint)
    : sqrt_weight_(std::sqrt(options.weight)),
      max_tilt_(options.max_tilt_deg * M_PI / 180.0),
      pelvis_(pelvis_joint) {}

bool UprightTerm::Evaluate(const FitEvaluation& eval, double* residuals,
                           double* jacobian) const {
  const int p = static_cast<int>(eval.delta.size());
  const Eigen::Vector3d y = Eigen::Vector3d::UnitY();
  const bool has_pelvis = pelvis_ >= 0 && pelvis_ < eval.pose.num_joints();
  const Eigen::Matrix3d r0 = eval.pose.rotation;
  const Eigen::Vector3d u =
      has_pelvis ? Eigen::Vector3d(r0 * eval.pose.joint_rotations[pelvis_] * y) : Eigen::Vector3d(r0 * y);
  const double c = std::clamp(u.dot(y), -1.0, 1.0);
  const double tilt = std::acos(c);
  const double excess = std::max(0.0, tilt - max_tilt_);
  residuals[0] = sqrt_weight_ * excess;
  if (jacobian != nullptr) {
    Eigen::Map<Eigen::RowVectorXd> j(jacobian, p);
    j.setZero();
    const double s = std::sqrt(std::max(0.0, 1.0 - c * c));
    if (excess > 0.0 && s > 1e-12) {
      // Left perturbations: R0 <- Exp(dw0) R0 gives du = dw0 x u; R_p <- Exp(dwp) R_p gives
      // du = (R0 dwp) x u. d tilt = -(y . du) / sin(tilt) = -dw . (u x y) / sin(tilt).
      const Eigen::RowVector3d d_local = -sqrt_weight_ * u.cross(y).transpose() / s;
      j.segment<3>(kNumGlobalParameters - 3) = d_local * eval.delta_to_local[0];
      if (has_pelvis) {
        j.segment<3>(JointParameterIndex(pelvis_)) =
            d_local * r0 * eval.delta_to_local[pelvis_ + 1];
      }
    }
  }
  return std::isfinite(residuals[0]);
}

}  // namespace artex
