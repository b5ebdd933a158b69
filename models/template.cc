#include "models/template.h"

#include <cmath>
#include <sstream>

namespace artex {

std::vector<std::string> Template::JointNames() const {
  std::vector<std::string> names;
  for (const Joint& j : joints) names.push_back(j.name);
  return names;
}

std::vector<int> Template::Chain(int joint) const {
  std::vector<int> chain;
  for (int j = joint; j >= 0; j = joints[j].parent) chain.push_back(j);
  return std::vector<int>(chain.rbegin(), chain.rend());
}

int Template::FindJoint(const std::string& name) const {
  for (int j = 0; j < num_joints(); ++j) {
    if (joints[j].name == name) return j;
  }
  return -1;
}

namespace {
bool Fail(std::string* error, const std::string& message) {
  if (error) *error = message;
  return false;
}
}  // namespace

bool Template::IsValid(std::string* error) const {
  const int v = num_vertices();
  const int f = num_triangles();
  std::ostringstream msg;
  if (v == 0) return Fail(error, "vertices: expected at least one vertex, found none");
  if (f == 0) return Fail(error, "triangles: expected at least one triangle, found none");
  if (!vertices.allFinite()) return Fail(error, "vertices: found a non-finite coordinate");
  if (triangles.minCoeff() < 0 || triangles.maxCoeff() >= v) {
    msg << "triangles: expected vertex indices in [0, " << v << "), found "
        << triangles.minCoeff() << ".." << triangles.maxCoeff();
    return Fail(error, msg.str());
  }
  if (uv_triangles.rows() != 0) {
    if (uv_triangles.rows() != f) {
      msg << "uv_triangles: expected " << f << " rows, found " << uv_triangles.rows();
      return Fail(error, msg.str());
    }
    if (uvs.rows() == 0 || uv_triangles.minCoeff() < 0 || uv_triangles.maxCoeff() >= uvs.rows())
      return Fail(error, "uv_triangles: index outside the uvs array");
    if (!uvs.allFinite()) return Fail(error, "uvs: found a non-finite coordinate");
  }
  if (triangle_chart.size() != 0 && triangle_chart.size() != f) {
    msg << "triangle_chart: expected " << f << " entries, found " << triangle_chart.size();
    return Fail(error, msg.str());
  }
  const int j = num_joints();
  if (j == 0) return Fail(error, "joints: expected at least one joint, found none");
  for (int i = 0; i < j; ++i) {
    const Joint& joint = joints[i];
    if (i == 0 && joint.parent != -1) {
      msg << "joints[0] (" << joint.name << "): the root must have parent -1, found "
          << joint.parent;
      return Fail(error, msg.str());
    }
    if (i > 0 && (joint.parent < 0 || joint.parent >= i)) {
      msg << "joints[" << i << "] (" << joint.name << "): expected a parent index in [0, " << i
          << ") (parents precede children; no cycles), found " << joint.parent;
      return Fail(error, msg.str());
    }
    if (!joint.center.allFinite() || !joint.twist_axis.allFinite()) {
      msg << "joints[" << i << "] (" << joint.name << "): non-finite centre or twist axis";
      return Fail(error, msg.str());
    }
    if (std::abs(joint.twist_axis.norm() - 1.0) > 1e-6) {
      msg << "joints[" << i << "] (" << joint.name << "): twist axis must be unit, found norm "
          << joint.twist_axis.norm();
      return Fail(error, msg.str());
    }
  }
  if (vertex_joint.size() != v || lbs_weight.size() != v || slerp_tau.size() != v) {
    msg << "skinning constants: expected " << v << " entries each, found vertex_joint "
        << vertex_joint.size() << ", lbs_weight " << lbs_weight.size() << ", slerp_tau "
        << slerp_tau.size();
    return Fail(error, msg.str());
  }
  if (vertex_joint.minCoeff() < 0 || vertex_joint.maxCoeff() >= j) {
    msg << "vertex_joint: expected joint indices in [0, " << j << "), found "
        << vertex_joint.minCoeff() << ".." << vertex_joint.maxCoeff();
    return Fail(error, msg.str());
  }
  for (int i = 0; i < v; ++i) {
    if (!(lbs_weight[i] >= 0.0 && lbs_weight[i] <= 1.0)) {
      msg << "lbs_weight[" << i << "]: expected a value in [0, 1], found " << lbs_weight[i];
      return Fail(error, msg.str());
    }
    if (!(slerp_tau[i] >= 0.0 && slerp_tau[i] <= 1.0)) {
      msg << "slerp_tau[" << i << "]: expected a value in [0, 1], found " << slerp_tau[i];
      return Fail(error, msg.str());
    }
  }
  return true;
}

}  // namespace artex
