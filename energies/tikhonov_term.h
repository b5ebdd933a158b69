// Tikhonov and temporal regularisation of the pose (paper eq. 5 and sec. 3):
//   update part:   r = sqrt(Gamma) .* delta          (keeps the M-step update small; Gamma per
//                                                    parameter group, the paper's Tikhonov matrix)
//   temporal part: r = sqrt(W) .* theta_prev.LocalCoordinates(theta)  (pulls towards the
//                  previous frame's pose; rotations via Log(R R_prev^T))
// P residuals per part (P = 7 + 3 J); the temporal part is present only with a reference pose.
#pragma once

#include <string>

#include "energies/fitting_term.h"

namespace artex {

struct TikhonovOptions {
  // Gamma: weights on the tangent update from the M-step's start pose (cost units of the data
  // term, i.e. m^2 when the data term is normalised to a weighted mean, per unit^2 / m^2 / rad^2).
  PoseGroupWeights update = {1e-3, 1e-5, 1e-5, 1e-5};
  // Weights of the temporal prior to the previous frame's pose (0: off).
  PoseGroupWeights temporal = {0.0, 0.0, 0.0, 0.0};

  bool IsValid(std::string* error) const;
};

class TikhonovTerm : public FittingTerm {
 public:
  // `previous` (may be null: no temporal part) must outlive the term.
  TikhonovTerm(const TikhonovOptions& options, int num_joints, const Pose* previous);

  std::string name() const override { return "tikhonov"; }
  int num_residuals() const override;
  bool Evaluate(const FitEvaluation& eval, double* residuals, double* jacobian) const override;

 private:
  Eigen::VectorXd sqrt_update_;
  Eigen::VectorXd sqrt_temporal_;
  const Pose* previous_;
};

}  // namespace artex
