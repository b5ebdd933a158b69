// Upright prior on the lower body (docs/fitting.md "Joint limits and the upright prior"): the
// pelvis's up axis u = R0 R_pelvis y (world, +Y up) may tilt from world up by max_tilt freely;
// beyond it a hinge pulls it back: r = sqrt(w) max(0, acos(u . y) - max_tilt) (1 residual).
// It holds a lower body the scan does not see (an upper-body view) standing, where the global
// rotation and the pelvis and spine joints otherwise trade freely.
#pragma once

#include <string>

#include "energies/fitting_term.h"

namespace artex {

struct UprightOptions {
  // Per rad^2 of tilt beyond max_tilt (data-term cost units); 0: off. The default acts only in
  // frames where joints are out of the depth camera's view (below): when the legs are below the
  // image, nothing in the scan holds the pelvis, and the held legs swing out with it.
  double weight = 0.01;
  double max_tilt_deg = 10;  // degrees of free tilt of the pelvis from world up, in [0, 180)
  // true: only in frames in which the fitter holds joints out of view (solvers/out_of_view.h);
  // false: in every frame.
  bool only_out_of_view = true;

  bool IsValid(std::string* error) const;
};

class UprightTerm : public FittingTerm {
 public:
  // `pelvis_joint`: the template joint whose up axis is held (-1: the global rotation alone).
  UprightTerm(const UprightOptions& options, int pelvis_joint);

  std::string name() const override { return "upright"; }
  int num_residuals() const override { return 1; }
  bool Evaluate(const FitEvaluation& eval, double* residuals, double* jacobian) const override;

 private:
  double sqrt_weight_;
  double max_tilt_;  // rad
  int pelvis_;
};

}  // namespace artex
