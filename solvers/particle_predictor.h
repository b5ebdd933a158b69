// Multi-hypothesis (particle) prediction of a tracking frame (docs/fitting.md "Prediction"):
// the frame is first fitted from the base prediction (PredictionOptions::particle.base); when
// the trigger fires (every frame, or when that fit's quality drops) a bounded set of hypotheses
// is sampled around the prediction (the previous pose, then per-limb joint perturbations with
// a small global jitter, seeded by (seed, frame)), each is fitted by a few EM iterations and
// ranked by the fit quality (solvers/fit_quality.h), the best is refined by a whole tracking
// fit, and the better of it and the base fit (by quality score) is accepted.
#pragma once

#include <string>
#include <vector>

#include "render/camera.h"
#include "sensors/scan.h"
#include "solvers/em_fitter.h"
#include "solvers/fit_quality.h"

namespace artex {

struct ParticleFrameReport {
  bool triggered = false;     // hypotheses were sampled
  int hypotheses = 0;         // fitted (besides the base fit)
  int chosen = -1;            // -1: the base fit, else the hypothesis index
  double base_score = 0.0;    // quality score of the base fit
  double chosen_score = 0.0;  // of the accepted fit
  int em_iterations = 0;      // over the base fit, the hypotheses and the refinement
};

// Limbs of the template for per-limb perturbations (ParticleOptions): the last max_joints
// joints of every chain ending in a leaf joint, up to (not including) a joint with several
// children or the root; each limb lists its joints, root first.
std::vector<std::vector<int>> TemplateLimbs(const Template& tmpl, int max_joints);

// The hypotheses of a triggered frame (ParticleOptions): previous, the step-scaled
// predictions, then the random per-limb perturbations of `centre` from (seed, frame).
std::vector<Pose> ParticleHypotheses(const Pose& previous, const Pose& centre,
                                     const std::vector<std::vector<int>>& limbs,
                                     const ParticleOptions& options, int frame);

// Fits `scan` as the next frame of `fitter`: the multi-hypothesis step when
// fitter->options().prediction.model is kParticle and the frame is a tracking frame, else
// fitter->FitFrame(scan). The returned summary is the accepted fit's, with iterations and
// total_seconds over all fits of the frame. depth_camera and quality rank the hypotheses.
FitSummary TrackFrame(EMFitter* fitter, const Scan& scan, const PinholeCamera& depth_camera,
                      const FitQualityOptions& quality, ParticleFrameReport* report = nullptr);

}  // namespace artex
