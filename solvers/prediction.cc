#include "solvers/prediction.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <vector>

#include "energies/pose_smoothness_term.h"
#include "models/error.h"

namespace artex {

namespace {

class PreviousPredictor : public PosePredictor {
 public:
  std::string name() const override { return "previous"; }
  std::unique_ptr<PosePredictor> Clone() const override {
    return std::make_unique<PreviousPredictor>(*this);
  }
  void Reset() override { has_last_ = false; }
  void Observe(const Pose& pose, const Eigen::MatrixXd&) override {
    last_ = pose;
    has_last_ = true;
  }
  void ObserveMissing(const Pose& kept) override { Observe(kept, Eigen::MatrixXd()); }
  Pose Predict() const override {
    if (!has_last_) throw Error("pose prediction: no pose observed yet");
    return last_;
  }

 private:
  Pose last_;
  bool has_last_ = false;
};

// The fitter's historical prediction: previous (+) (tangent step between the last two).
class ConstantVelocityPredictor : public PosePredictor {
 public:
  std::string name() const override { return "constant_velocity"; }
  std::unique_ptr<PosePredictor> Clone() const override {
    return std::make_unique<ConstantVelocityPredictor>(*this);
  }
  void Reset() override { history_.clear(); }
  void Observe(const Pose& pose, const Eigen::MatrixXd&) override {
    history_.push_back(pose);
    if (history_.size() > 2) history_.erase(history_.begin());
  }
  void ObserveMissing(const Pose& kept) override { Observe(kept, Eigen::MatrixXd()); }
  Pose Predict() const override {
    if (history_.empty()) throw Error("pose prediction: no pose observed yet");
    if (history_.size() < 2) return history_.back();
    return ConstantVelocityPrediction(history_[0], history_[1]);
  }

 private:
  std::vector<Pose> history_;  // the last two observed poses
};

class KalmanPredictor : public PosePredictor {
 public:
  explicit KalmanPredictor(const KalmanOptions& options) : filter_(options) {}
  std::string name() const override { return "kalman"; }
  std::unique_ptr<PosePredictor> Clone() const override {
    return std::make_unique<KalmanPredictor>(*this);
  }
  void Reset() override { filter_.Reset(); }
  void Observe(const Pose& pose, const Eigen::MatrixXd& information) override {
    filter_.Observe(pose, information);
  }
  void ObserveMissing(const Pose& kept) override {
    if (filter_.initialized()) {
      filter_.Skip();
    } else {
      filter_.Observe(kept, Eigen::MatrixXd());
    }
  }
  Pose Predict() const override {
    if (!filter_.initialized()) throw Error("pose prediction: no pose observed yet");
    return filter_.Predict();
  }

 private:
  KalmanPosePredictor filter_;
};

}  // namespace

const std::map<std::string, PredictionModel>& PredictionModelNames() {
  static const std::map<std::string, PredictionModel> kNames = {
      {"previous", PredictionModel::kPrevious},
      {"constant_velocity", PredictionModel::kConstantVelocity},
      {"kalman", PredictionModel::kKalman},
      {"particle", PredictionModel::kParticle}};
  return kNames;
}

const char* PredictionModelName(PredictionModel model) {
  switch (model) {
    case PredictionModel::kPrevious:
      return "previous";
    case PredictionModel::kConstantVelocity:
      return "constant_velocity";
    case PredictionModel::kKalman:
      return "kalman";
    case PredictionModel::kParticle:
      return "particle";
  }
  return "unknown";
}

const std::map<std::string, ParticleTrigger>& ParticleTriggerNames() {
  static const std::map<std::string, ParticleTrigger> kNames = {
      {"always", ParticleTrigger::kAlways}, {"quality_drop", ParticleTrigger::kQualityDrop}};
  return kNames;
}

bool ParticleOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (base == PredictionModel::kParticle) {
    msg << "base: expected previous, constant_velocity or kalman, found particle";
  } else if (!(trigger_score >= 0.0 && trigger_score <= 1.0)) {
    msg << "trigger_score: expected a value in [0, 1], found " << trigger_score;
  } else if (std::any_of(step_scales.begin(), step_scales.end(),
                         [](double x) { return !std::isfinite(x); })) {
    msg << "step_scales: expected finite values";
  } else if (!(accept_margin >= 0.0 && accept_margin <= 1.0)) {
    msg << "accept_margin: expected a value in [0, 1], found " << accept_margin;
  } else if (hypotheses < 0) {
    msg << "hypotheses: expected >= 0, found " << hypotheses;
  } else if (hypothesis_iterations < 1) {
    msg << "hypothesis_iterations: expected >= 1, found " << hypothesis_iterations;
  } else if (max_limb_joints < 1) {
    msg << "max_limb_joints: expected >= 1, found " << max_limb_joints;
  } else if (!(std::isfinite(child_rotation_factor) && child_rotation_factor >= 0.0)) {
    msg << "child_rotation_factor: expected a finite value >= 0, found " << child_rotation_factor;
  } else if (!(std::isfinite(limb_rotation_std) && limb_rotation_std >= 0.0) ||
             !(std::isfinite(translation_std) && translation_std >= 0.0) ||
             !(std::isfinite(global_rotation_std) && global_rotation_std >= 0.0)) {
    msg << "limb_rotation_std/translation_std/global_rotation_std: expected finite values >= 0";
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

bool PredictionOptions::IsValid(std::string* error) const {
  std::string inner;
  if (!kalman.IsValid(&inner)) {
    if (error) *error = "kalman." + inner;
    return false;
  }
  if (!particle.IsValid(&inner)) {
    if (error) *error = "particle." + inner;
    return false;
  }
  return true;
}

std::unique_ptr<PosePredictor> PosePredictor::Create(const PredictionOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw Error("prediction options: " + error);
  const PredictionModel model =
      options.model == PredictionModel::kParticle ? options.particle.base : options.model;
  switch (model) {
    case PredictionModel::kPrevious:
      return std::make_unique<PreviousPredictor>();
    case PredictionModel::kKalman:
      return std::make_unique<KalmanPredictor>(options.kalman);
    case PredictionModel::kConstantVelocity:
    case PredictionModel::kParticle:
      break;
  }
  return std::make_unique<ConstantVelocityPredictor>();
}

}  // namespace artex
