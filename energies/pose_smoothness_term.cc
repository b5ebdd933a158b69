#include "energies/pose_smoothness_term.h"

namespace artex {

Pose ConstantVelocityPrediction(const Pose& before_previous, const Pose& previous) {
  return previous.Retracted(before_previous.LocalCoordinates(previous));
}

PoseSmoothnessTerm::PoseSmoothnessTerm(const PoseGroupWeights& weights,
                                       const Pose& before_previous, const Pose& previous)
    : sqrt_weights_(weights.Expand(previous.num_joints()).cwiseSqrt()),
      prediction_(ConstantVelocityPrediction(before_previous, previous)) {}

bool PoseSmoothnessTerm::Evaluate(const FitEvaluation& eval, double* residuals,
                                  double* jacobian) const {
  return ReferencePoseResidual(prediction_, sqrt_weights_, eval, residuals, jacobian);
}

}  // namespace artex
