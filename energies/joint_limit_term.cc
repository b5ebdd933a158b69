#include "energies/joint_limit_term.h"

#include <cmath>
#include <sstream>

#include "models/error.h"
#include "models/numeric.h"
#include "models/so3.h"

namespace artex {

bool JointLimitOptions::IsValid(int num_joints, std::string* error) const {
  std::ostringstream msg;
  if (!(std::isfinite(weight) && weight >= 0.0)) {
    msg << "weight: expected a finite value >= 0, found " << weight;
  } else if (!per_joint_min.empty() && static_cast<int>(per_joint_min.size()) != num_joints) {
    msg << "per_joint_min: expected " << num_joints << " entries, found " << per_joint_min.size();
  } else if (per_joint_max.size() != per_joint_min.size()) {
    msg << "per_joint_max: expected " << per_joint_min.size() << " entries (as per_joint_min), found "
        << per_joint_max.size();
  } else if (!(default_min.array() <= default_max.array()).all()) {
    msg << "default_min/default_max: expected min <= max per component";
  } else {
    for (size_t j = 0; j < per_joint_min.size(); ++j) {
      if (!(per_joint_min[j].array() <= per_joint_max[j].array()).all()) {
        msg << "per_joint_min/max[" << j << "]: expected min <= max per component";
        break;
      }
    }
    if (msg.str().empty()) return true;
  }
  if (error) *error = msg.str();
  return false;
}

namespace {

// Degrees, rotation-vector components of a left (or central) joint in the rest frame. About
// +x: positive bends the segment's far end towards -z for a downward segment (hip extension,
// knee flexion) and towards +z for an upward one (spine, neck and head bending forwards).
// About +z: positive moves a downward left segment outwards (hip abduction). The ranges are a
// healthy adult's active range of motion with a margin, since the rotation-vector components
// of a combined rotation are not its Euler angles.
struct AnatomicalEntry {
  const char* name;
  double min_deg[3];
  double max_deg[3];
};

constexpr AnatomicalEntry kAnatomical[] = {
    // The pelvis joint turns the whole body below the root like the global rotation does:
    // a small box keeps the two from trading a contorted spine for a turned pelvis.
    {"pelvis", {-30, -30, -30}, {30, 30, 30}},
    {"spine", {-35, -40, -35}, {55, 40, 35}},
    {"chest", {-35, -40, -35}, {55, 40, 35}},
    {"neck", {-50, -70, -45}, {55, 70, 45}},
    {"head", {-40, -60, -40}, {45, 60, 40}},
    {"l_hip", {-125, -55, -35}, {35, 55, 55}},
    {"l_knee", {-10, -25, -20}, {150, 25, 20}},
    {"l_ankle", {-55, -35, -35}, {55, 35, 35}},
    {"l_wrist", {-90, -90, -90}, {90, 90, 90}},
};

}  // namespace

bool AnatomicalJointBox(const std::string& joint_name, JointBox* box) {
  const bool right = joint_name.rfind("r_", 0) == 0;
  const std::string left = right ? "l_" + joint_name.substr(2) : joint_name;
  for (const AnatomicalEntry& e : kAnatomical) {
    if (left != e.name) continue;
    for (int c = 0; c < 3; ++c) {
      box->min[c] = e.min_deg[c] * kDegToRad;
      box->max[c] = e.max_deg[c] * kDegToRad;
    }
    if (right) {  // mirror x -> -x: a rotation vector (x, y, z) becomes (x, -y, -z)
      for (int c = 1; c < 3; ++c) {
        const double lo = box->min[c];
        box->min[c] = -box->max[c];
        box->max[c] = -lo;
      }
    }
    return true;
  }
  return false;
}

JointLimitOptions ResolveJointLimits(const JointLimitOptions& options,
                                     const std::vector<std::string>& joint_names) {
  JointLimitOptions resolved = options;
  const bool own = !options.per_joint_min.empty();
  const int n = static_cast<int>(joint_names.size());
  resolved.per_joint_min.resize(n);
  resolved.per_joint_max.resize(n);
  for (int j = 0; j < n; ++j) {
    JointBox box{own ? options.per_joint_min[j] : options.default_min,
                 own ? options.per_joint_max[j] : options.default_max};
    if (options.preset == JointLimitPreset::kAnatomical) AnatomicalJointBox(joint_names[j], &box);
    const auto it = options.joints.find(joint_names[j]);
    if (it != options.joints.end()) box = it->second;
    resolved.per_joint_min[j] = box.min;
    resolved.per_joint_max[j] = box.max;
  }
  for (const auto& [name, box] : options.joints) {
    bool found = false;
    for (const std::string& j : joint_names) found = found || j == name;
    if (!found) {
      std::string known;
      for (const std::string& j : joint_names) known += (known.empty() ? "" : ", ") + j;
      throw Error("fitting options: joint_limits.joints." + name +
                  ": expected a joint of the template (" + known + "), found none of that name");
    }
  }
  return resolved;
}

const std::map<std::string, JointLimitPreset>& JointLimitPresetNames() {
  static const std::map<std::string, JointLimitPreset> names = {
      {"uniform", JointLimitPreset::kUniform}, {"anatomical", JointLimitPreset::kAnatomical}};
  return names;
}

JointLimitTerm::JointLimitTerm(const JointLimitOptions& options, int num_joints)
    : sqrt_weight_(std::sqrt(options.weight)) {
  for (int j = 0; j < num_joints; ++j) {
    const bool own = !options.per_joint_min.empty();
    min_.push_back(own ? options.per_joint_min[j] : options.default_min);
    max_.push_back(own ? options.per_joint_max[j] : options.default_max);
  }
}

bool JointLimitTerm::Evaluate(const FitEvaluation& eval, double* residuals,
                              double* jacobian) const {
  const int num_joints = static_cast<int>(min_.size());
  const int p = static_cast<int>(eval.delta.size());
  Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> j(
      jacobian, jacobian != nullptr ? 3 * num_joints : 0, p);
  if (jacobian != nullptr) j.setZero();
  for (int k = 0; k < num_joints; ++k) {
    const Eigen::Vector3d phi = LogSO3(eval.pose.joint_rotations[k]);
    Eigen::Matrix3d d_phi;
    if (jacobian != nullptr) d_phi = LeftJacobianInverseSO3(phi) * eval.delta_to_local[k + 1];
    for (int c = 0; c < 3; ++c) {
      double excess = 0.0;
      if (phi[c] > max_[k][c]) excess = phi[c] - max_[k][c];
      if (phi[c] < min_[k][c]) excess = phi[c] - min_[k][c];
      residuals[3 * k + c] = sqrt_weight_ * excess;
      if (jacobian != nullptr && excess != 0.0) {
        j.block<1, 3>(3 * k + c, JointParameterIndex(k)) = sqrt_weight_ * d_phi.row(c);
      }
    }
  }
  if (!Eigen::Map<const Eigen::VectorXd>(residuals, 3 * num_joints).allFinite()) return false;
  return jacobian == nullptr || j.allFinite();
}

}  // namespace artex
