// Test fixture: a small 17-joint template with the default joint names (A-pose, Y up,
// facing +Z, left = +X, feet at y = 0) made of one box per body segment, so motion and BVH
// tests do not depend on the full template generator.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "models/template.h"

namespace artex {
namespace testing_skeleton {

inline Template MakeBoxTemplate() {
  Template t;
  const double a = 40.0 * M_PI / 180.0;  // arms below horizontal
  const Eigen::Vector3d left_arm(std::cos(a), -std::sin(a), 0.0);
  const Eigen::Vector3d right_arm(-std::cos(a), -std::sin(a), 0.0);
  const Eigen::Vector3d up = Eigen::Vector3d::UnitY(), down = -up;
  const Eigen::Vector3d forward = Eigen::Vector3d::UnitZ();
  auto add = [&](const std::string& name, int parent, const Eigen::Vector3d& c,
                 const Eigen::Vector3d& axis) {
    Joint j;
    j.name = name;
    j.parent = parent;
    j.center = c;
    j.twist_axis = axis.normalized();
    t.joints.push_back(j);
  };
  const Eigen::Vector3d ls(0.18, 1.42, 0.0), rs(-0.18, 1.42, 0.0);
  add("pelvis", -1, {0, 0.95, 0}, up);                  // 0
  add("spine", 0, {0, 1.05, 0}, up);                    // 1
  add("chest", 1, {0, 1.25, 0}, up);                    // 2
  add("neck", 2, {0, 1.47, 0}, up);                     // 3
  add("head", 3, {0, 1.57, 0}, up);                     // 4
  add("l_shoulder", 2, ls, left_arm);                   // 5
  add("l_elbow", 5, ls + 0.28 * left_arm, left_arm);    // 6
  add("l_wrist", 6, ls + 0.53 * left_arm, left_arm);    // 7
  add("r_shoulder", 2, rs, right_arm);                  // 8
  add("r_elbow", 8, rs + 0.28 * right_arm, right_arm);  // 9
  add("r_wrist", 9, rs + 0.53 * right_arm, right_arm);  // 10
  add("l_hip", 0, {0.09, 0.90, 0}, down);               // 11
  add("l_knee", 11, {0.09, 0.50, 0}, down);             // 12
  add("l_ankle", 12, {0.09, 0.08, 0}, forward);         // 13
  add("r_hip", 0, {-0.09, 0.90, 0}, down);              // 14
  add("r_knee", 14, {-0.09, 0.50, 0}, down);            // 15
  add("r_ankle", 15, {-0.09, 0.08, 0}, forward);        // 16

  std::vector<Eigen::Vector3d> verts;
  std::vector<Eigen::Vector3i> tris;
  std::vector<int> owner;
  // Box between p0 and p1 (long axis) with half extents h along two perpendicular axes.
  auto box = [&](int joint, const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, double h) {
    const Eigen::Vector3d axis = (p1 - p0).normalized();
    Eigen::Vector3d u = axis.cross(Eigen::Vector3d::UnitZ());
    if (u.norm() < 1e-6) u = axis.cross(Eigen::Vector3d::UnitX());
    u.normalize();
    const Eigen::Vector3d v = axis.cross(u).normalized();
    const int base = static_cast<int>(verts.size());
    for (int i = 0; i < 8; ++i) {
      const Eigen::Vector3d end = (i & 1) ? p1 : p0;
      verts.push_back(end + ((i & 2) ? h : -h) * u + ((i & 4) ? h : -h) * v);
      owner.push_back(joint);
    }
    const int faces[12][3] = {{0, 2, 6}, {0, 6, 4}, {1, 5, 7}, {1, 7, 3}, {0, 1, 3}, {0, 3, 2},
                              {4, 6, 7}, {4, 7, 5}, {0, 4, 5}, {0, 5, 1}, {2, 3, 7}, {2, 7, 6}};
    for (const auto& f : faces) tris.emplace_back(base + f[0], base + f[1], base + f[2]);
  };
  const auto& J = t.joints;
  box(0, J[0].center + Eigen::Vector3d(0, -0.08, 0), J[1].center, 0.12);
  box(1, J[1].center, J[2].center, 0.11);
  box(2, J[2].center, J[3].center, 0.13);
  box(3, J[3].center, J[4].center, 0.05);
  box(4, J[4].center, J[4].center + Eigen::Vector3d(0, 0.18, 0), 0.08);
  for (int s : {5, 8}) {
    box(s, J[s].center, J[s + 1].center, 0.05);
    box(s + 1, J[s + 1].center, J[s + 2].center, 0.04);
    box(s + 2, J[s + 2].center, J[s + 2].center + 0.17 * J[s + 2].twist_axis, 0.03);
  }
  for (int h : {11, 14}) {
    box(h, J[h].center, J[h + 1].center, 0.07);
    box(h + 1, J[h + 1].center, J[h + 2].center, 0.05);
    // Foot: sole at y = 0, from the heel to the toes.
    const Eigen::Vector3d c = J[h + 2].center;
    box(h + 2, Eigen::Vector3d(c.x(), 0.04, -0.06), Eigen::Vector3d(c.x(), 0.04, 0.18), 0.04);
  }
  t.vertices.resize(verts.size(), 3);
  for (size_t i = 0; i < verts.size(); ++i) t.vertices.row(i) = verts[i].transpose();
  t.triangles.resize(tris.size(), 3);
  for (size_t i = 0; i < tris.size(); ++i) t.triangles.row(i) = tris[i].transpose();
  t.vertex_joint = Eigen::Map<Eigen::VectorXi>(owner.data(), owner.size());
  t.lbs_weight = Eigen::VectorXd::Ones(verts.size());
  t.slerp_tau = Eigen::VectorXd::Zero(verts.size());
  return t;
}

}  // namespace testing_skeleton
}  // namespace artex
