// One-to-many probabilistic correspondence of the paper (eq. 3-4, docs/design.md "Fitting energy"):
//   Q(theta) = sum_s sum_t p_st |v_s - S(v_t; theta)|^2,
//   p_st = max(0, n_s . n'_t) / (|v_s - v'_t|^2 + lambda_c |rgb_s - rgb'_t|^2 + eps).
// For p fixed by the E-step (solvers/estep.h), sum_s p_st |v_s - x|^2 = P_t |x - mu_t|^2 + c_t
// with P_t = sum_s p_st and mu_t = sum_s p_st v_s / P_t, so the M-step term is the weighted
// one-to-one residual r_t = sqrt(w P_t) (S(v_t; theta) - mu_t), 3 per template vertex.
#pragma once

#include <string>

#include <Eigen/Core>

#include "energies/fitting_term.h"

namespace artex {

struct OneToManyOptions {
  double epsilon = 1e-4;        // eps of eq. 4 (m^2): 1 cm^2
  double lambda_color = 1.0;    // lambda_c (m^2 per unit squared RGB distance); paper: 1
  bool use_color = true;        // colour term; applied only when template colours are given
  // CPD-like normalisation per scan point: p_st <- p_st / sum_t p_st (over the pairs searched).
  bool normalize_per_scan_point = false;

  bool IsValid(std::string* error) const;
};

// p_st of eq. 4 for one pair; `color_distance2` = |rgb_s - rgb'_t|^2 (0 without colour).
inline double CorrespondenceWeight(double normal_dot, double distance2, double color_distance2,
                                   const OneToManyOptions& options) {
  if (!(normal_dot > 0.0)) return 0.0;
  return normal_dot / (distance2 + options.lambda_color * color_distance2 + options.epsilon);
}

// E-step output per template vertex t (T entries each).
struct CorrespondenceTargets {
  Eigen::VectorXd weight;    // P_t = sum_s p_st (>= 0; 0: vertex has no correspondence)
  Eigen::MatrixX3d mean;     // mu_t (m); rows with P_t = 0 are zero
  // sum_t c_t, c_t = sum_s p_st |v_s|^2 - P_t |mu_t|^2, so that Q = data cost + constant.
  double constant = 0.0;
  long long num_pairs = 0;   // (s, t) pairs with p_st > 0

  int size() const { return static_cast<int>(weight.size()); }
  double total_weight() const { return weight.sum(); }
};

// M-step data term: residuals sqrt(w P_t) (v'_t(theta) - mu_t), 3 T entries, w = `weight`
// (e.g. 1 / sum_t P_t to make the cost a weighted mean of squared distances, m^2).
// `targets` must outlive the term and have the template's vertex count.
class OneToManyCorrespondenceTerm : public FittingTerm {
 public:
  OneToManyCorrespondenceTerm(const CorrespondenceTargets* targets, double weight);

  std::string name() const override { return "one_to_many"; }
  int num_residuals() const override { return 3 * targets_->size(); }
  bool needs_skinning() const override { return true; }
  bool Evaluate(const FitEvaluation& eval, double* residuals, double* jacobian) const override;
  double AccumulateNormalEquations(const FitEvaluation& eval, Eigen::MatrixXd* jtj,
                                   Eigen::VectorXd* jtr) const override;
  double Cost(const FitEvaluation& eval) const override;

 private:
  const CorrespondenceTargets* targets_;
  double weight_;
};

// Shared by the correspondence terms (x_t = eval.posed row t, J_t its Jacobian w.r.t. delta):
// adds sum_t c w_t J_t^T J_t to *jtj and sum_t c w_t J_t^T (x_t - y_t) to *jtr over the
// vertices with w_t > 0 (block-sparse, parallel), returns sum_t c w_t |x_t - y_t|^2.
// With `normals` non-null the residual is point-to-plane: c w_t (n_t . (x_t - y_t))^2.
// *jtj and *jtr may be null (cost only).
double AccumulateVertexResiduals(const FitEvaluation& eval, const Eigen::VectorXd& weights,
                                 double c, const Eigen::MatrixX3d& targets,
                                 const Eigen::MatrixX3d* normals, Eigen::MatrixXd* jtj,
                                 Eigen::VectorXd* jtr);

}  // namespace artex
