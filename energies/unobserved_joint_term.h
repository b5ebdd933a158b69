// Prior on the joints the scan does not observe (docs/fitting.md "Unobserved joints"): a limb
// whose fitted vertices have (almost) no correspondences is held by nothing in the data term
// and drifts where the other terms push it (legs below the image border swinging into view, or
// in front of the body). For every joint with fewer than min_observed_fraction of its fitted
// vertices matched by the E-step, r = sqrt(w) Log(R_j R_ref,j^T) pulls its rotation towards a
// reference: the rest pose in a first frame, the previous frame's pose when tracking.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "energies/fitting_term.h"
#include "models/pose.h"
#include "models/template.h"

namespace artex {

struct UnobservedJointOptions {
  // Per rad^2 of an unobserved joint (data-term cost units); 0: off, the default (1e-3 is the
  // measured setting of docs/fitting.md "Unobserved joints": better on upper-body framing,
  // worse on the real stills).
  double weight = 0.0;
  // A joint with fewer than this fraction of its fitted vertices matched is unobserved.
  double min_observed_fraction = 0.3;

  bool IsValid(std::string* error) const;
};

// Joints (template indices) whose fitted vertices are matched less than `fraction`:
// vertex_joint[i] is the joint of fitted vertex i and `matched[i]` its E-step weight
// (> 0: matched). Joints without fitted vertices are not listed.
std::vector<int> UnobservedJoints(const Eigen::VectorXi& vertex_joint,
                                  const Eigen::VectorXd& matched, int num_joints,
                                  double fraction);

class UnobservedJointTerm : public FittingTerm {
 public:
  // `reference` must outlive the term; only the listed joints' rotations are pulled.
  UnobservedJointTerm(const Pose* reference, const std::vector<int>& joints, double weight);

  std::string name() const override { return "unobserved_joints"; }
  int num_residuals() const override { return sqrt_weights_.size(); }
  bool Evaluate(const FitEvaluation& eval, double* residuals, double* jacobian) const override;

 private:
  const Pose* reference_;
  Eigen::VectorXd sqrt_weights_;  // P
};

}  // namespace artex
