// Soft joint-angle limits: a box per joint on the rotation-vector components phi_j = Log(R_j)
// (R_j relative to the rest pose, rest frame, radians). Hinge-squared penalty per component:
//   r_jc = sqrt(w) * (max(0, phi_jc - max_jc) + min(0, phi_jc - min_jc))     (3 J residuals)
#pragma once

#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "energies/fitting_term.h"

namespace artex {

// The boxes of joints without an entry of their own: `default_min/max` for every joint
// (kUniform), or a human's range of motion for the joints of artex's template by name
// (kAnatomical, AnatomicalJointBox; other joints keep `default_min/max`).
enum class JointLimitPreset { kUniform, kAnatomical };

struct JointBox {
  Eigen::Vector3d min, max;  // rad, rotation-vector components in the rest frame
};

struct JointLimitOptions {
  double weight = 0.0;  // w (cost units per rad^2); 0 disables the prior
  JointLimitPreset preset = JointLimitPreset::kUniform;
  // Boxes by joint name; they override the preset (config `fitting.joint_limits.joints`).
  std::map<std::string, JointBox> joints;
  // Box applied to every joint without an entry in `per_joint_min/max` (rad).
  Eigen::Vector3d default_min = Eigen::Vector3d::Constant(-2.5);
  Eigen::Vector3d default_max = Eigen::Vector3d::Constant(2.5);
  // Optional per-joint boxes: empty, or one entry per template joint.
  std::vector<Eigen::Vector3d> per_joint_min;
  std::vector<Eigen::Vector3d> per_joint_max;

  // Checks weight >= 0, min <= max and the per-joint sizes against `num_joints`.
  bool IsValid(int num_joints, std::string* error) const;
};

// The anatomical range of motion of a joint of artex's template (models/template_generator.h:
// A-pose, Y up, front +Z, "l_" joints at +x) by name, e.g. hip flexion up to 125 degrees and
// abduction up to 55 degrees, a knee that bends backwards only. Right joints mirror the left
// ones (x, -y, -z). False for a name it does not know.
bool AnatomicalJointBox(const std::string& joint_name, JointBox* box);

// `options` with `per_joint_min/max` filled for the named joints: the preset, then `joints`.
// Throws Error naming an entry of `joints` that is no joint of `joint_names`.
JointLimitOptions ResolveJointLimits(const JointLimitOptions& options,
                                     const std::vector<std::string>& joint_names);

// The preset names for configuration ("uniform", "anatomical").
const std::map<std::string, JointLimitPreset>& JointLimitPresetNames();

class JointLimitTerm : public FittingTerm {
 public:
  JointLimitTerm(const JointLimitOptions& options, int num_joints);

  std::string name() const override { return "joint_limits"; }
  int num_residuals() const override { return 3 * static_cast<int>(min_.size()); }
  bool Evaluate(const FitEvaluation& eval, double* residuals, double* jacobian) const override;

 private:
  double sqrt_weight_;
  std::vector<Eigen::Vector3d> min_, max_;
};

}  // namespace artex
