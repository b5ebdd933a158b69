#include "models/shape.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "models/error.h"
#include "models/so3.h"

namespace artex {

const std::map<std::string, ShapeMode>& ShapeModeNames() {
  static const std::map<std::string, ShapeMode> kNames = {{"fixed", ShapeMode::kFixed},
                                                          {"scale", ShapeMode::kScale},
                                                          {"bones", ShapeMode::kBones},
                                                          {"bones_girth", ShapeMode::kBonesGirth}};
  return kNames;
}

const char* ShapeModeName(ShapeMode mode) {
  switch (mode) {
    case ShapeMode::kFixed:
      return "fixed";
    case ShapeMode::kScale:
      return "scale";
    case ShapeMode::kBones:
      return "bones";
    case ShapeMode::kBonesGirth:
      return "bones_girth";
  }
  return "?";
}

BodyShape BodyShape::Identity(int num_joints) {
  BodyShape s;
  s.bone_length = Eigen::VectorXd::Ones(num_joints);
  s.girth = Eigen::VectorXd::Ones(num_joints);
  s.leaf_length = Eigen::VectorXd::Ones(num_joints);
  s.fork_width = Eigen::VectorXd::Ones(num_joints);
  s.depth = Eigen::VectorXd::Ones(num_joints);
  return s;
}

namespace {
// Index of the l_ counterpart of an r_ joint (-1 when none or not an r_ joint).
int MirrorOf(const Template& t, int j) {
  const std::string& name = t.joints[j].name;
  if (name.rfind("r_", 0) != 0) return -1;
  return t.FindJoint("l_" + name.substr(2));
}
}  // namespace

ShapeModel::ShapeModel(const Template& base, ShapeMode mode, bool symmetric, bool leaf_lengths,
                       bool fork_widths, bool girth_depth)
    : base_(base), mode_(mode), girth_depth_(girth_depth && mode == ShapeMode::kBonesGirth) {
  std::string error;
  if (!base_.IsValid(&error)) throw Error("ShapeModel: invalid template: " + error);
  const int nj = base_.num_joints();
  const int nv = base_.num_vertices();
  bone_offset_.assign(nj, Eigen::Vector3d::Zero());
  for (int j = 1; j < nj; ++j) {
    bone_offset_[j] = base_.joints[j].center - base_.joints[base_.joints[j].parent].center;
  }
  // Segment stretch: the child bone along the twist axis, a leaf's own bone, else none.
  segment_bone_.assign(nj, -1);
  for (int j = 0; j < nj; ++j) {
    bool has_child = false;
    double best = 0.9;
    for (int c = j + 1; c < nj; ++c) {
      if (base_.joints[c].parent != j) continue;
      has_child = true;
      const double n = bone_offset_[c].norm();
      if (n <= 0) continue;
      const double cosine = bone_offset_[c].dot(base_.joints[j].twist_axis) / n;
      if (cosine >= best) {
        best = cosine;
        segment_bone_[j] = c;
      }
    }
    if (!has_child && j > 0) segment_bone_[j] = j;
  }
  // The full row whose factor stretches segment j: its bone's, or a leaf's own length.
  const bool per_bone = mode_ == ShapeMode::kBones || mode_ == ShapeMode::kBonesGirth;
  const bool leaves = leaf_lengths && per_bone;
  // Forks: a bone mostly across its parent's twist axis (|lateral| > 0.5 |offset|: the
  // shoulders, the hips) with fork_widths gets a width factor on that lateral component; its
  // bone factor then scales the component along the axis only.
  fork_.assign(nj, false);
  bone_axial_.assign(nj, Eigen::Vector3d::Zero());
  bone_lateral_.assign(nj, Eigen::Vector3d::Zero());
  for (int j = 1; j < nj; ++j) {
    const Eigen::Vector3d a = base_.joints[base_.joints[j].parent].twist_axis.normalized();
    bone_axial_[j] = a.dot(bone_offset_[j]) * a;
    bone_lateral_[j] = bone_offset_[j] - bone_axial_[j];
    fork_[j] = fork_widths && per_bone && bone_lateral_[j].norm() > 0.5 * bone_offset_[j].norm();
  }
  stretch_row_ = segment_bone_;
  for (int j = 1; j < nj; ++j) {
    if (leaves && segment_bone_[j] == j) stretch_row_[j] = 2 * nj + j;
  }
  alpha_.resize(nv);
  rho_.resize(nv, 3);
  for (int v = 0; v < nv; ++v) {
    const int k = base_.vertex_joint[v];
    const Eigen::Vector3d a = base_.joints[k].twist_axis.normalized();
    const Eigen::Vector3d o = base_.vertices.row(v).transpose() - base_.joints[k].center;
    alpha_[v] = a.dot(o);
    rho_.row(v) = (o - alpha_[v] * a).transpose();
  }
  // Depth axes: +Z (the template faces it) across the twist axis; +Y for a segment along Z.
  if (girth_depth_) {
    std::vector<Eigen::Vector3d> depth_axis(nj);
    for (int j = 0; j < nj; ++j) {
      const Eigen::Vector3d a = base_.joints[j].twist_axis.normalized();
      Eigen::Vector3d d = Eigen::Vector3d::UnitZ() - a.z() * a;
      if (d.norm() < 0.5) d = Eigen::Vector3d::UnitY() - a.y() * a;
      depth_axis[j] = d.normalized();
    }
    rho_depth_.resize(nv, 3);
    for (int v = 0; v < nv; ++v) {
      const Eigen::Vector3d& d = depth_axis[base_.vertex_joint[v]];
      rho_depth_.row(v) = rho_.row(v).dot(d.transpose()) * d.transpose();
    }
  }
  // Reduced parameters.
  std::vector<std::vector<int>> rows;  // full rows of each reduced parameter
  if (mode_ == ShapeMode::kScale) {
    names_.push_back("scale");
    rows.emplace_back();
    for (int j = 1; j < nj; ++j) rows.back().push_back(j);
    for (int j = 0; j < nj; ++j) rows.back().push_back(nj + j);
  } else if (mode_ == ShapeMode::kBones || mode_ == ShapeMode::kBonesGirth) {
    const int groups = mode_ == ShapeMode::kBones ? 1 : 2;
    for (int g : {0, 1, 2, 3, 4}) {
      if (g == 1 && groups < 2) continue;
      if (g == 2 && !leaves) continue;
      if (g == 4 && !girth_depth_) continue;
      std::vector<int> index_of(nj, -1);
      for (int j = g == 0 ? 1 : 0; j < nj; ++j) {
        if (g == 2 && stretch_row_[j] != 2 * nj + j) continue;  // leaves only
        if (g == 3 && !fork_[j]) continue;                       // forks only
        const int mirror = symmetric ? MirrorOf(base_, j) : -1;
        if (mirror >= 0 && index_of[mirror] >= 0) {
          rows[index_of[mirror]].push_back(g * nj + j);
          continue;
        }
        index_of[j] = static_cast<int>(rows.size());
        static const char* const kPrefix[] = {"bone:", "girth:", "length:", "width:", "depth:"};
        names_.push_back(kPrefix[g] + base_.joints[j].name);
        rows.push_back({g * nj + j});
      }
    }
  }
  expansion_ = Eigen::MatrixXd::Zero(full_rows(), static_cast<int>(names_.size()));
  for (size_t p = 0; p < rows.size(); ++p) {
    for (int r : rows[p]) expansion_(r, static_cast<int>(p)) = 1.0;
  }
}

BodyShape ShapeModel::Expand(const Eigen::VectorXd& q) const {
  if (q.size() != num_parameters()) {
    std::ostringstream msg;
    msg << "shape parameters: expected " << num_parameters() << " entries (mode "
        << ShapeModeName(mode_) << "), found " << q.size();
    throw Error(msg.str());
  }
  const int nj = base_.num_joints();
  const int rows = full_rows();
  const Eigen::VectorXd full =
      Eigen::VectorXd::Ones(rows) +
      (q.size() ? Eigen::VectorXd(expansion_ * q) : Eigen::VectorXd::Zero(rows));
  BodyShape s;
  s.bone_length = full.head(nj);
  s.bone_length[0] = 1.0;
  s.girth = full.segment(nj, nj);
  s.leaf_length = full.segment(2 * nj, nj);
  s.fork_width = full.segment(3 * nj, nj);
  s.depth = girth_depth_ ? Eigen::VectorXd(full.segment(4 * nj, nj))
                         : Eigen::VectorXd(Eigen::VectorXd::Ones(nj));
  return s;
}

void ShapeModel::RestGeometry(const Eigen::VectorXd& q, Eigen::MatrixX3d* centers,
                              Eigen::MatrixX3d* vertices) const {
  const BodyShape s = Expand(q);
  const int nj = base_.num_joints();
  centers->resize(nj, 3);
  centers->row(0) = base_.joints[0].center.transpose();
  for (int j = 1; j < nj; ++j) {
    const Eigen::Vector3d offset =
        fork_[j] ? Eigen::Vector3d(s.bone_length[j] * bone_axial_[j] +
                                   s.fork_width[j] * bone_lateral_[j])
                 : Eigen::Vector3d(s.bone_length[j] * bone_offset_[j]);
    centers->row(j) = centers->row(base_.joints[j].parent) + offset.transpose();
  }
  const int nv = base_.num_vertices();
  vertices->resize(nv, 3);
  for (int v = 0; v < nv; ++v) {
    const int k = base_.vertex_joint[v];
    const int parent = std::max(0, base_.joints[k].parent);  // the root blends with itself
    const double w = base_.lbs_weight[v];
    // A cross-section factor blended across the joint like the skinning.
    const auto blend = [&](const Eigen::VectorXd& f) { return w * f[k] + (1.0 - w) * f[parent]; };
    const double g = blend(s.girth);
    const int row = stretch_row_[k];
    const double l = row < 0 ? 1.0 : row < nj ? s.bone_length[row] : s.leaf_length[row - 2 * nj];
    const Eigen::Vector3d a = base_.joints[k].twist_axis.normalized();
    vertices->row(v) = centers->row(k) + (l * alpha_[v]) * a.transpose() + g * rho_.row(v);
    if (girth_depth_) {
      vertices->row(v) += (blend(s.depth) - 1.0) * rho_depth_.row(v);
    }
  }
}

Template ShapeModel::Apply(const Eigen::VectorXd& q) const {
  Template t = base_;
  Eigen::MatrixX3d centers;
  RestGeometry(q, &centers, &t.vertices);
  for (int j = 0; j < t.num_joints(); ++j) t.joints[j].center = centers.row(j).transpose();
  return t;
}

void ShapeModel::PosedJacobian(const Pose& pose, const std::vector<int>& vertices,
                               Eigen::MatrixXd* jacobian) const {
  const int nj = base_.num_joints();
  if (pose.num_joints() != nj) {
    std::ostringstream msg;
    msg << "ShapeModel::PosedJacobian: pose has " << pose.num_joints() << " joints, expected "
        << nj;
    throw Error(msg.str());
  }
  // Per joint: W_j = R0 Q_parent(j) (Q: chain linear part), swing R^LBS and twist angle.
  std::vector<Eigen::Matrix3d> chain(nj), world(nj), swing(nj);
  std::vector<double> twist(nj);
  for (int j = 0; j < nj; ++j) {
    const int p = base_.joints[j].parent;
    const Eigen::Matrix3d parent_linear = p >= 0 ? chain[p] : Eigen::Matrix3d::Identity();
    chain[j] = parent_linear * pose.joint_rotations[j];
    world[j] = pose.scale * pose.rotation * parent_linear;
    const SwingTwist st =
        DecomposeSwingTwist(pose.joint_rotations[j], base_.joints[j].twist_axis.normalized());
    swing[j] = st.swing;
    twist[j] = st.twist_angle;
  }
  const int n = vertices.empty() ? base_.num_vertices() : static_cast<int>(vertices.size());
  Eigen::Matrix<double, 3, Eigen::Dynamic> full(3, full_rows());
  jacobian->resize(3 * n, num_parameters());
  for (int i = 0; i < n; ++i) {
    const int v = vertices.empty() ? i : vertices[i];
    const int k = base_.vertex_joint[v];
    const double w = base_.lbs_weight[v];
    const double tau = base_.slerp_tau[v];
    const Eigen::Vector3d a = base_.joints[k].twist_axis.normalized();
    const Eigen::Vector3d rho = rho_.row(v).transpose();
    full.setZero();
    // Posed joint centre c_k = c_root + sum over the chain of s0 W_m bone_length[m] e_m.
    for (int m = k; m > 0; m = base_.joints[m].parent) {
      if (fork_[m]) {
        full.col(m) = world[m] * bone_axial_[m];
        full.col(3 * nj + m) = world[m] * bone_lateral_[m];
      } else {
        full.col(m) = world[m] * bone_offset_[m];
      }
    }
    // v' = c_k + s0 W_k (w R^LBS + (1 - w) 1) (L alpha a + g Rot(a, tau theta) rho).
    const Eigen::Matrix3d g_map =
        world[k] * (w * swing[k] + (1.0 - w) * Eigen::Matrix3d::Identity());
    if (stretch_row_[k] >= 0) full.col(stretch_row_[k]) += g_map * (alpha_[v] * a);
    // A radial offset x twisted by the SLERP share of the joint's twist and mapped, into the
    // columns of the cross-section factor group starting at full row `first` (girths or depth
    // factors), split across the joint like the blend in RestGeometry.
    const double angle = tau * twist[k];
    const double cos_angle = std::cos(angle), sin_angle = std::sin(angle);
    const auto add_cross_section = [&](int first, const Eigen::Vector3d& x) {
      const Eigen::Vector3d d = g_map * (cos_angle * x + sin_angle * a.cross(x));
      if (k == 0) {
        full.col(first) += d;
      } else {
        full.col(first + k) += w * d;
        full.col(first + base_.joints[k].parent) += (1.0 - w) * d;
      }
    };
    add_cross_section(nj, rho);
    if (girth_depth_) add_cross_section(4 * nj, rho_depth_.row(v).transpose());
    full.col(0).setZero();  // the root's bone length is unused
    jacobian->middleRows<3>(3 * i) = full * expansion_;
  }
}

bool ShapeModel::IsGirthParameter(int p) const {
  const int nj = base_.num_joints();
  const Eigen::VectorXd col = expansion_.col(p);
  return col.head(nj).isZero() && col.segment(2 * nj, 2 * nj).isZero();
}

bool ShapeModel::IsDepthParameter(int p) const {
  const int nj = base_.num_joints();
  return girth_depth_ && expansion_.col(p).head(4 * nj).isZero();
}

}  // namespace artex
