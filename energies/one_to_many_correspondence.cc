#include "energies/one_to_many_correspondence.h"

#include <cmath>
#include <limits>
#include <sstream>

#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include "models/pose.h"

namespace artex {

bool OneToManyOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (!(std::isfinite(epsilon) && epsilon > 0.0)) {
    msg << "epsilon: expected a finite value > 0 (m^2), found " << epsilon;
  } else if (!(std::isfinite(lambda_color) && lambda_color >= 0.0)) {
    msg << "lambda_color: expected a finite value >= 0, found " << lambda_color;
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

OneToManyCorrespondenceTerm::OneToManyCorrespondenceTerm(const CorrespondenceTargets* targets,
                                                         double weight)
    : targets_(targets), weight_(weight) {}

bool OneToManyCorrespondenceTerm::Evaluate(const FitEvaluation& eval, double* residuals,
                                           double* jacobian) const {
  const int t_count = targets_->size();
  const int p = static_cast<int>(eval.delta.size());
  Eigen::Map<Eigen::VectorXd> r(residuals, 3 * t_count);
  for (int t = 0; t < t_count; ++t) {
    const double sw = std::sqrt(weight_ * targets_->weight[t]);
    r.segment<3>(3 * t) = sw * (eval.posed.row(t) - targets_->mean.row(t)).transpose();
  }
  if (!r.allFinite()) return false;
  if (jacobian == nullptr) return true;
  Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> j(
      jacobian, 3 * t_count, p);
  j.setZero();
  for (int t = 0; t < t_count; ++t) {
    const double sw = std::sqrt(weight_ * targets_->weight[t]);
    if (sw == 0.0) continue;
    const std::vector<int>& cols = eval.jacobian.Columns(t);
    const auto block = eval.jacobian.Block(t);
    for (size_t c = 0; c < cols.size(); ++c) j.block<3, 1>(3 * t, cols[c]) = sw * block.col(c);
  }
  LocalToDeltaJacobian(eval, 3 * t_count, jacobian);
  return j.allFinite();
}

double OneToManyCorrespondenceTerm::AccumulateNormalEquations(const FitEvaluation& eval,
                                                              Eigen::MatrixXd* jtj,
                                                              Eigen::VectorXd* jtr) const {
  return AccumulateVertexResiduals(eval, targets_->weight, weight_, targets_->mean, nullptr, jtj,
                                   jtr);
}

double OneToManyCorrespondenceTerm::Cost(const FitEvaluation& eval) const {
  return AccumulateVertexResiduals(eval, targets_->weight, weight_, targets_->mean, nullptr,
                                   nullptr, nullptr);
}

namespace {

// Per-thread accumulator: one dense (n x n, n) block per column set (keyed by joint).
struct NormalAccumulator {
  std::vector<Eigen::MatrixXd> h;
  std::vector<Eigen::VectorXd> g;
  double cost = 0.0;
  bool with_jacobian = false;

  NormalAccumulator(int num_joints, bool with_jac) : with_jacobian(with_jac) {
    if (!with_jacobian) return;
    h.resize(num_joints);
    g.resize(num_joints);
  }
};

// Multiplies the rotation column triples of a vertex block by J_l (delta != 0).
void MapBlockToDelta(const FitEvaluation& eval, const std::vector<int>& cols,
                     Eigen::Matrix<double, 3, Eigen::Dynamic>* block) {
  if (eval.delta_is_zero) return;
  const int n = static_cast<int>(cols.size());
  for (int c = 0; c + 2 < n; ++c) {
    const int index = cols[c];
    int rot = -1;
    if (index == kGlobalRotationIndex) {
      rot = 0;
    } else if (index >= kNumGlobalParameters && (index - kNumGlobalParameters) % 3 == 0) {
      rot = 1 + (index - kNumGlobalParameters) / 3;
    }
    if (rot < 0) continue;
    block->middleCols<3>(c) = (block->middleCols<3>(c) * eval.delta_to_local[rot]).eval();
    c += 2;
  }
}

}  // namespace

double AccumulateVertexResiduals(const FitEvaluation& eval, const Eigen::VectorXd& weights,
                                 double c, const Eigen::MatrixX3d& targets,
                                 const Eigen::MatrixX3d* normals, Eigen::MatrixXd* jtj,
                                 Eigen::VectorXd* jtr) {
  const int t_count = static_cast<int>(weights.size());
  const bool with_jacobian = jtj != nullptr && jtr != nullptr;
  const Eigen::VectorXi& vertex_joint = eval.skinning->model().vertex_joint;
  NormalAccumulator init(eval.skinning->model().num_joints(), with_jacobian);
  constexpr int kGrain = 1024;
  NormalAccumulator total = tbb::parallel_reduce(
      tbb::blocked_range<int>(0, t_count, kGrain), init,
      [&](const tbb::blocked_range<int>& range, NormalAccumulator acc) {
        Eigen::Matrix<double, 3, Eigen::Dynamic> block;
        for (int t = range.begin(); t != range.end(); ++t) {
          const double w = c * weights[t];
          if (!(w > 0.0)) continue;
          Eigen::Vector3d d = (eval.posed.row(t) - targets.row(t)).transpose();
          double r2;
          if (normals != nullptr) {
            const Eigen::Vector3d n = normals->row(t).transpose();
            const double e = n.dot(d);
            r2 = e * e;
            d = e * n;  // B^T n n^T d == B^T (n e)
          } else {
            r2 = d.squaredNorm();
          }
          acc.cost += w * r2;
          if (!acc.with_jacobian) continue;
          const std::vector<int>& cols = eval.jacobian.Columns(t);
          block = eval.jacobian.Block(t);
          MapBlockToDelta(eval, cols, &block);
          const int k = vertex_joint[t];
          const int n = static_cast<int>(cols.size());
          if (acc.h[k].rows() != n) {
            acc.h[k].setZero(n, n);
            acc.g[k].setZero(n);
          }
          if (normals != nullptr) {
            const Eigen::VectorXd bn = block.transpose() * normals->row(t).transpose();
            acc.h[k].selfadjointView<Eigen::Lower>().rankUpdate(bn, w);
          } else {
            acc.h[k].selfadjointView<Eigen::Lower>().rankUpdate(block.transpose(), w);
          }
          acc.g[k].noalias() += w * (block.transpose() * d);
        }
        return acc;
      },
      [](NormalAccumulator a, const NormalAccumulator& b) {
        a.cost += b.cost;
        for (size_t k = 0; k < b.h.size(); ++k) {
          if (b.h[k].size() == 0) continue;
          if (a.h[k].size() == 0) {
            a.h[k] = b.h[k];
            a.g[k] = b.g[k];
          } else {
            a.h[k] += b.h[k];
            a.g[k] += b.g[k];
          }
        }
        return a;
      });
  if (with_jacobian) {
    // Any vertex of joint k carries the column set of joint k.
    std::vector<int> first_vertex(total.h.size(), -1);
    for (int t = 0; t < t_count; ++t) {
      if (first_vertex[vertex_joint[t]] < 0) first_vertex[vertex_joint[t]] = t;
    }
    for (size_t k = 0; k < total.h.size(); ++k) {
      if (total.h[k].size() == 0) continue;
      const std::vector<int>& cols = eval.jacobian.Columns(first_vertex[k]);
      const int n = static_cast<int>(cols.size());
      const Eigen::MatrixXd full = total.h[k].selfadjointView<Eigen::Lower>();
      for (int a = 0; a < n; ++a) {
        (*jtr)[cols[a]] += total.g[k][a];
        for (int b = 0; b < n; ++b) (*jtj)(cols[a], cols[b]) += full(a, b);
      }
    }
  }
  return std::isfinite(total.cost) ? total.cost : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace artex
