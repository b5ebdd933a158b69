#include "energies/fitting_term.h"

#include <cmath>
#include <limits>
#include <sstream>

#include "models/so3.h"

namespace artex {

namespace {
// Below this rotation angle (rad) the SO(3) Jacobians use their Taylor series.
constexpr double kSmallAngle = 1e-5;
}  // namespace

Eigen::VectorXd PoseGroupWeights::Expand(int num_joints) const {
  Eigen::VectorXd w(kNumGlobalParameters + 3 * num_joints);
  w[kScaleIndex] = scale;
  w.segment<3>(kTranslationIndex).setConstant(translation);
  w.segment<3>(kGlobalRotationIndex).setConstant(rotation);
  w.tail(3 * num_joints).setConstant(joints);
  return w;
}

bool PoseGroupWeights::IsValid(std::string* error) const {
  const char* names[] = {"scale", "translation", "rotation", "joints"};
  const double values[] = {scale, translation, rotation, joints};
  for (int i = 0; i < 4; ++i) {
    if (!(std::isfinite(values[i]) && values[i] >= 0.0)) {
      if (error) {
        std::ostringstream msg;
        msg << names[i] << ": expected a finite weight >= 0, found " << values[i];
        *error = msg.str();
      }
      return false;
    }
  }
  return true;
}

Eigen::Matrix3d LeftJacobianSO3(const Eigen::Vector3d& w) {
  const double theta = w.norm();
  const Eigen::Matrix3d k = Skew(w);
  double a, b;
  if (theta < kSmallAngle) {
    a = 0.5 - theta * theta / 24.0;
    b = 1.0 / 6.0 - theta * theta / 120.0;
  } else {
    a = (1.0 - std::cos(theta)) / (theta * theta);
    b = (theta - std::sin(theta)) / (theta * theta * theta);
  }
  return Eigen::Matrix3d::Identity() + a * k + b * k * k;
}

Eigen::Matrix3d LeftJacobianInverseSO3(const Eigen::Vector3d& w) {
  const double theta = w.norm();
  const Eigen::Matrix3d k = Skew(w);
  double c;
  if (theta < kSmallAngle) {
    c = 1.0 / 12.0 + theta * theta / 720.0;
  } else {
    c = 1.0 / (theta * theta) - (1.0 + std::cos(theta)) / (2.0 * theta * std::sin(theta));
  }
  return Eigen::Matrix3d::Identity() - 0.5 * k + c * k * k;
}

void PrepareFitEvaluation(const Skinning* skinning, const Pose& anchor,
                          const Eigen::VectorXd& delta, bool need_posed, bool need_jacobian,
                          FitEvaluation* eval) {
  const int num_joints = anchor.num_joints();
  eval->skinning = skinning;
  eval->delta = delta;
  eval->pose = anchor.Retracted(delta);
  eval->delta_is_zero = delta.isZero(0.0);
  eval->delta_to_local.resize(1 + num_joints);
  for (int r = 0; r <= num_joints; ++r) {
    const int index = r == 0 ? kGlobalRotationIndex : JointParameterIndex(r - 1);
    eval->delta_to_local[r] = eval->delta_is_zero
                                  ? Eigen::Matrix3d::Identity()
                                  : LeftJacobianSO3(delta.segment<3>(index));
  }
  eval->has_posed = false;
  eval->has_jacobian = false;
  if (!need_posed && !need_jacobian) return;
  if (need_jacobian) {
    skinning->ApplyWithJacobian(eval->pose, &eval->posed, &eval->jacobian);
    eval->has_jacobian = true;
  } else {
    skinning->Apply(eval->pose, &eval->posed);
  }
  eval->has_posed = true;
}

void LocalToDeltaJacobian(const FitEvaluation& eval, int rows, double* jacobian) {
  if (eval.delta_is_zero) return;
  const int p = static_cast<int>(eval.delta.size());
  Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> j(
      jacobian, rows, p);
  for (size_t r = 0; r < eval.delta_to_local.size(); ++r) {
    const int index = r == 0 ? kGlobalRotationIndex : JointParameterIndex(static_cast<int>(r) - 1);
    j.middleCols<3>(index) = (j.middleCols<3>(index) * eval.delta_to_local[r]).eval();
  }
}

double FittingTerm::AccumulateNormalEquations(const FitEvaluation& eval, Eigen::MatrixXd* jtj,
                                              Eigen::VectorXd* jtr) const {
  const int n = num_residuals();
  const int p = static_cast<int>(eval.delta.size());
  if (n == 0) return 0.0;
  Eigen::VectorXd r(n);
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> j(n, p);
  if (!Evaluate(eval, r.data(), j.data())) return std::numeric_limits<double>::quiet_NaN();
  jtj->noalias() += j.transpose() * j;
  jtr->noalias() += j.transpose() * r;
  return r.squaredNorm();
}

double FittingTerm::Cost(const FitEvaluation& eval) const {
  const int n = num_residuals();
  if (n == 0) return 0.0;
  Eigen::VectorXd r(n);
  if (!Evaluate(eval, r.data(), nullptr)) return std::numeric_limits<double>::quiet_NaN();
  return r.squaredNorm();
}

bool ReferencePoseResidual(const Pose& reference, const Eigen::VectorXd& sqrt_weights,
                           const FitEvaluation& eval, double* residuals, double* jacobian) {
  const Pose& pose = eval.pose;
  const int num_joints = pose.num_joints();
  const int p = pose.num_parameters();
  Eigen::Map<Eigen::VectorXd> r(residuals, p);
  r = reference.LocalCoordinates(pose).cwiseProduct(sqrt_weights);
  if (!r.allFinite()) return false;
  if (jacobian == nullptr) return true;
  Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> j(
      jacobian, p, p);
  j.setZero();
  j(kScaleIndex, kScaleIndex) = sqrt_weights[kScaleIndex];
  for (int i = 0; i < 3; ++i) {
    j(kTranslationIndex + i, kTranslationIndex + i) = sqrt_weights[kTranslationIndex + i];
  }
  for (int rot = 0; rot <= num_joints; ++rot) {
    const int index = rot == 0 ? kGlobalRotationIndex : JointParameterIndex(rot - 1);
    const Eigen::Matrix3d& r_now = rot == 0 ? pose.rotation : pose.joint_rotations[rot - 1];
    const Eigen::Matrix3d& r_ref =
        rot == 0 ? reference.rotation : reference.joint_rotations[rot - 1];
    const Eigen::Vector3d phi = LogSO3(r_now * r_ref.transpose());
    const Eigen::Matrix3d block = sqrt_weights.segment<3>(index).asDiagonal() *
                                  LeftJacobianInverseSO3(phi) * eval.delta_to_local[rot];
    j.block<3, 3>(index, index) = block;
  }
  return j.allFinite();
}

}  // namespace artex
