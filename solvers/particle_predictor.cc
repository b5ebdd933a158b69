#include "solvers/particle_predictor.h"

#include <algorithm>
#include <chrono>
#include <random>

#include "models/numeric.h"
#include "models/so3.h"

namespace artex {

namespace {

using Clock = std::chrono::steady_clock;
// One fit of the frame from `guess` (FitCandidate: at most max_iterations EM iterations, 0: the
// whole tracking schedule), discarded from the fitter: the fitted pose, its data-term
// information and its quality (of a fit that passed the robustness checks).
struct Candidate {
  int index = -1;  // hypothesis index, -1: the base fit
  FitSummary fit;
  Pose pose;
  Eigen::MatrixXd information;
  FitQuality quality;
};

Candidate FitCandidate(EMFitter* fitter, const Scan& scan, const Pose& guess, int max_iterations,
                       const PinholeCamera& camera, const FitQualityOptions& quality) {
  Candidate c;
  fitter->BeginFrame(scan, guess);
  int iterations = 0;
  while (!fitter->frame_done() && (max_iterations <= 0 || iterations < max_iterations)) {
    fitter->Iterate();
    ++iterations;
  }
  c.fit = fitter->DiscardFrame(&c.pose);
  c.information = fitter->frame_information();
  if (c.fit.ok()) {
    Eigen::MatrixX3d posed;
    fitter->skinning().Apply(c.pose, &posed);
    c.quality =
        EvaluateFitQuality(posed, fitter->skinning().model().triangles, scan, camera, quality);
  }
  return c;
}

Eigen::Vector3d Gaussian3(std::mt19937_64* rng, double sigma) {
  std::normal_distribution<double> n(0.0, 1.0);
  const double x = n(*rng), y = n(*rng), z = n(*rng);
  return sigma * Eigen::Vector3d(x, y, z);
}

}  // namespace

std::vector<std::vector<int>> TemplateLimbs(const Template& tmpl, int max_joints) {
  const int n = tmpl.num_joints();
  std::vector<int> children(n, 0);
  for (int j = 0; j < n; ++j) {
    if (tmpl.joints[j].parent >= 0) ++children[tmpl.joints[j].parent];
  }
  std::vector<std::vector<int>> limbs;
  for (int leaf = 0; leaf < n; ++leaf) {
    if (children[leaf] != 0 || tmpl.joints[leaf].parent < 0) continue;
    std::vector<int> limb = {leaf};
    int j = leaf;
    while (static_cast<int>(limb.size()) < max_joints) {
      const int parent = tmpl.joints[j].parent;
      if (parent < 0 || tmpl.joints[parent].parent < 0 || children[parent] != 1) break;
      limb.push_back(parent);
      j = parent;
    }
    std::reverse(limb.begin(), limb.end());
    limbs.push_back(std::move(limb));
  }
  return limbs;
}

std::vector<Pose> ParticleHypotheses(const Pose& previous, const Pose& centre,
                                     const std::vector<std::vector<int>>& limbs,
                                     const ParticleOptions& options, int frame) {
  std::vector<Pose> hypotheses = {previous};
  const Eigen::VectorXd step = previous.LocalCoordinates(centre);
  for (double s : options.step_scales) hypotheses.push_back(centre.Retracted(s * step));
  for (int k = 0; k < options.hypotheses; ++k) {
    std::seed_seq seq{static_cast<uint32_t>(options.seed),
                      static_cast<uint32_t>(options.seed >> 32), static_cast<uint32_t>(frame),
                      static_cast<uint32_t>(k)};
    std::mt19937_64 rng(seq);
    Pose h = centre;
    h.translation += Gaussian3(&rng, options.translation_std);
    h.rotation = ExpSO3(Gaussian3(&rng, options.global_rotation_std)) * h.rotation;
    if (!limbs.empty()) {
      const std::vector<int>& limb = limbs[k % limbs.size()];
      for (size_t i = 0; i < limb.size(); ++i) {
        const double sigma =
            options.limb_rotation_std * (i == 0 ? 1.0 : options.child_rotation_factor);
        h.joint_rotations[limb[i]] = ExpSO3(Gaussian3(&rng, sigma)) * h.joint_rotations[limb[i]];
      }
    }
    hypotheses.push_back(std::move(h));
  }
  return hypotheses;
}

FitSummary TrackFrame(EMFitter* fitter, const Scan& scan, const PinholeCamera& depth_camera,
                      const FitQualityOptions& quality, ParticleFrameReport* report) {
  ParticleFrameReport local;
  ParticleFrameReport& r = report ? *report : local;
  r = ParticleFrameReport();
  const PredictionOptions& prediction = fitter->options().prediction;
  if (prediction.model != PredictionModel::kParticle || !fitter->tracking()) {
    FitSummary fit = fitter->FitFrame(scan);
    r.em_iterations = fit.iterations;
    return fit;
  }
  const auto start = Clock::now();
  const ParticleOptions& options = prediction.particle;
  const int frame = fitter->frames_fitted();
  const Pose centre = fitter->PredictNextPose();
  Candidate best = FitCandidate(fitter, scan, centre, 0, depth_camera, quality);
  int iterations = best.fit.iterations;
  r.base_score = best.fit.ok() ? best.quality.score : 0.0;
  const bool good = best.fit.ok() && best.quality.label == FitQualityLabel::kGood &&
                    best.quality.score >= options.trigger_score;
  if (options.trigger == ParticleTrigger::kAlways || !good) {
    r.triggered = true;
    const std::vector<std::vector<int>> limbs =
        TemplateLimbs(fitter->skinning().model(), options.max_limb_joints);
    // The previous pose keeps the base prediction's scale handling (PredictNextPose).
    Pose previous = fitter->pose();
    previous.scale = centre.scale;
    Candidate ranked;
    bool have_ranked = false;
    const std::vector<Pose> guesses = ParticleHypotheses(previous, centre, limbs, options, frame);
    for (int k = 0; k < static_cast<int>(guesses.size()); ++k) {
      Candidate c = FitCandidate(fitter, scan, guesses[k], options.hypothesis_iterations,
                                 depth_camera, quality);
      iterations += c.fit.iterations;
      ++r.hypotheses;
      if (c.fit.ok() && (!have_ranked || c.quality.score > ranked.quality.score)) {
        ranked = std::move(c);
        ranked.index = k;
        have_ranked = true;
      }
    }
    if (have_ranked) {
      const int index = ranked.index;
      Candidate refined = FitCandidate(fitter, scan, ranked.pose, 0, depth_camera, quality);
      iterations += refined.fit.iterations;
      if (refined.fit.ok() &&
          (!best.fit.ok() || refined.quality.score > best.quality.score + options.accept_margin)) {
        best = std::move(refined);
        r.chosen = index;
      }
    }
  }
  if (!best.fit.ok()) {
    // Nothing passed the robustness checks: record the frame as the plain fit does.
    FitSummary fit = fitter->FitFrame(scan);
    iterations += fit.iterations;
    fit.iterations = iterations;
    r.em_iterations = iterations;
    fit.total_seconds = SecondsSince(start);
    return fit;
  }
  fitter->AcceptPose(scan, best.pose, best.information);
  r.chosen_score = best.quality.score;
  r.em_iterations = iterations;
  FitSummary fit = best.fit;
  fit.frame = frame;
  fit.iterations = iterations;
  fit.scale = fitter->pose().scale;
  fit.total_seconds = SecondsSince(start);
  return fit;
}

}  // namespace artex
