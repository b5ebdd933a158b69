// The rigged template of the paper (sec. 3, eq. 1-2; docs/design.md "Skinning"): a triangle mesh
// with per-corner UVs, a joint tree, and per-vertex skinning constants (joint k, LBS weight
// w_l, SLERP parameter tau). Units: metres. Frame: Y up, the body faces +Z, feet at y = 0.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

namespace artex {

struct Joint {
  std::string name;
  int parent = -1;                                        // -1 for the root joint only
  Eigen::Vector3d center = Eigen::Vector3d::Zero();       // t_i, rest frame (m)
  Eigen::Vector3d twist_axis = Eigen::Vector3d::UnitY();  // a_i, unit, outward along the bone
};

struct Template {
  Eigen::MatrixX3d vertices;      // V x 3 rest positions (m)
  Eigen::MatrixX3i triangles;     // F x 3, counter-clockwise seen from outside
  Eigen::MatrixX2d uvs;           // U x 2 atlas coordinates in [0,1]^2, glTF convention:
                                  // u to the right, v downwards (image row = v * height)
  Eigen::MatrixX3i uv_triangles;  // F x 3 indices into uvs (per-corner UVs); 0 rows: no atlas
  Eigen::VectorXi triangle_chart; // F: UV chart (body part) of each triangle; may be empty
  std::vector<Joint> joints;      // parents precede children; joints[0] is the root
  Eigen::VectorXi vertex_joint;   // V: joint k each vertex belongs to
  Eigen::VectorXd lbs_weight;     // V: w_l in [0, 1]
  Eigen::VectorXd slerp_tau;      // V: tau in [0, 1]

  int num_vertices() const { return static_cast<int>(vertices.rows()); }
  int num_triangles() const { return static_cast<int>(triangles.rows()); }
  int num_joints() const { return static_cast<int>(joints.size()); }
  // 7 global (scale, translation, rotation) + 3 per joint: 58 for 17 joints.
  int num_pose_parameters() const { return 7 + 3 * num_joints(); }
  bool has_uvs() const { return uv_triangles.rows() == triangles.rows() && uvs.rows() > 0; }

  std::vector<std::string> JointNames() const;  // joints[j].name for every j
  // Joint indices from the root down to `joint` (inclusive).
  std::vector<int> Chain(int joint) const;
  int FindJoint(const std::string& name) const;  // -1 when absent

  // Checks shapes, index ranges, finiteness, w_l and tau in [0,1], unit twist axes and an
  // acyclic, parent-before-child joint order. On failure returns false and, if `error` is
  // non-null, describes the first problem found (field, expected, found).
  bool IsValid(std::string* error) const;
};

}  // namespace artex
