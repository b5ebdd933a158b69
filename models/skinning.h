// Skinning S(v; theta) of the paper (eq. 1-2, docs/design.md "Skinning") for all template vertices,
// and its analytic Jacobian with respect to the pose's tangent perturbations (models/pose.h):
//   v' = s0 R0 T_root o ... o T_parent(k) ( B_k(v) ) + t0,  T_i(x) = R_i (x - t_i) + t_i,
//   B_k: LBS blend (w_l) of the swing part and cylindrical SLERP (tau) of the twist part of R_k
//   about the joint's twist axis.
#pragma once

#include <Eigen/Core>
#include <Eigen/SparseCore>
#include <vector>

#include "models/pose.h"
#include "models/template.h"

namespace artex {

// Per-vertex 3 x n blocks of d v'_v / d delta. A vertex depends only on the 7 global
// parameters and on the joints of its chain, so each block is stored densely over those
// columns only.
class SkinningJacobian {
 public:
  int num_vertices() const { return static_cast<int>(block_offset_.size()) - 1; }
  int num_parameters() const { return num_parameters_; }
  // Tangent indices (ascending) that vertex v depends on.
  const std::vector<int>& Columns(int v) const { return columns_[column_set_[v]]; }
  // 3 x Columns(v).size(), column-major.
  Eigen::Map<const Eigen::Matrix<double, 3, Eigen::Dynamic>> Block(int v) const {
    return {values_.data() + block_offset_[v], 3, static_cast<Eigen::Index>(Columns(v).size())};
  }
  Eigen::MatrixXd ToDense() const;               // 3V x P; rows 3v .. 3v+2 belong to vertex v
  Eigen::SparseMatrix<double> ToSparse() const;  // same layout

 private:
  friend class Skinning;
  int num_parameters_ = 0;
  std::vector<std::vector<int>> columns_;  // one column set per joint
  std::vector<int> column_set_;            // V: index into columns_
  std::vector<int> block_offset_;          // V + 1 offsets into values_
  std::vector<double> values_;
};

struct SkinningOptions {
  // Distribute vertices over TBB worker threads; false runs everything on the calling thread.
  bool parallel = true;
  // Vertices per TBB task (>= 1); also the size below which a call stays on the calling thread.
  int grain_size = 2048;
};

// SLERP weights of eq. 2: w_s = sin(tau theta) / sin(theta), wbar_s = sin((1 - tau) theta) /
// sin(theta), with the series limits w_s -> tau, wbar_s -> 1 - tau as theta -> 0. Undefined
// (non-finite) at theta = +-pi. For a vector d perpendicular to the unit axis a,
// (w_s Rot(a, theta) + wbar_s 1) d = Rot(a, tau theta) d, the form Skinning evaluates (it is
// smooth on the whole open interval (-2 pi, 2 pi)).
void TwistSlerpWeights(double theta, double tau, double* w_s, double* wbar_s);

class Skinning {
 public:
  // Precomputes joint chains and per-vertex twist-axis projections t'_k. The template must be
  // valid (Template::IsValid), otherwise artex::Error is thrown with the reason; it is copied,
  // so the Skinning does not dangle. Throws artex::Error on invalid options (grain_size < 1).
  explicit Skinning(const Template& tmpl, const SkinningOptions& options = SkinningOptions());

  const Template& model() const { return template_; }
  const SkinningOptions& options() const { return options_; }

  // posed: V x 3 positions S(v; pose). Throws artex::Error when pose.num_joints() differs from
  // the template's joint count.
  void Apply(const Pose& pose, Eigen::MatrixX3d* posed) const;
  // Positions and the Jacobian w.r.t. pose.Retracted(delta) at delta = 0. `jacobian` keeps its
  // storage across calls (no reallocation for the same template).
  // The twist angle of R_k is discontinuous at +-pi (and undefined for a 180-degree swing,
  // where DecomposeSwingTwist yields twist 0); there the twist-angle derivative is set to 0.
  void ApplyWithJacobian(const Pose& pose, Eigen::MatrixX3d* posed,
                         SkinningJacobian* jacobian) const;
  // J x 3 posed joint centres (each joint centre moves with its parent's chain):
  // s0 R0 T_root o ... o T_parent(j) (t_j) + t0.
  void PosedJointCenters(const Pose& pose, Eigen::MatrixX3d* centers) const;
  // Replaces the rest geometry, vertices V x 3 and joint centres J x 3 (same counts), keeping
  // the rig (parents, twist axes, skinning constants): a subject shape (models/shape.h) without
  // a new Skinning, so references to this one stay valid. Throws artex::Error on a wrong shape
  // or a non-finite value (the Skinning is then unchanged).
  void SetRestGeometry(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3d& centers);

 private:
  struct JointFrame;  // per-call, per-joint transforms (defined in skinning.cc)
  void PrecomputeRestOffsets();  // axis_foot_, offset_, radial_ from template_
  void ComputeJointFrames(const Pose& pose, std::vector<JointFrame>* frames) const;
  template <bool kWithJacobian>
  void Evaluate(const Pose& pose, Eigen::MatrixX3d* posed, SkinningJacobian* jacobian) const;

  Template template_;
  SkinningOptions options_;
  std::vector<std::vector<int>> chains_;  // per joint: root .. joint
  std::vector<Eigen::Vector3d> axes_;     // per joint: unit twist axis a_k
  Eigen::MatrixX3d axis_foot_;            // V x 3: t'_k, projection of v onto its twist axis
  Eigen::MatrixX3d offset_;               // V x 3: v - t_k
  Eigen::MatrixX3d radial_;               // V x 3: v - t'_k (perpendicular to a_k)
  SkinningJacobian layout_;               // column sets and offsets; values_ left empty
};

}  // namespace artex
