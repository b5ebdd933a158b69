// The common contract of the kinematic fitting terms (paper eq. 3-5, docs/design.md "Fitting
// energy"). Every term is a residual vector r(delta) of a tangent offset `delta` (P = 7 + 3 J
// entries, layout of models/pose.h) around an anchor pose: theta(delta) = anchor.Retracted(delta).
// Its cost is |r|^2 (no factor 1/2; Ceres reports half of it). Work shared by all terms of one
// evaluation (posing the template, its skinning Jacobian) is done once in a FitEvaluation.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "models/pose.h"
#include "models/skinning.h"

namespace artex {

// Per-parameter-group weights of a pose prior (cost w * x^2 per tangent component):
// scale (1/1), translation (1/m^2), global rotation (1/rad^2), joint rotations (1/rad^2).
struct PoseGroupWeights {
  double scale = 0.0;
  double translation = 0.0;
  double rotation = 0.0;
  double joints = 0.0;

  // P-vector of weights laid out like the pose tangent.
  Eigen::VectorXd Expand(int num_joints) const;
  bool AllZero() const { return scale == 0 && translation == 0 && rotation == 0 && joints == 0; }
  // False when a weight is negative or not finite; names the group in *error.
  bool IsValid(std::string* error) const;
};

// The state every term reads at one evaluation point.
struct FitEvaluation {
  const Skinning* skinning = nullptr;  // the skinning that produced posed / jacobian
  Eigen::VectorXd delta;        // P: offset from the anchor
  Pose pose;                    // anchor.Retracted(delta)
  Eigen::MatrixX3d posed;       // V x 3 posed template (valid when has_posed)
  SkinningJacobian jacobian;    // d posed / d local perturbation at `pose` (when has_jacobian)
  bool has_posed = false;
  bool has_jacobian = false;
  // Per rotation (global first, then joints): J_l(w) with w the rotation part of delta, so that
  // d(local perturbation) = J_l(w) d(delta). All identity when delta is zero.
  std::vector<Eigen::Matrix3d> delta_to_local;
  bool delta_is_zero = true;
};

// Fills *eval at anchor (+) delta. Skinning runs only when `need_posed` (with its Jacobian
// when also `need_jacobian`); `skinning` may be null when neither is needed.
void PrepareFitEvaluation(const Skinning* skinning, const Pose& anchor,
                          const Eigen::VectorXd& delta, bool need_posed, bool need_jacobian,
                          FitEvaluation* eval);

// Right-multiplies a Jacobian w.r.t. local perturbations (row-major rows x P) by
// blockdiag(1, I, J_l(w0), J_l(w_j)...) to make it a Jacobian w.r.t. delta. No-op at delta = 0.
void LocalToDeltaJacobian(const FitEvaluation& eval, int rows, double* jacobian);

// SO(3) left Jacobian J_l(w) (Exp(w + dw) = Exp(J_l(w) dw) Exp(w)) and its inverse; exact
// series near w = 0.
Eigen::Matrix3d LeftJacobianSO3(const Eigen::Vector3d& w);
Eigen::Matrix3d LeftJacobianInverseSO3(const Eigen::Vector3d& w);

class FittingTerm {
 public:
  virtual ~FittingTerm() = default;
  virtual std::string name() const = 0;
  virtual int num_residuals() const = 0;
  // Whether Evaluate reads eval.posed / eval.jacobian.
  virtual bool needs_skinning() const { return false; }

  // The Ceres CostFunction contract at the evaluation point: writes num_residuals() residuals;
  // when `jacobian` is non-null also d r / d delta, row-major num_residuals() x P (requires
  // eval.has_jacobian for terms that need skinning). Returns false when a value is not finite.
  virtual bool Evaluate(const FitEvaluation& eval, double* residuals, double* jacobian) const = 0;

  // Gauss-Newton normal equations: adds J^T J to *jtj (P x P) and J^T r to *jtr (P), returns
  // |r|^2 (NaN when not finite). The default goes through Evaluate with a dense Jacobian;
  // terms with many residuals override it with a block-sparse accumulation.
  virtual double AccumulateNormalEquations(const FitEvaluation& eval, Eigen::MatrixXd* jtj,
                                           Eigen::VectorXd* jtr) const;
  // |r|^2 without Jacobians (NaN when not finite).
  virtual double Cost(const FitEvaluation& eval) const;
};

// Residual of a prior pulling theta towards `reference`:
//   r = sqrt(weights) .* reference.LocalCoordinates(theta)   (P entries)
// with its Jacobian w.r.t. delta (rotation blocks J_l^{-1}(Log(R R_ref^T)) J_l(w)). Shared by
// the temporal (previous frame) and constant-velocity priors.
bool ReferencePoseResidual(const Pose& reference, const Eigen::VectorXd& sqrt_weights,
                           const FitEvaluation& eval, double* residuals, double* jacobian);

}  // namespace artex
