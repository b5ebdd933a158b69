#include "energies/one_to_many_correspondence.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <limits>
#include <sstream>

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

// Vertices with w_t > 0 grouped by joint (all vertices of a joint share its column set).
struct JointGroups {
  std::vector<int> offset;  // per joint + 1
  std::vector<int> vertex;
};

}  // namespace

double AccumulateVertexResiduals(const FitEvaluation& eval, const Eigen::VectorXd& weights,
                                 double c, const Eigen::MatrixX3d& targets,
                                 const Eigen::MatrixX3d* normals, Eigen::MatrixXd* jtj,
                                 Eigen::VectorXd* jtr) {
  const int t_count = static_cast<int>(weights.size());
  const bool with_jacobian = jtj != nullptr && jtr != nullptr;
  const Eigen::VectorXi& vertex_joint = eval.skinning->model().vertex_joint;
  const int num_joints = eval.skinning->model().num_joints();
  // Residuals and cost (cheap; serial).
  double cost = 0.0;
  for (int t = 0; t < t_count; ++t) {
    const double w = c * weights[t];
    if (!(w > 0.0)) continue;
    const Eigen::Vector3d d = (eval.posed.row(t) - targets.row(t)).transpose();
    if (normals != nullptr) {
      const double e = normals->row(t).dot(d);
      cost += w * e * e;
    } else {
      cost += w * d.squaredNorm();
    }
  }
  if (!std::isfinite(cost)) return std::numeric_limits<double>::quiet_NaN();
  if (!with_jacobian) return cost;

  // Normal equations per joint k: stack the weighted rows of its vertices,
  // A_k = [sqrt(w_t) B_t] (3 rows per vertex; point-to-plane: 1 row sqrt(w_t) n_t^T B_t) over
  // the joint's column set, and r_k likewise; then H_k = A_k^T A_k (one symmetric rank update,
  // blocked by Eigen) and g_k = A_k^T r_k, scattered into the P x P system.
  JointGroups groups;
  groups.offset.assign(num_joints + 1, 0);
  for (int t = 0; t < t_count; ++t) {
    if (c * weights[t] > 0.0) ++groups.offset[vertex_joint[t] + 1];
  }
  for (int k = 0; k < num_joints; ++k) groups.offset[k + 1] += groups.offset[k];
  groups.vertex.resize(groups.offset.back());
  {
    std::vector<int> fill(groups.offset.begin(), groups.offset.end() - 1);
    for (int t = 0; t < t_count; ++t) {
      if (c * weights[t] > 0.0) groups.vertex[fill[vertex_joint[t]]++] = t;
    }
  }
  const int rows_per_vertex = normals != nullptr ? 1 : 3;
  std::vector<Eigen::MatrixXd> h(num_joints);
  std::vector<Eigen::VectorXd> g(num_joints);
  std::vector<int> first_vertex(num_joints, -1);
  tbb::parallel_for(0, num_joints, [&](int k) {
    const int begin = groups.offset[k], end = groups.offset[k + 1];
    if (begin == end) return;
    const int first = groups.vertex[begin];
    first_vertex[k] = first;
    const int n = static_cast<int>(eval.jacobian.Columns(first).size());
    const int m = end - begin;
    // The stacked rows in buffers of this thread, grown as needed and kept: no allocation per
    // joint and call (with one malloc arena for all threads, pipeline.heap_arenas, the
    // workers' allocations would wait for each other). Nothing else runs on this thread while
    // they are in use: the body does not wait for other tasks.
    thread_local Eigen::MatrixXd a_buffer;
    thread_local Eigen::VectorXd r_buffer;
    thread_local Eigen::Matrix<double, 3, Eigen::Dynamic> block;
    const Eigen::Index rows = static_cast<Eigen::Index>(rows_per_vertex) * m;
    if (a_buffer.size() < rows * n) a_buffer.resize(rows * n, 1);
    if (r_buffer.size() < rows) r_buffer.resize(rows);
    Eigen::Map<Eigen::MatrixXd, Eigen::AlignedMax> a(a_buffer.data(), rows, n);
    Eigen::Map<Eigen::VectorXd, Eigen::AlignedMax> r(r_buffer.data(), rows);
    for (int i = 0; i < m; ++i) {
      const int t = groups.vertex[begin + i];
      const double sw = std::sqrt(c * weights[t]);
      const Eigen::Vector3d d = (eval.posed.row(t) - targets.row(t)).transpose();
      block = eval.jacobian.Block(t);
      MapBlockToDelta(eval, eval.jacobian.Columns(t), &block);
      if (normals != nullptr) {
        const Eigen::Vector3d nt = normals->row(t).transpose();
        a.row(i).noalias() = sw * (nt.transpose() * block);
        r[i] = sw * nt.dot(d);
      } else {
        a.middleRows<3>(3 * i) = sw * block;
        r.segment<3>(3 * i) = sw * d;
      }
    }
    h[k].setZero(n, n);
    h[k].selfadjointView<Eigen::Lower>().rankUpdate(a.transpose());
    g[k].noalias() = a.transpose() * r;
  });
  for (int k = 0; k < num_joints; ++k) {
    if (first_vertex[k] < 0) continue;
    const std::vector<int>& cols = eval.jacobian.Columns(first_vertex[k]);
    const int n = static_cast<int>(cols.size());
    for (int a = 0; a < n; ++a) {
      (*jtr)[cols[a]] += g[k][a];
      for (int b = 0; b <= a; ++b) {
        const double v = h[k](a, b);
        (*jtj)(cols[a], cols[b]) += v;
        if (a != b) (*jtj)(cols[b], cols[a]) += v;
      }
    }
  }
  return cost;
}

}  // namespace artex
