// Skinning S(v; theta) of the paper (eq. 1-2, DESIGN.md "Skinning") for all template vertices,
// and its analytic Jacobian with respect to the pose's tangent perturbations (models/pose.h):
//   v' = s0 R0 T_root o ... o T_parent(k) ( B_k(v) ) + t0,  T_i(x) = R_i (x - t_i) + t_i,
//   B_k: LBS blend (w_l) of the swing part and cylindrical SLERP (tau) of the twist part of R_k
//   about the joint's twist axis.
#pragma once

#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

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
    return {values_.data() + block_offset_[v], 3,
            static_cast<Eigen::Index>(Columns(v).size())};
  }
  Eigen::MatrixXd ToDense() const;                 // 3V x P; rows 3v .. 3v+2 belong to vertex v
  Eigen::SparseMatrix<double> ToSparse() const;    // same layout

 private:
  friend class Skinning;
  int num_parameters_ = 0;
  std::vector<std::vector<int>> columns_;  // one column set per joint
  std::vector<int> column_set_;            // V: index into columns_
  std::vector<int> block_offset_;          // V + 1 offsets into values_
  std::vector<double> values_;
};

class Skinning {
 public:
  // Precomputes joint chains and per-vertex twist-axis projections t'_k. The template must be
  // valid (Template::IsValid); it is copied, so the Skinning does not dangle.
  explicit Skinning(const Template& tmpl);

  const Template& model() const { return template_; }

  // posed: V x 3 positions S(v; pose).
  void Apply(const Pose& pose, Eigen::MatrixX3d* posed) const;
  // Positions and the Jacobian w.r.t. pose.Retracted(delta) at delta = 0.
  void ApplyWithJacobian(const Pose& pose, Eigen::MatrixX3d* posed,
                         SkinningJacobian* jacobian) const;
  // J x 3 posed joint centres (each joint centre moves with its parent's chain).
  void PosedJointCenters(const Pose& pose, Eigen::MatrixX3d* centers) const;

 private:
  Template template_;
  std::vector<std::vector<int>> chains_;  // per joint: root .. joint
  Eigen::MatrixX3d axis_foot_;             // V x 3: t'_k, projection of v onto its twist axis
};

}  // namespace artex
