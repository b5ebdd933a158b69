// Prediction of the next frame's pose, the EM fitter's initial guess for a tracking frame
// (docs/fitting.md "Prediction"), behind one interface chosen by PredictionOptions::model:
//   kPrevious:         the last accepted pose;
//   kConstantVelocity: the last pose moved on by the tangent step between the last two
//                      (ConstantVelocityPrediction, energies/pose_smoothness_term.h);
//   kKalman:           a Kalman filter over the pose tangent space (solvers/kalman_predictor.h)
//                      fed with the fitted poses and their Gauss-Newton information;
//   kParticle:         multi-hypothesis fitting around the prediction of `particle.base`
//                      (solvers/particle_predictor.h; the predictor itself is the base's).
// A failed frame (its previous pose kept) is reported by ObserveMissing: previous and constant
// velocity repeat the kept pose (zero velocity next), the Kalman filter only time-updates.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "models/pose.h"
#include "solvers/kalman_predictor.h"

namespace artex {

enum class PredictionModel { kPrevious, kConstantVelocity, kKalman, kParticle };
// "previous", "constant_velocity", "kalman", "particle".
const std::map<std::string, PredictionModel>& PredictionModelNames();
const char* PredictionModelName(PredictionModel model);

// When the particle stage runs: kAlways on every tracking frame; kQualityDrop only when the fit
// from the base prediction is not labelled good or scores below trigger_score.
enum class ParticleTrigger { kAlways, kQualityDrop };
const std::map<std::string, ParticleTrigger>& ParticleTriggerNames();  // "always", "quality_drop"

struct ParticleOptions {
  // Centre of the hypotheses: kPrevious, kConstantVelocity or kKalman (not kParticle).
  PredictionModel base = PredictionModel::kConstantVelocity;
  ParticleTrigger trigger = ParticleTrigger::kQualityDrop;
  double trigger_score = 0.75;  // kQualityDrop: a good fit scoring below this triggers too
  // Hypotheses per triggered frame besides the base fit (bounded cost: each runs at most
  // hypothesis_iterations EM iterations, the best is then refined by a whole tracking fit):
  // the previous pose (zero velocity); the prediction moved on by s times the predicted step
  // (previous -> prediction) for every s of step_scales (-2: the motion reverses, 1: twice the
  // step, e.g. a dropped frame); then `hypotheses` random per-limb perturbations of the
  // prediction.
  std::vector<double> step_scales = {-2.0, 1.0};
  int hypotheses = 4;
  int hypothesis_iterations = 3;
  // The refined best hypothesis replaces the base fit only when its quality score is higher
  // by more than this (scores of near-equal fits differ by noise; switching on noise picks
  // plausible wrong limbs).
  double accept_margin = 0.02;
  // Per-limb perturbation: random hypothesis k rotates the root joint of limb k mod L by a
  // tangent vector with limb_rotation_std per component (rad), the limb's other joints with
  // child_rotation_factor times that. Limbs: the last max_limb_joints joints of every joint
  // chain ending in a leaf, not reaching past a branching joint or the root (arms, legs, neck
  // + head of the default skeleton).
  double limb_rotation_std = 0.5;
  double child_rotation_factor = 0.5;
  int max_limb_joints = 3;
  double translation_std = 0.02;      // m, global translation perturbation of every hypothesis
  double global_rotation_std = 0.05;  // rad, global rotation perturbation of every hypothesis
  uint64_t seed = 1;                  // hypotheses of frame f come from (seed, f)

  bool IsValid(std::string* error) const;
};

struct PredictionOptions {
  PredictionModel model = PredictionModel::kConstantVelocity;
  KalmanOptions kalman;      // kKalman, and kParticle with base kKalman
  ParticleOptions particle;  // kParticle
  // The temporal prior (tikhonov.temporal) pulls towards the prediction instead of the
  // previous pose.
  bool temporal_prior_on_prediction = false;

  bool IsValid(std::string* error) const;
};

class PosePredictor {
 public:
  // The predictor of options.model (of options.particle.base for kParticle). Throws
  // artex::Error on invalid options.
  static std::unique_ptr<PosePredictor> Create(const PredictionOptions& options);
  virtual ~PosePredictor() = default;
  virtual std::string name() const = 0;
  virtual void Reset() = 0;
  // An accepted pose; information: the frame's data-term information (P x P) or empty.
  virtual void Observe(const Pose& pose, const Eigen::MatrixXd& information) = 0;
  // A frame without a measurement whose previous pose `kept` was kept.
  virtual void ObserveMissing(const Pose& kept) = 0;
  // The next frame's pose; requires at least one observation.
  virtual Pose Predict() const = 0;
  // An independent copy in the same state.
  virtual std::unique_ptr<PosePredictor> Clone() const = 0;
};

}  // namespace artex
