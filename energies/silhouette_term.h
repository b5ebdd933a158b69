// Silhouette (free-space) term of the fitting (docs/fitting.md "Silhouette term"): the scan
// only pulls the template where it has points; nothing stops a limb without correspondences
// from swinging into empty space in view (a leg below the image border raised beside the body,
// a head pitched back above the scan). For every fitted vertex that projects onto a free pixel
// of the frame's SilhouetteMap (sensors/silhouette.h) in front of the observed surface, the
// E-step-like FindSilhouetteViolations fixes a target y_t: the back-projection of the nearest
// allowed pixel at the vertex's camera depth. The residuals are the lateral offsets
//   r_t = sqrt(w) (a_u . (x_t - y_t), a_v . (x_t - y_t)),
// a_u, a_v the depth camera's x and y axes in the world, i.e. the image-plane distance in
// metres to the allowed region. A vertex that projects onto the subject but lies in front of
// its observed surface by more than the margin is in free space as well: its target is the
// observed surface point on its ray and its residual the depth offset sqrt(w) a_z . (x_t - y_t)
// (pushed behind the surface, where the camera could not have seen it). Vertices without
// violation have no residual (weight 0).
#pragma once

#include <string>

#include <Eigen/Core>

#include "energies/fitting_term.h"
#include "sensors/silhouette.h"

namespace artex {

struct SilhouetteTermOptions {
  // Cost weight per violating vertex relative to the data term's weighted mean (the term's
  // weight is weight / fitted vertices, so 1 makes a vertex 1 cm outside the silhouette cost
  // like a vertex 1 cm from its correspondence). 0: off, the default: measured on the virtual
  // Kinect conditions and the real recordings it helps some and breaks others (docs/fitting.md
  // "Silhouette term").
  double weight = 0.0;
  // m: a vertex counts as in front of the observed surface when nearer than it by this.
  double depth_margin = 0.05;
  // Weight of the in-front-of-the-subject residual relative to `weight` (0: off, only vertices
  // outside the silhouette count). Off by default: a template thicker than the subject sits
  // in front of its surface and is pushed back and grown (upper-body framing: 27 -> 82 mm).
  double front_weight = 0.0;
  // Radius E-step: the term acts only in stages with a radius at most this (m); the coarse
  // first-frame stages place the template first (pulled into the silhouette from a wrong
  // placement, limbs fold where they should turn).
  double max_radius = 0.05;

  bool IsValid(std::string* error) const;
};

// Per fitted vertex (T rows): weight 1 for a violation of its kind, 0 otherwise; target y_t
// and the axes.
struct SilhouetteTargets {
  Eigen::VectorXd weight;        // outside the silhouette (lateral residuals)
  Eigen::VectorXd depth_weight;  // in front of the subject's surface (depth residual)
  Eigen::MatrixX3d target;
  Eigen::MatrixX3d axis_u, axis_v, axis_z;  // every row the camera's x, y, z axis in the world
  int violations = 0;        // both kinds
  int depth_violations = 0;  // of them in front of the subject

  int size() const { return static_cast<int>(weight.size()); }
};

// Finds the violations of `posed` (T x 3 world) against `map`; front_weight 0 skips the
// in-front kind.
void FindSilhouetteViolations(const SilhouetteMap& map, const Eigen::MatrixX3d& posed,
                              const SilhouetteTermOptions& options, SilhouetteTargets* targets);

// M-step term over `targets` (which must outlive it, T = the fitted vertex count); `weight`
// multiplies every squared residual.
class SilhouetteTerm : public FittingTerm {
 public:
  SilhouetteTerm(const SilhouetteTargets* targets, double weight);

  std::string name() const override { return "silhouette"; }
  int num_residuals() const override { return 3 * targets_->size(); }
  bool needs_skinning() const override { return true; }
  bool Evaluate(const FitEvaluation& eval, double* residuals, double* jacobian) const override;
  double AccumulateNormalEquations(const FitEvaluation& eval, Eigen::MatrixXd* jtj,
                                   Eigen::VectorXd* jtr) const override;
  double Cost(const FitEvaluation& eval) const override;

 private:
  const SilhouetteTargets* targets_;
  double weight_;
};

}  // namespace artex
