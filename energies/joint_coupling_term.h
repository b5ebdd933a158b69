// Coupled joints: a prior that two joints of a chain turn alike, on the difference of their
// rotation vectors phi_j = Log(R_j) (R_j relative to the rest pose, rest frame, radians):
//   r_p = sqrt(w) (phi_a - phi_b)      (3 residuals per pair p = (a, b))
// For the neck and the head (docs/fitting.md "Coupled neck and head"): a short thick neck and a
// near-ellipsoid head leave a bent neck with the head turned back almost unobserved (nearly the
// same surface), while a person's cervical spine turns neck and head the same way. The prior
// removes the counter-rotation and leaves a head turn or nod shared by both joints free.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "energies/fitting_term.h"

namespace artex {

struct JointCouplingOptions {
  // w (cost units per rad^2 of the difference; the data term is a mean squared distance in m^2,
  // fitting.normalize_data_term); 0 disables the prior.
  double weight = 1e-2;
  // Joint pairs by name (config `fitting.joint_coupling.pairs`: [neck, head], two by two). A
  // pair naming a joint the template lacks is skipped (an imported rig may name its joints
  // otherwise; `artex track` warns).
  std::vector<std::pair<std::string, std::string>> pairs = {{"neck", "head"}};

  bool IsValid(std::string* error) const;  // weight >= 0 and finite, no pair of one joint
};

class JointCouplingTerm : public FittingTerm {
 public:
  // Resolves the pairs' names among `joint_names` (pairs with a name not among them are
  // skipped).
  JointCouplingTerm(const JointCouplingOptions& options,
                    const std::vector<std::string>& joint_names);
  // The names of `options.pairs` that are no joint of `joint_names` ("" when none).
  static std::string MissingJoints(const JointCouplingOptions& options,
                                   const std::vector<std::string>& joint_names);

  std::string name() const override { return "joint_coupling"; }
  int num_residuals() const override { return 3 * static_cast<int>(pairs_.size()); }
  bool Evaluate(const FitEvaluation& eval, double* residuals, double* jacobian) const override;

 private:
  double sqrt_weight_;
  std::vector<std::pair<int, int>> pairs_;  // joint indices
};

}  // namespace artex
