// Synthetic fixtures for the fitting tests: a small articulated template made of capped tubes
// (one per bone), random poses, and scans sampled from a posed surface as a depth camera would
// see it (front-facing triangles only, Gaussian noise along the viewing ray).
#pragma once

#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "models/normals.h"
#include "models/pose.h"
#include "models/skinning.h"
#include "models/so3.h"
#include "models/template.h"
#include "sensors/scan.h"

namespace artex {
namespace testing_util {

// A noise-free "scan": every vertex of the subject posed as `pose`, with its normal.
inline Scan VertexScan(const Template& subject, const Pose& pose) {
  Scan scan;
  Skinning(subject).Apply(pose, &scan.points);
  ComputeVertexNormals(scan.points, subject.triangles, &scan.normals);
  scan.colors = Eigen::MatrixX3d::Zero(scan.points.rows(), 3);
  scan.color_valid.assign(scan.points.rows(), 0);
  return scan;
}

// A capped tube from joint `j`'s centre along `dir` (length, radius), vertices skinned to j.
// The cross-section is an ellipse (semi-axes radius and 0.6 radius) so that twist about the
// bone is observable.
inline void AddTube(Template* t, int joint, const Eigen::Vector3d& start,
                    const Eigen::Vector3d& dir, double length, double radius, int rings,
                    int segments, std::vector<Eigen::Vector3i>* tris) {
  const Eigen::Vector3d a = dir.normalized();
  Eigen::Vector3d u = a.unitOrthogonal();
  Eigen::Vector3d w = a.cross(u);
  const int base = static_cast<int>(t->vertices.rows());
  std::vector<Eigen::Vector3d> verts;
  std::vector<double> taus;
  for (int r = 0; r < rings; ++r) {
    const double f = (r + 0.5) / rings;
    for (int s = 0; s < segments; ++s) {
      const double phi = 2.0 * M_PI * s / segments;
      verts.push_back(start + f * length * a +
                      radius * (std::cos(phi) * u + 0.6 * std::sin(phi) * w));
      taus.push_back(f);
    }
  }
  verts.push_back(start + 0.02 * length * a - 0.3 * radius * a);  // bottom cap centre
  taus.push_back(0.0);
  verts.push_back(start + length * a + 0.3 * radius * a);  // top cap centre
  taus.push_back(1.0);
  const int bottom = base + rings * segments, top = bottom + 1;
  auto id = [&](int r, int s) { return base + r * segments + (s % segments); };
  std::vector<Eigen::Vector3i> local;
  for (int r = 0; r + 1 < rings; ++r) {
    for (int s = 0; s < segments; ++s) {
      local.emplace_back(id(r, s), id(r, s + 1), id(r + 1, s + 1));
      local.emplace_back(id(r, s), id(r + 1, s + 1), id(r + 1, s));
    }
  }
  for (int s = 0; s < segments; ++s) {
    local.emplace_back(bottom, id(0, s + 1), id(0, s));
    local.emplace_back(top, id(rings - 1, s), id(rings - 1, s + 1));
  }
  // Orient outwards: away from the tube axis (caps: along the axis).
  const Eigen::Index old_rows = t->vertices.rows();
  t->vertices.conservativeResize(old_rows + verts.size(), 3);
  t->vertex_joint.conservativeResize(old_rows + verts.size());
  t->lbs_weight.conservativeResize(old_rows + verts.size());
  t->slerp_tau.conservativeResize(old_rows + verts.size());
  for (size_t i = 0; i < verts.size(); ++i) {
    t->vertices.row(old_rows + i) = verts[i].transpose();
    t->vertex_joint[old_rows + i] = joint;
    t->lbs_weight[old_rows + i] = 1.0;
    t->slerp_tau[old_rows + i] = taus[i];
  }
  const Eigen::Vector3d centre = start + 0.5 * length * a;
  for (Eigen::Vector3i tri : local) {
    const Eigen::Vector3d p0 = t->vertices.row(tri[0]), p1 = t->vertices.row(tri[1]),
                          p2 = t->vertices.row(tri[2]);
    const Eigen::Vector3d n = (p1 - p0).cross(p2 - p0);
    const Eigen::Vector3d c = (p0 + p1 + p2) / 3.0;
    const double along = (c - centre).dot(a);
    Eigen::Vector3d out = (c - centre) - along * a;
    if ((tri.array() == bottom).any()) out = -a;
    if ((tri.array() == top).any()) out = a;
    if (n.dot(out) < 0.0) std::swap(tri[1], tri[2]);
    tris->push_back(tri);
  }
}

// Six joints: pelvis (root, torso tube up), l_hip -> l_knee (leg), chest -> r_shoulder ->
// r_elbow (arm). About 600 vertices; feet near y = 0, facing +Z.
inline Template MakeStickTemplate(int rings = 8, int segments = 12) {
  Template t;
  auto joint = [&](const char* name, int parent, Eigen::Vector3d c, Eigen::Vector3d axis) {
    Joint j;
    j.name = name;
    j.parent = parent;
    j.center = c;
    j.twist_axis = axis.normalized();
    t.joints.push_back(j);
  };
  joint("pelvis", -1, {0.0, 0.95, 0.0}, {0, 1, 0});
  joint("chest", 0, {0.0, 1.25, 0.0}, {0, 1, 0});
  joint("l_hip", 0, {0.1, 0.9, 0.0}, {0, -1, 0});
  joint("l_knee", 2, {0.1, 0.5, 0.0}, {0, -1, 0});
  joint("r_shoulder", 1, {-0.2, 1.45, 0.0}, {-1, -0.6, 0});
  joint("r_elbow", 4, Eigen::Vector3d(-0.2, 1.45, 0.0) + 0.28 * Eigen::Vector3d(-1, -0.6, 0).normalized(),
        {-1, -0.6, 0});
  std::vector<Eigen::Vector3i> tris;
  t.vertices.resize(0, 3);
  AddTube(&t, 0, {0.0, 0.9, 0.0}, {0, 1, 0}, 0.35, 0.14, rings, segments, &tris);
  AddTube(&t, 1, {0.0, 1.25, 0.0}, {0, 1, 0}, 0.25, 0.16, rings, segments, &tris);
  AddTube(&t, 2, {0.1, 0.9, 0.0}, {0, -1, 0}, 0.4, 0.07, rings, segments, &tris);
  AddTube(&t, 3, {0.1, 0.5, 0.0}, {0, -1, 0}, 0.45, 0.055, rings, segments, &tris);
  AddTube(&t, 4, t.joints[4].center, t.joints[4].twist_axis, 0.28, 0.05, rings, segments, &tris);
  AddTube(&t, 5, t.joints[5].center, t.joints[5].twist_axis, 0.26, 0.04, rings, segments, &tris);
  t.triangles.resize(static_cast<Eigen::Index>(tris.size()), 3);
  for (size_t i = 0; i < tris.size(); ++i) t.triangles.row(i) = tris[i].transpose();
  // Smooth blending near the joint for the children (exercises LBS weights).
  for (int v = 0; v < t.num_vertices(); ++v) {
    if (t.vertex_joint[v] != 0) t.lbs_weight[v] = std::min(1.0, 0.4 + t.slerp_tau[v]);
  }
  return t;
}

// Pose with joint rotations of angle ~ joint_angle (random axes), global rotation of angle
// global_angle, translation of norm `translation`.
inline Pose RandomPose(int num_joints, double joint_angle, double global_angle, double translation,
                       std::mt19937_64* rng, double scale = 1.0) {
  std::normal_distribution<double> n(0.0, 1.0);
  auto random_vector = [&](double norm) {
    Eigen::Vector3d v(n(*rng), n(*rng), n(*rng));
    return Eigen::Vector3d(v.normalized() * norm);
  };
  Pose pose = Pose::Identity(num_joints);
  pose.scale = scale;
  pose.translation = random_vector(translation);
  pose.rotation = ExpSO3(random_vector(global_angle));
  for (int j = 0; j < num_joints; ++j) pose.joint_rotations[j] = ExpSO3(random_vector(joint_angle));
  return pose;
}

// Points sampled uniformly on the triangles facing `camera` (density per m^2), with Gaussian
// noise along the viewing ray; normals = triangle normals (towards the camera).
inline Scan SampleScan(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                       const Eigen::Vector3d& camera, double density, double noise,
                       std::mt19937_64* rng, bool front_only = true) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<Eigen::Vector3d> pts, nrm;
  for (int f = 0; f < triangles.rows(); ++f) {
    const Eigen::Vector3d a = vertices.row(triangles(f, 0)), b = vertices.row(triangles(f, 1)),
                          c = vertices.row(triangles(f, 2));
    Eigen::Vector3d n = (b - a).cross(c - a);
    const double area = 0.5 * n.norm();
    if (area <= 0.0) continue;
    n.normalize();
    const Eigen::Vector3d centroid = (a + b + c) / 3.0;
    if (front_only && n.dot(camera - centroid) <= 0.0) continue;
    const double expected = area * density;
    int count = static_cast<int>(expected);
    if (u(*rng) < expected - count) ++count;
    for (int i = 0; i < count; ++i) {
      double r1 = u(*rng), r2 = u(*rng);
      if (r1 + r2 > 1.0) {
        r1 = 1.0 - r1;
        r2 = 1.0 - r2;
      }
      Eigen::Vector3d p = a + r1 * (b - a) + r2 * (c - a);
      const Eigen::Vector3d ray = (p - camera).normalized();
      p += noise * g(*rng) * ray;
      pts.push_back(p);
      nrm.push_back(n);
    }
  }
  Scan scan;
  scan.points.resize(static_cast<Eigen::Index>(pts.size()), 3);
  scan.normals.resize(static_cast<Eigen::Index>(pts.size()), 3);
  for (size_t i = 0; i < pts.size(); ++i) {
    scan.points.row(i) = pts[i].transpose();
    scan.normals.row(i) = nrm[i].transpose();
  }
  scan.colors = Eigen::MatrixX3d::Constant(scan.points.rows(), 3, 0.5);
  scan.color_valid.assign(pts.size(), 1);
  return scan;
}

inline double MeanVertexError(const Skinning& skinning, const Pose& a, const Pose& b) {
  Eigen::MatrixX3d pa, pb;
  skinning.Apply(a, &pa);
  skinning.Apply(b, &pb);
  return (pa - pb).rowwise().norm().mean();
}

}  // namespace testing_util
}  // namespace artex
