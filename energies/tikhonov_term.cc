#include "energies/tikhonov_term.h"

namespace artex {

bool TikhonovOptions::IsValid(std::string* error) const {
  std::string inner;
  if (!update.IsValid(&inner)) {
    if (error) *error = "update." + inner;
    return false;
  }
  if (!temporal.IsValid(&inner)) {
    if (error) *error = "temporal." + inner;
    return false;
  }
  return true;
}

TikhonovTerm::TikhonovTerm(const TikhonovOptions& options, int num_joints, const Pose* previous)
    : sqrt_update_(options.update.Expand(num_joints).cwiseSqrt()),
      sqrt_temporal_(options.temporal.Expand(num_joints).cwiseSqrt()),
      previous_(options.temporal.AllZero() ? nullptr : previous) {}

int TikhonovTerm::num_residuals() const {
  const int p = static_cast<int>(sqrt_update_.size());
  return previous_ != nullptr ? 2 * p : p;
}

bool TikhonovTerm::Evaluate(const FitEvaluation& eval, double* residuals,
                            double* jacobian) const {
  const int p = static_cast<int>(sqrt_update_.size());
  Eigen::Map<Eigen::VectorXd> r(residuals, p);
  r = sqrt_update_.cwiseProduct(eval.delta);
  if (jacobian != nullptr) {
    Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> j(
        jacobian, p, p);
    j = sqrt_update_.asDiagonal();
  }
  if (!r.allFinite()) return false;
  if (previous_ == nullptr) return true;
  return ReferencePoseResidual(*previous_, sqrt_temporal_, eval, residuals + p,
                               jacobian != nullptr ? jacobian + p * p : nullptr);
}

}  // namespace artex
