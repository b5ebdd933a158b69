#include "sensors/bvh_export.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <sstream>

#include "models/error.h"
#include "models/mesh_export.h"
#include "models/numeric.h"

namespace artex {
namespace {

int AxisIndex(char c) { return c - 'X'; }

// Angles (rad) a with R = Rot(axis0, a0) Rot(axis1, a1) Rot(axis2, a2), the solution of the
// two closest to `previous` (each angle unwrapped by multiples of 2 pi towards it).
Eigen::Vector3d EulerNear(const Eigen::Matrix3d& r, const std::string& order,
                          const Eigen::Vector3d& previous) {
  const Eigen::Vector3d a =
      r.eulerAngles(AxisIndex(order[0]), AxisIndex(order[1]), AxisIndex(order[2]));
  // The other solution of a Tait-Bryan decomposition: (a0 + pi, pi - a1, a2 + pi).
  const Eigen::Vector3d b(a[0] + kPi, kPi - a[1], a[2] + kPi);
  auto unwrap = [&previous](Eigen::Vector3d v) {
    for (int i = 0; i < 3; ++i) v[i] += 2 * kPi * std::round((previous[i] - v[i]) / (2 * kPi));
    return v;
  };
  const Eigen::Vector3d ua = unwrap(a), ub = unwrap(b);
  return (ua - previous).squaredNorm() <= (ub - previous).squaredNorm() ? ua : ub;
}

std::string Number(double x) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.6f", std::abs(x) < 5e-7 ? 0.0 : x);
  return buf;
}

}  // namespace

bool BvhExportOptions::IsValid(std::string* error) const {
  auto fail = [error](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(units_per_metre > 0) || !std::isfinite(units_per_metre))
    return fail("units_per_metre: expected > 0, found " + Number(units_per_metre));
  std::string sorted = rotation_order;
  std::sort(sorted.begin(), sorted.end());
  if (sorted != "XYZ")
    return fail("rotation_order: expected a permutation of XYZ, found '" + rotation_order + "'");
  if (!(end_site_length >= 0) || !std::isfinite(end_site_length))
    return fail("end_site_length: expected >= 0, found " + Number(end_site_length));
  return true;
}

std::string EncodeBvh(const Template& tmpl, const std::vector<Pose>& poses, double frame_rate,
                      const BvhExportOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error("BVH export: " + why);
  if (!tmpl.IsValid(&why)) throw Error("BVH export: template: " + why);
  if (poses.empty()) throw Error("BVH export: expected at least one pose, found none");
  if (!(frame_rate > 0) || !std::isfinite(frame_rate))
    throw Error("BVH export: frame_rate: expected > 0, found " + Number(frame_rate));
  const int num_joints = tmpl.num_joints();
  std::vector<double> scales;
  for (std::size_t f = 0; f < poses.size(); ++f) {
    const Pose& p = poses[f];
    if (p.num_joints() != num_joints || !p.AllFinite() || !(p.scale > 0)) {
      throw Error("BVH export: poses[" + std::to_string(f) + "]: expected " +
                  std::to_string(num_joints) + " joints, finite values and a positive scale");
    }
    scales.push_back(p.scale);
  }
  std::nth_element(scales.begin(), scales.begin() + scales.size() / 2, scales.end());
  const double scale = scales[scales.size() / 2];
  const double unit = options.units_per_metre;

  std::vector<std::vector<int>> children(num_joints);
  for (int j = 1; j < num_joints; ++j) children[tmpl.joints[j].parent].push_back(j);
  // End Site lengths of leaf joints.
  std::vector<double> extent(num_joints, 0.0);
  for (int v = 0; v < tmpl.num_vertices(); ++v) {
    const int k = tmpl.vertex_joint[v];
    const Eigen::Vector3d d = tmpl.vertices.row(v).transpose() - tmpl.joints[k].center;
    extent[k] = std::max(extent[k], d.dot(tmpl.joints[k].twist_axis));
  }

  std::ostringstream out;
  out << "HIERARCHY\n";
  std::vector<int> order;  // joints in file (depth-first) order
  std::string channels_rot;
  for (char c : options.rotation_order) channels_rot += std::string(" ") + c + "rotation";
  std::function<void(int, int)> write_joint = [&](int j, int depth) {
    const std::string indent(2 * depth, ' ');
    const Joint& joint = tmpl.joints[j];
    const Eigen::Vector3d offset =
        scale * unit *
        (joint.parent >= 0 ? joint.center - tmpl.joints[joint.parent].center : joint.center);
    out << indent << (j == 0 ? "ROOT " : "JOINT ") << joint.name << "\n" << indent << "{\n";
    out << indent << "  OFFSET " << Number(offset.x()) << " " << Number(offset.y()) << " "
        << Number(offset.z()) << "\n";
    out << indent << "  CHANNELS " << (j == 0 ? "6 Xposition Yposition Zposition" : "3")
        << channels_rot << "\n";
    order.push_back(j);
    for (int c : children[j]) write_joint(c, depth + 1);
    if (children[j].empty()) {
      const double length = options.end_site_length > 0 ? options.end_site_length : extent[j];
      const Eigen::Vector3d end = scale * unit * length * joint.twist_axis;
      out << indent << "  End Site\n"
          << indent << "  {\n"
          << indent << "    OFFSET " << Number(end.x()) << " " << Number(end.y()) << " "
          << Number(end.z()) << "\n"
          << indent << "  }\n";
    }
    out << indent << "}\n";
  };
  write_joint(0, 0);

  out << "MOTION\nFrames: " << poses.size() << "\nFrame Time: " << Number(1.0 / frame_rate) << "\n";
  std::vector<Eigen::Vector3d> previous(num_joints, Eigen::Vector3d::Zero());
  for (const Pose& p : poses) {
    // Root: position s0 R0 t_root + t0 and rotation R0 R_root (see the header).
    const Eigen::Vector3d root =
        unit * (p.scale * p.rotation * tmpl.joints[0].center + p.translation);
    out << Number(root.x()) << " " << Number(root.y()) << " " << Number(root.z());
    for (int j : order) {
      const Eigen::Matrix3d local =
          j == 0 ? Eigen::Matrix3d(p.rotation * p.joint_rotations[0]) : p.joint_rotations[j];
      previous[j] = EulerNear(local, options.rotation_order, previous[j]);
      for (int i = 0; i < 3; ++i) out << " " << Number(previous[j][i] * 180.0 / kPi);
    }
    out << "\n";
  }
  return out.str();
}

void WriteBvh(const std::string& path, const Template& tmpl, const std::vector<Pose>& poses,
              double frame_rate, const BvhExportOptions& options) {
  std::string text;
  try {
    text = EncodeBvh(tmpl, poses, frame_rate, options);
  } catch (const Error& e) {
    throw Error(path + ": " + e.what());
  }
  WriteFileAtomically(path, text);
}

}  // namespace artex
