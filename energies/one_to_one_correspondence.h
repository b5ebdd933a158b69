// One-to-one nearest-neighbour correspondence: the articulated ICP baseline the paper's
// one-to-many energy is compared with. Each template vertex t is paired with at most one scan
// point y_t (found by solvers/estep.h, gated by distance and normal compatibility):
//   point-to-point: r_t = sqrt(w w_t) (v'_t(theta) - y_t)            (3 residuals per vertex)
//   point-to-plane: r_t = sqrt(w w_t) n_t . (v'_t(theta) - y_t)       (1 residual per vertex)
// with n_t the scan normal at y_t; w_t = 0 marks an unmatched vertex.
#pragma once

#include <string>

#include <Eigen/Core>

#include "energies/fitting_term.h"

namespace artex {

enum class IcpMetric { kPointToPoint, kPointToPlane };

struct OneToOneOptions {
  IcpMetric metric = IcpMetric::kPointToPlane;
  double max_distance = 0.10;    // pairs farther apart are rejected (m)
  double min_normal_dot = 0.5;   // pairs with n_s . n'_t below this are rejected (cosine)

  bool IsValid(std::string* error) const;
};

// Nearest-neighbour pairs per template vertex (T rows each).
struct NearestTargets {
  Eigen::VectorXd weight;     // w_t: 1 for a valid pair, 0 otherwise
  Eigen::MatrixX3d point;     // y_t (m)
  Eigen::MatrixX3d normal;    // scan normal at y_t (unit)
  Eigen::VectorXi index;      // scan index of y_t, -1 when unmatched
  int num_matched = 0;

  int size() const { return static_cast<int>(weight.size()); }
};

// `targets` must outlive the term and have the template's vertex count.
class OneToOneCorrespondenceTerm : public FittingTerm {
 public:
  OneToOneCorrespondenceTerm(const NearestTargets* targets, IcpMetric metric, double weight);

  std::string name() const override { return "one_to_one"; }
  int num_residuals() const override {
    return (metric_ == IcpMetric::kPointToPoint ? 3 : 1) * targets_->size();
  }
  bool needs_skinning() const override { return true; }
  bool Evaluate(const FitEvaluation& eval, double* residuals, double* jacobian) const override;
  double AccumulateNormalEquations(const FitEvaluation& eval, Eigen::MatrixXd* jtj,
                                   Eigen::VectorXd* jtr) const override;
  double Cost(const FitEvaluation& eval) const override;

 private:
  const NearestTargets* targets_;
  IcpMetric metric_;
  double weight_;
};

}  // namespace artex
