#include "models/gltf_skinning.h"

#include <Eigen/LU>
#include <cmath>
#include <string>
#include <vector>

#include "models/error.h"

namespace artex {
namespace {

// Affine maps (3 x 4: [A | b]) of skin joint 0 (the global similarity G) and of skin joint
// j + 1 = J_j for every artex joint j (parents precede children).
std::vector<Eigen::Matrix<double, 3, 4>> SkinJointMaps(const Template& tmpl, const Pose& pose) {
  if (pose.num_joints() != tmpl.num_joints()) {
    throw Error("glTF skinning: pose has " + std::to_string(pose.num_joints()) +
                " joint rotations, the template " + std::to_string(tmpl.num_joints()) + " joints");
  }
  std::vector<Eigen::Matrix<double, 3, 4>> maps(tmpl.num_joints() + 1);
  maps[0].leftCols<3>() = pose.scale * pose.rotation;
  maps[0].col(3) = pose.translation;
  for (int j = 0; j < tmpl.num_joints(); ++j) {
    const Eigen::Matrix3d& r = pose.joint_rotations[j];
    const Eigen::Vector3d& t = tmpl.joints[j].center;
    const Eigen::Matrix<double, 3, 4>& parent = maps[tmpl.joints[j].parent + 1];
    // parent o T_j: x -> P_A (R x + t - R t) + P_b.
    maps[j + 1].leftCols<3>() = parent.leftCols<3>() * r;
    maps[j + 1].col(3) = parent.leftCols<3>() * (t - r * t) + parent.col(3);
  }
  return maps;
}

// The blended affine map of vertex v.
Eigen::Matrix<double, 3, 4> VertexMap(const Template& tmpl,
                                      const std::vector<Eigen::Matrix<double, 3, 4>>& maps, int v) {
  const int k = tmpl.vertex_joint[v];
  const double w = tmpl.lbs_weight[v];
  return w * maps[k + 1] + (1.0 - w) * maps[tmpl.joints[k].parent + 1];
}

}  // namespace

bool GltfCorrectiveOptions::IsValid(std::string* error) const {
  if (!(min_relative_determinant >= 0.0) || !std::isfinite(min_relative_determinant)) {
    if (error) {
      *error = "min_relative_determinant: expected a finite value >= 0, found " +
               std::to_string(min_relative_determinant);
    }
    return false;
  }
  return true;
}

void GltfSkinnedPositions(const Template& tmpl, const Pose& pose, const Eigen::MatrixX3d* offsets,
                          Eigen::MatrixX3d* positions) {
  const int n = tmpl.num_vertices();
  if (offsets && offsets->rows() != n) {
    throw Error("glTF skinning: offsets have " + std::to_string(offsets->rows()) +
                " rows, the template " + std::to_string(n) + " vertices");
  }
  const auto maps = SkinJointMaps(tmpl, pose);
  positions->resize(n, 3);
  for (int v = 0; v < n; ++v) {
    Eigen::Vector3d x = tmpl.vertices.row(v).transpose();
    if (offsets) x += offsets->row(v).transpose();
    const Eigen::Matrix<double, 3, 4> m = VertexMap(tmpl, maps, v);
    positions->row(v) = (m.leftCols<3>() * x + m.col(3)).transpose();
  }
}

void GltfCorrectiveOffsets(const Template& tmpl, const Pose& pose, const Eigen::MatrixX3d& target,
                           const GltfCorrectiveOptions& options, Eigen::MatrixX3d* offsets,
                           GltfCorrectiveStats* stats) {
  std::string why;
  if (!options.IsValid(&why)) throw Error("glTF correctives: " + why);
  const int n = tmpl.num_vertices();
  if (target.rows() != n) {
    throw Error("glTF correctives: target has " + std::to_string(target.rows()) +
                " rows, the template " + std::to_string(n) + " vertices");
  }
  const auto maps = SkinJointMaps(tmpl, pose);
  const double min_det = options.min_relative_determinant * std::pow(pose.scale, 3);
  GltfCorrectiveStats s;
  offsets->setZero(n, 3);
  for (int v = 0; v < n; ++v) {
    const Eigen::Matrix<double, 3, 4> m = VertexMap(tmpl, maps, v);
    const Eigen::Matrix3d a = m.leftCols<3>();
    if (!(std::abs(a.determinant()) >= min_det)) {
      ++s.singular_vertices;
      continue;
    }
    const Eigen::Vector3d rest = tmpl.vertices.row(v).transpose();
    const Eigen::Vector3d x = a.partialPivLu().solve(target.row(v).transpose() - m.col(3));
    offsets->row(v) = (x - rest).transpose();
    s.max_offset = std::max(s.max_offset, (x - rest).norm());
  }
  if (stats) *stats = s;
}

}  // namespace artex
