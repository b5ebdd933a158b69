// Constant-velocity pose smoothness prior: theta_f should stay close to the prediction
// theta_{f-1}.Retracted(theta_{f-2}.LocalCoordinates(theta_{f-1})), i.e. "2 theta_{f-1} -
// theta_{f-2}" on the manifold (rotations: R_{f-1} R_{f-2}^T R_{f-1}).
//   r = sqrt(W) .* prediction.LocalCoordinates(theta)      (P residuals, W per parameter group)
#pragma once

#include <string>

#include "energies/fitting_term.h"

namespace artex {

// The constant-velocity extrapolation of two consecutive poses (same joint count).
Pose ConstantVelocityPrediction(const Pose& before_previous, const Pose& previous);

class PoseSmoothnessTerm : public FittingTerm {
 public:
  PoseSmoothnessTerm(const PoseGroupWeights& weights, const Pose& before_previous,
                     const Pose& previous);

  std::string name() const override { return "pose_smoothness"; }
  int num_residuals() const override { return static_cast<int>(sqrt_weights_.size()); }
  bool Evaluate(const FitEvaluation& eval, double* residuals, double* jacobian) const override;
  const Pose& prediction() const { return prediction_; }

 private:
  Eigen::VectorXd sqrt_weights_;
  Pose prediction_;
};

}  // namespace artex
