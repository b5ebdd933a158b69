#include "models/skinning.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <cmath>
#include <sstream>

#include "models/error.h"
#include "models/so3.h"

namespace artex {

namespace {

// Below this |theta| the SLERP weights use their Taylor series (truncation error ~ theta^4).
constexpr double kSlerpSeriesThreshold = 1e-4;
// q.w^2 + (q.vec . a)^2 below this: 180-degree swing, twist angle undefined (derivative 0).
constexpr double kSingularTwistNorm2 = 1e-24;

// Runs body(begin, end) over [0, n), on TBB workers when enabled and worthwhile.
template <typename Body>
void ForEachVertexRange(int n, const SkinningOptions& options, const Body& body) {
  if (!options.parallel || n <= options.grain_size) {
    body(0, n);
    return;
  }
  tbb::parallel_for(tbb::blocked_range<int>(0, n, options.grain_size),
                    [&](const tbb::blocked_range<int>& r) { body(r.begin(), r.end()); });
}

// cos and sin of an angle (one out-of-line function, so that every caller gets the same bits
// for the same angle).
__attribute__((noinline)) void CosSin(double angle, double* c, double* s) {
  *c = std::cos(angle);
  *s = std::sin(angle);
}

}  // namespace

void TwistSlerpWeights(double theta, double tau, double* w_s, double* wbar_s) {
  if (std::abs(theta) < kSlerpSeriesThreshold) {
    // sin(x t) / sin(t) = x (1 + (1 - x^2) t^2 / 6) + O(t^4).
    const double t2 = theta * theta / 6.0;
    const double tau_bar = 1.0 - tau;
    *w_s = tau * (1.0 + (1.0 - tau * tau) * t2);
    *wbar_s = tau_bar * (1.0 + (1.0 - tau_bar * tau_bar) * t2);
    return;
  }
  const double s = std::sin(theta);
  *w_s = std::sin(tau * theta) / s;
  *wbar_s = std::sin((1.0 - tau) * theta) / s;
}

// ---------------------------------------------------------------------------------------------
// SkinningJacobian

Eigen::MatrixXd SkinningJacobian::ToDense() const {
  Eigen::MatrixXd dense = Eigen::MatrixXd::Zero(3 * num_vertices(), num_parameters_);
  for (int v = 0; v < num_vertices(); ++v) {
    const std::vector<int>& cols = Columns(v);
    const auto block = Block(v);
    for (size_t c = 0; c < cols.size(); ++c) dense.block<3, 1>(3 * v, cols[c]) = block.col(c);
  }
  return dense;
}

Eigen::SparseMatrix<double> SkinningJacobian::ToSparse() const {
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(values_.size());
  for (int v = 0; v < num_vertices(); ++v) {
    const std::vector<int>& cols = Columns(v);
    const auto block = Block(v);
    for (size_t c = 0; c < cols.size(); ++c) {
      for (int r = 0; r < 3; ++r) triplets.emplace_back(3 * v + r, cols[c], block(r, c));
    }
  }
  Eigen::SparseMatrix<double> sparse(3 * num_vertices(), num_parameters_);
  sparse.setFromTriplets(triplets.begin(), triplets.end());
  return sparse;
}

// ---------------------------------------------------------------------------------------------
// Skinning

// Per-joint quantities of one pose. With F_j = T_root o ... o T_j (affine, linear part Q_j) and
// F_parent(root) = identity:
//   W_j = R0 Q_parent(j), o_j = R0 F_parent(j)(t_j), c_j = s0 o_j + t0 (posed centre),
// so a vertex of joint k is posed as v' = s0 W_k (B_k(v) - t_k) + c_k.
struct Skinning::JointFrame {
  Eigen::Matrix3d chain_linear;       // Q_j
  Eigen::Vector3d chain_offset;       // F_j(x) = Q_j x + chain_offset
  Eigen::Matrix3d parent_world;       // W_j
  Eigen::Matrix3d scaled_parent;      // s0 W_j
  Eigen::Matrix3d scaled_swing;       // s0 W_j R_j^LBS
  Eigen::Matrix3d swing;              // R_j^LBS
  Eigen::Vector3d center_unscaled;    // o_j
  Eigen::Vector3d center;             // c_j
  double twist_angle = 0.0;           // theta_j, signed, about a_j
  double twist_cos = 1.0;             // cos theta_j, sin theta_j (vertices with tau = 1)
  double twist_sin = 0.0;
  Eigen::RowVector3d twist_gradient;  // d theta_j / d w_j for R_j <- Exp(w_j) R_j
};

Skinning::Skinning(const Template& tmpl, const SkinningOptions& options)
    : template_(tmpl), options_(options) {
  std::string error;
  if (!template_.IsValid(&error)) throw Error("Skinning: invalid template: " + error);
  if (options_.grain_size < 1) {
    std::ostringstream msg;
    msg << "SkinningOptions.grain_size: expected >= 1, found " << options_.grain_size;
    throw Error(msg.str());
  }
  const int num_joints = template_.num_joints();
  const int num_vertices = template_.num_vertices();
  chains_.resize(num_joints);
  axes_.resize(num_joints);
  layout_.num_parameters_ = template_.num_pose_parameters();
  layout_.columns_.resize(num_joints);
  for (int j = 0; j < num_joints; ++j) {
    chains_[j] = template_.Chain(j);
    axes_[j] = template_.joints[j].twist_axis.normalized();
    std::vector<int>& cols = layout_.columns_[j];
    for (int c = 0; c < kNumGlobalParameters; ++c) cols.push_back(c);
    for (int i : chains_[j]) {  // parents precede children: ascending
      for (int c = 0; c < 3; ++c) cols.push_back(JointParameterIndex(i) + c);
    }
  }
  layout_.column_set_.resize(num_vertices);
  layout_.block_offset_.resize(num_vertices + 1);
  layout_.block_offset_[0] = 0;
  for (int v = 0; v < num_vertices; ++v) {
    const int k = template_.vertex_joint[v];
    layout_.column_set_[v] = k;
    layout_.block_offset_[v + 1] =
        layout_.block_offset_[v] + 3 * static_cast<int>(layout_.columns_[k].size());
  }
  PrecomputeRestOffsets();
}

void Skinning::PrecomputeRestOffsets() {
  const int num_vertices = template_.num_vertices();
  axis_foot_.resize(num_vertices, 3);
  offset_.resize(num_vertices, 3);
  radial_.resize(num_vertices, 3);
  for (int v = 0; v < num_vertices; ++v) {
    const int k = template_.vertex_joint[v];
    const Eigen::Vector3d& a = axes_[k];
    const Eigen::Vector3d t = template_.joints[k].center;
    const Eigen::Vector3d x = template_.vertices.row(v).transpose();
    const Eigen::Vector3d foot = t + a * a.dot(x - t);
    axis_foot_.row(v) = foot.transpose();
    offset_.row(v) = (x - t).transpose();
    radial_.row(v) = (x - foot).transpose();
  }
}

void Skinning::SetRestGeometry(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3d& centers) {
  if (vertices.rows() != template_.num_vertices() || centers.rows() != template_.num_joints()) {
    std::ostringstream msg;
    msg << "Skinning::SetRestGeometry: expected " << template_.num_vertices() << " vertices and "
        << template_.num_joints() << " joint centres, found " << vertices.rows() << " and "
        << centers.rows();
    throw Error(msg.str());
  }
  if (!vertices.allFinite() || !centers.allFinite()) {
    throw Error("Skinning::SetRestGeometry: found a non-finite rest coordinate");
  }
  template_.vertices = vertices;
  for (int j = 0; j < template_.num_joints(); ++j) {
    template_.joints[j].center = centers.row(j).transpose();
  }
  PrecomputeRestOffsets();
}

void Skinning::ComputeJointFrames(const Pose& pose, std::vector<JointFrame>* frames) const {
  const int num_joints = template_.num_joints();
  if (pose.num_joints() != num_joints) {
    std::ostringstream msg;
    msg << "Skinning: pose has " << pose.num_joints() << " joint rotations, expected " << num_joints
        << " (template joints)";
    throw Error(msg.str());
  }
  frames->resize(num_joints);
  const double s0 = pose.scale;
  for (int j = 0; j < num_joints; ++j) {
    JointFrame& f = (*frames)[j];
    const Joint& joint = template_.joints[j];
    const Eigen::Matrix3d& r = pose.joint_rotations[j];
    const Eigen::Vector3d& t = joint.center;
    Eigen::Matrix3d parent_linear = Eigen::Matrix3d::Identity();
    Eigen::Vector3d parent_offset = Eigen::Vector3d::Zero();
    if (joint.parent >= 0) {
      parent_linear = (*frames)[joint.parent].chain_linear;
      parent_offset = (*frames)[joint.parent].chain_offset;
    }
    f.chain_linear = parent_linear * r;
    f.chain_offset = parent_linear * (t - r * t) + parent_offset;
    f.parent_world = pose.rotation * parent_linear;
    f.scaled_parent = s0 * f.parent_world;
    f.center_unscaled = pose.rotation * (parent_linear * t + parent_offset);
    f.center = s0 * f.center_unscaled + pose.translation;

    const Eigen::Vector3d& a = axes_[j];
    const SwingTwist st = DecomposeSwingTwist(r, a);
    f.swing = st.swing;
    f.scaled_swing = f.scaled_parent * st.swing;
    f.twist_angle = st.twist_angle;
    CosSin(f.twist_angle, &f.twist_cos, &f.twist_sin);
    // theta = 2 atan2(p, q.w), p = q.vec . a. For R <- Exp(w) R, dq = (0, w/2) (x) q:
    //   dq.w = -q.vec . w / 2,  dp = (q.w a + q.vec x a) . w / 2,
    //   dtheta/dw = (q.w (q.w a + q.vec x a) + p q.vec) / (q.w^2 + p^2),
    // invariant under q -> -q, hence continuous wherever theta is.
    const Eigen::Quaterniond q = Eigen::Quaterniond(r).normalized();
    const double p = q.vec().dot(a);
    const double n2 = q.w() * q.w() + p * p;
    if (n2 < kSingularTwistNorm2) {
      f.twist_gradient.setZero();
    } else {
      f.twist_gradient = ((q.w() * (q.w() * a + q.vec().cross(a)) + p * q.vec()) / n2).transpose();
    }
  }
}

template <bool kWithJacobian>
void Skinning::Evaluate(const Pose& pose, Eigen::MatrixX3d* posed,
                        SkinningJacobian* jacobian) const {
  std::vector<JointFrame> frames;
  ComputeJointFrames(pose, &frames);
  const int num_vertices = template_.num_vertices();
  posed->resize(num_vertices, 3);
  if (kWithJacobian) {
    if (jacobian->num_parameters_ != layout_.num_parameters_ ||
        jacobian->column_set_ != layout_.column_set_ || jacobian->columns_ != layout_.columns_) {
      jacobian->num_parameters_ = layout_.num_parameters_;
      jacobian->columns_ = layout_.columns_;
      jacobian->column_set_ = layout_.column_set_;
      jacobian->block_offset_ = layout_.block_offset_;
    }
    jacobian->values_.resize(layout_.block_offset_.back());
  }
  const Eigen::Vector3d& t0 = pose.translation;

  ForEachVertexRange(num_vertices, options_, [&](int begin, int end) {
    for (int v = begin; v < end; ++v) {
      const int k = template_.vertex_joint[v];
      const JointFrame& f = frames[k];
      const double w = template_.lbs_weight[v];
      const double tau = template_.slerp_tau[v];
      const Eigen::Vector3d& a = axes_[k];
      const Eigen::Vector3d d = radial_.row(v).transpose();
      const Eigen::Vector3d ad = a.cross(d);
      // SLERP bracket on the cylinder: (w_s R^SLERP + wbar_s 1) d = Rot(a, tau theta) d = r.
      // cos and sin of tau theta: a vertex with tau = 1 (its whole segment twists) takes its
      // joint's, tau theta = 0 (tau = 0, untwisted joint) has cos 1 and sin tau theta (+-0) as
      // libm gives them; the same values as evaluating them per vertex, bit for bit.
      const double angle = tau * f.twist_angle;
      double c, s;
      if (tau == 1.0) {
        c = f.twist_cos;
        s = f.twist_sin;
      } else if (angle == 0.0) {
        c = 1.0;
        s = angle;
      } else {
        CosSin(angle, &c, &s);
      }
      // u = r + t' - t_k = (v - t_k) + (r - d)
      const Eigen::Vector3d u = offset_.row(v).transpose() + (c - 1.0) * d + s * ad;
      // v' = s0 W_k (w R^LBS u + (1 - w) u) + c_k
      const Eigen::Vector3d x =
          w * (f.scaled_swing * u) + (1.0 - w) * (f.scaled_parent * u) + f.center;
      posed->row(v) = x.transpose();
      if (!kWithJacobian) continue;

      double* out = jacobian->values_.data() + jacobian->block_offset_[v];
      Eigen::Map<Eigen::Matrix<double, 3, Eigen::Dynamic>> block(
          out, 3, static_cast<Eigen::Index>(layout_.columns_[k].size()));
      // ds: d v' / d s0 = (v' - t0) / s0.
      const Eigen::Vector3d rel = x - t0;
      const Eigen::Vector3d h = f.swing * u;  // R^LBS u
      const Eigen::Vector3d m = w * h + (1.0 - w) * u;
      block.col(0) = f.parent_world * m + f.center_unscaled;
      // dt0: identity.
      block.middleCols<3>(1).setIdentity();
      // w0: R0 <- Exp(w0) R0 gives d v' = w0 x (v' - t0).
      block.middleCols<3>(4) = -Skew(rel);
      // Ancestors i (full rigid T_i): d v' = (W_i w_i) x (v' - c_i).
      const std::vector<int>& chain = chains_[k];
      const int num_chain = static_cast<int>(chain.size());
      for (int ci = 0; ci + 1 < num_chain; ++ci) {
        const JointFrame& fi = frames[chain[ci]];
        block.middleCols<3>(kNumGlobalParameters + 3 * ci) = -Skew(x - fi.center) * fi.parent_world;
      }
      // Own joint k: R_k <- Exp(w) R_k changes R^LBS = R_k R^SLERP^T and theta:
      //   d R^LBS = [w]x R^LBS - R^LBS [a]x dtheta,  d u / dtheta = tau a x r,  a x u = a x r,
      //   d m = -w_l [h]x w + ((tau - 1) w_l R^LBS (a x r) + tau (1 - w_l) (a x r)) dtheta,
      //   d v' = s0 W_k d m, with s0 W_k [h]x = [s0 W_k h]x W_k.
      const Eigen::Vector3d ar = c * ad - s * d;  // a x r, with a x (a x d) = -d
      const Eigen::Vector3d z = (tau - 1.0) * w * (f.swing * ar) + tau * (1.0 - w) * ar;
      block.middleCols<3>(kNumGlobalParameters + 3 * (num_chain - 1)) =
          -w * Skew(f.scaled_parent * h) * f.parent_world +
          (f.scaled_parent * z) * f.twist_gradient;
    }
  });
}

void Skinning::Apply(const Pose& pose, Eigen::MatrixX3d* posed) const {
  Evaluate<false>(pose, posed, nullptr);
}

void Skinning::ApplyWithJacobian(const Pose& pose, Eigen::MatrixX3d* posed,
                                 SkinningJacobian* jacobian) const {
  Evaluate<true>(pose, posed, jacobian);
}

void Skinning::PosedJointCenters(const Pose& pose, Eigen::MatrixX3d* centers) const {
  std::vector<JointFrame> frames;
  ComputeJointFrames(pose, &frames);
  centers->resize(template_.num_joints(), 3);
  for (int j = 0; j < template_.num_joints(); ++j) centers->row(j) = frames[j].center.transpose();
}

}  // namespace artex
