#include "energies/silhouette_term.h"

#include <cmath>
#include <sstream>

#include "energies/one_to_many_correspondence.h"

namespace artex {

bool SilhouetteTermOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (!(std::isfinite(weight) && weight >= 0.0)) {
    msg << "weight: expected a finite value >= 0, found " << weight;
  } else if (!(max_radius > 0.0)) {
    msg << "max_radius: expected a value > 0 (m), found " << max_radius;
  } else if (!(std::isfinite(front_weight) && front_weight >= 0.0)) {
    msg << "front_weight: expected a finite value >= 0, found " << front_weight;
  } else if (!(std::isfinite(depth_margin) && depth_margin >= 0.0)) {
    msg << "depth_margin: expected a finite value >= 0 (m), found " << depth_margin;
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

void FindSilhouetteViolations(const SilhouetteMap& map, const Eigen::MatrixX3d& posed,
                              const SilhouetteTermOptions& options, SilhouetteTargets* targets) {
  const double depth_margin = options.depth_margin;
  const int t_count = static_cast<int>(posed.rows());
  targets->weight.setZero(t_count);
  targets->depth_weight.setZero(t_count);
  targets->target.setZero(t_count, 3);
  const Eigen::Matrix3d camera_to_world = map.camera.world_to_camera.linear().transpose();
  targets->axis_u = camera_to_world.col(0).transpose().replicate(t_count, 1);
  targets->axis_v = camera_to_world.col(1).transpose().replicate(t_count, 1);
  targets->axis_z = camera_to_world.col(2).transpose().replicate(t_count, 1);
  targets->violations = 0;
  targets->depth_violations = 0;
  for (int t = 0; t < t_count; ++t) {
    double z = 0.0;
    const Eigen::Vector2d uv = map.camera.Project(posed.row(t).transpose(), &z);
    if (!(z > 0.0)) continue;
    const int i = map.RasterIndex(uv.x(), uv.y());
    if (i < 0) continue;
    const float observed = map.free_depth[i];
    if (observed != 0.0f) {
      if (!(z < observed - depth_margin)) continue;  // behind what the camera saw: hidden
      const Eigen::Vector2f q = map.nearest_allowed[i];
      targets->weight[t] = 1.0;
      targets->target.row(t) = map.camera.Unproject(q.x(), q.y(), z).transpose();
      ++targets->violations;
      continue;
    }
    const float surface = map.subject_depth[i];
    if (options.front_weight > 0.0 && surface > 0.0f && z < surface - depth_margin) {
      targets->depth_weight[t] = options.front_weight;
      targets->target.row(t) = map.camera.Unproject(uv.x(), uv.y(), surface).transpose();
      ++targets->violations;
      ++targets->depth_violations;
    }
  }
}

SilhouetteTerm::SilhouetteTerm(const SilhouetteTargets* targets, double weight)
    : targets_(targets), weight_(weight) {}

bool SilhouetteTerm::Evaluate(const FitEvaluation& eval, double* residuals,
                              double* jacobian) const {
  const int t_count = targets_->size();
  const int p = static_cast<int>(eval.delta.size());
  Eigen::Map<Eigen::VectorXd> r(residuals, 3 * t_count);
  for (int t = 0; t < t_count; ++t) {
    const double sw = std::sqrt(weight_ * targets_->weight[t]);
    const double sd = std::sqrt(weight_ * targets_->depth_weight[t]);
    const Eigen::RowVector3d d = eval.posed.row(t) - targets_->target.row(t);
    r[3 * t] = sw * targets_->axis_u.row(t).dot(d);
    r[3 * t + 1] = sw * targets_->axis_v.row(t).dot(d);
    r[3 * t + 2] = sd * targets_->axis_z.row(t).dot(d);
  }
  if (!r.allFinite()) return false;
  if (jacobian == nullptr) return true;
  Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> j(
      jacobian, 3 * t_count, p);
  j.setZero();
  for (int t = 0; t < t_count; ++t) {
    const double sw = std::sqrt(weight_ * targets_->weight[t]);
    const double sd = std::sqrt(weight_ * targets_->depth_weight[t]);
    if (sw == 0.0 && sd == 0.0) continue;
    const std::vector<int>& cols = eval.jacobian.Columns(t);
    const auto block = eval.jacobian.Block(t);
    for (size_t c = 0; c < cols.size(); ++c) {
      const Eigen::Vector3d b = block.col(c);
      j(3 * t, cols[c]) = sw * targets_->axis_u.row(t).dot(b.transpose());
      j(3 * t + 1, cols[c]) = sw * targets_->axis_v.row(t).dot(b.transpose());
      j(3 * t + 2, cols[c]) = sd * targets_->axis_z.row(t).dot(b.transpose());
    }
  }
  LocalToDeltaJacobian(eval, 3 * t_count, jacobian);
  return j.allFinite();
}

double SilhouetteTerm::AccumulateNormalEquations(const FitEvaluation& eval, Eigen::MatrixXd* jtj,
                                                 Eigen::VectorXd* jtr) const {
  double cost = 0.0;
  const int lateral = targets_->violations - targets_->depth_violations;
  if (lateral > 0) {
    cost += AccumulateVertexResiduals(eval, targets_->weight, weight_, targets_->target,
                                      &targets_->axis_u, jtj, jtr) +
            AccumulateVertexResiduals(eval, targets_->weight, weight_, targets_->target,
                                      &targets_->axis_v, jtj, jtr);
  }
  if (targets_->depth_violations > 0) {
    cost += AccumulateVertexResiduals(eval, targets_->depth_weight, weight_, targets_->target,
                                      &targets_->axis_z, jtj, jtr);
  }
  return cost;
}

double SilhouetteTerm::Cost(const FitEvaluation& eval) const {
  return AccumulateNormalEquations(eval, nullptr, nullptr);
}

}  // namespace artex
