#include "energies/one_to_one_correspondence.h"

#include <cmath>
#include <sstream>

#include "energies/one_to_many_correspondence.h"

namespace artex {

bool OneToOneOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (!(std::isfinite(max_distance) && max_distance > 0.0)) {
    msg << "max_distance: expected a finite value > 0 (m), found " << max_distance;
  } else if (!(std::isfinite(min_normal_dot) && min_normal_dot >= -1.0 && min_normal_dot <= 1.0)) {
    msg << "min_normal_dot: expected a cosine in [-1, 1], found " << min_normal_dot;
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

OneToOneCorrespondenceTerm::OneToOneCorrespondenceTerm(const NearestTargets* targets,
                                                       IcpMetric metric, double weight)
    : targets_(targets), metric_(metric), weight_(weight) {}

bool OneToOneCorrespondenceTerm::Evaluate(const FitEvaluation& eval, double* residuals,
                                          double* jacobian) const {
  const int t_count = targets_->size();
  const int p = static_cast<int>(eval.delta.size());
  const int rows_per_vertex = metric_ == IcpMetric::kPointToPoint ? 3 : 1;
  const int rows = rows_per_vertex * t_count;
  Eigen::Map<Eigen::VectorXd> r(residuals, rows);
  for (int t = 0; t < t_count; ++t) {
    const double sw = std::sqrt(weight_ * targets_->weight[t]);
    const Eigen::Vector3d d = (eval.posed.row(t) - targets_->point.row(t)).transpose();
    if (rows_per_vertex == 3) {
      r.segment<3>(3 * t) = sw * d;
    } else {
      r[t] = sw * targets_->normal.row(t).dot(d.transpose());
    }
  }
  if (!r.allFinite()) return false;
  if (jacobian == nullptr) return true;
  Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> j(
      jacobian, rows, p);
  j.setZero();
  for (int t = 0; t < t_count; ++t) {
    const double sw = std::sqrt(weight_ * targets_->weight[t]);
    if (sw == 0.0) continue;
    const std::vector<int>& cols = eval.jacobian.Columns(t);
    const auto block = eval.jacobian.Block(t);
    for (size_t c = 0; c < cols.size(); ++c) {
      if (rows_per_vertex == 3) {
        j.block<3, 1>(3 * t, cols[c]) = sw * block.col(c);
      } else {
        j(t, cols[c]) = sw * targets_->normal.row(t).dot(block.col(c).transpose());
      }
    }
  }
  LocalToDeltaJacobian(eval, rows, jacobian);
  return j.allFinite();
}

double OneToOneCorrespondenceTerm::AccumulateNormalEquations(const FitEvaluation& eval,
                                                             Eigen::MatrixXd* jtj,
                                                             Eigen::VectorXd* jtr) const {
  return AccumulateVertexResiduals(
      eval, targets_->weight, weight_, targets_->point,
      metric_ == IcpMetric::kPointToPlane ? &targets_->normal : nullptr, jtj, jtr);
}

double OneToOneCorrespondenceTerm::Cost(const FitEvaluation& eval) const {
  return AccumulateVertexResiduals(
      eval, targets_->weight, weight_, targets_->point,
      metric_ == IcpMetric::kPointToPlane ? &targets_->normal : nullptr, nullptr, nullptr);
}

}  // namespace artex
