// Multi-hypothesis prediction on the stick template: a motion that reverses (the arm swings
// out over two frames and back in the third) makes the constant-velocity guess overshoot by
// twice the step, a deliberately wrong initial guess that EM alone does not escape; the
// particle stage (hypotheses ranked by fit quality) recovers the pose. Also: the limbs of the
// default skeleton, seeded hypotheses, the EM fitter's information matrix and the config
// mapping of the prediction options.
#include "solvers/particle_predictor.h"

#include <gtest/gtest.h>

#include <random>

#include "models/error.h"
#include "models/template_generator.h"
#include "solvers/em_fitter.h"
#include "tests/solvers/fitting_test_util.h"

namespace artex {
namespace {

using testing_util::MeanVertexError;

constexpr int kShoulder = 4;  // r_shoulder of the stick template

class ParticlePredictorTest : public ::testing::Test {
 protected:
  ParticlePredictorTest() : model_(testing_util::MakeStickTemplate()), skinning_(model_) {
    camera_.world_to_camera =
        PinholeCamera::LookAt(eye_, Eigen::Vector3d(0, 0.9, 0), Eigen::Vector3d::UnitY());
    // The arm swings forward about the shoulder's x axis by `step` per frame, then back.
    for (double angle : {0.0, kStep, 0.0}) {
      Pose p = Pose::Identity(model_.num_joints());
      p.translation = Eigen::Vector3d(0.0, 0.0, 0.0);
      p.joint_rotations[kShoulder] = ExpSO3(Eigen::Vector3d(-angle, 0.0, 0.0));
      truth_.push_back(p);
      Eigen::MatrixX3d posed;
      skinning_.Apply(p, &posed);
      scans_.push_back(
          testing_util::SampleScan(posed, model_.triangles, eye_, 6000.0, 0.002, &rng_));
    }
  }

  EMFitterOptions Options(PredictionModel model) const {
    EMFitterOptions o;
    o.icp_first_frame = false;
    o.scale_mode = ScaleMode::kFixed;
    o.prediction.model = model;
    o.prediction.particle.trigger = ParticleTrigger::kAlways;
    return o;
  }

  // Frames 0 and 1 accepted at the truth, frame 2 fitted by TrackFrame; returns its error (m).
  double ThirdFrameError(const EMFitterOptions& options, ParticleFrameReport* report,
                         Pose* guess = nullptr) {
    EMFitter fitter(model_, options);
    fitter.AcceptPose(scans_[0], truth_[0]);
    fitter.AcceptPose(scans_[1], truth_[1]);
    if (guess) *guess = fitter.PredictNextPose();
    const FitSummary s = TrackFrame(&fitter, scans_[2], camera_, FitQualityOptions(), report);
    EXPECT_TRUE(s.ok()) << s.BriefReport();
    return MeanVertexError(skinning_, fitter.pose(), truth_[2]);
  }

  static constexpr double kStep = 0.45;  // rad per frame: the guess is 0.9 rad off
  Template model_;
  Skinning skinning_;
  std::mt19937_64 rng_{5};
  Eigen::Vector3d eye_{0.0, 1.2, 3.0};
  PinholeCamera camera_;
  std::vector<Pose> truth_;
  std::vector<Scan> scans_;
};

TEST_F(ParticlePredictorTest, RecoversFromAnOvershootingGuessThatEmAloneKeeps) {
  ParticleFrameReport plain_report, particle_report;
  Pose guess;
  const double plain =
      ThirdFrameError(Options(PredictionModel::kConstantVelocity), &plain_report, &guess);
  const double particle = ThirdFrameError(Options(PredictionModel::kParticle), &particle_report);
  const double guess_error = MeanVertexError(skinning_, guess, truth_[2]);
  RecordProperty("em_alone_error_mm", std::to_string(plain * 1e3));
  RecordProperty("particle_error_mm", std::to_string(particle * 1e3));
  EXPECT_GT(guess_error, 0.03);  // the constant-velocity guess is far off
  EXPECT_GT(plain, 0.015) << "EM alone escaped the wrong guess: the test proves nothing";
  EXPECT_FALSE(plain_report.triggered);
  EXPECT_LT(particle, 0.006);
  EXPECT_TRUE(particle_report.triggered);
  EXPECT_GE(particle_report.chosen, 0);  // a hypothesis, not the base fit, won
  EXPECT_GT(particle_report.chosen_score, particle_report.base_score);
  // Bounded cost: base fit + (1 + step scales + random) short fits + one refinement.
  const ParticleOptions o;
  const int hypotheses = 1 + static_cast<int>(o.step_scales.size()) + o.hypotheses;
  EXPECT_EQ(particle_report.hypotheses, hypotheses);
  EXPECT_LE(particle_report.em_iterations,
            2 * EMFitterOptions().max_iterations + hypotheses * o.hypothesis_iterations);
}

TEST_F(ParticlePredictorTest, QualityDropTriggerSkipsGoodFits) {
  // A frame the base prediction fits well is accepted without hypotheses.
  EMFitterOptions o = Options(PredictionModel::kParticle);
  o.prediction.particle.trigger = ParticleTrigger::kQualityDrop;
  o.prediction.particle.trigger_score = 0.0;
  EMFitter fitter(model_, o);
  fitter.AcceptPose(scans_[0], truth_[0]);
  // Labels: every fit passing the robustness checks is good on this small scene.
  FitQualityOptions quality;
  quality.good_min_inlier_fraction = quality.good_min_support_fraction = 0.0;
  quality.lost_min_inlier_fraction = quality.lost_min_support_fraction = 0.0;
  quality.good_max_depth_residual = quality.lost_max_depth_residual = 1.0;
  ParticleFrameReport report;
  const FitSummary s = TrackFrame(&fitter, scans_[0], camera_, quality, &report);
  EXPECT_TRUE(s.ok());
  EXPECT_FALSE(report.triggered) << report.base_score;
  EXPECT_EQ(fitter.frames_fitted(), 2);
}

TEST(ParticleHypothesesTest, DefaultSkeletonLimbsAndSeededHypotheses) {
  const Template t = GenerateTemplate();
  const std::vector<std::vector<int>> limbs = TemplateLimbs(t, 3);
  std::vector<std::string> roots;
  for (const auto& limb : limbs) roots.push_back(t.joints[limb[0]].name);
  std::sort(roots.begin(), roots.end());
  EXPECT_EQ(roots,
            (std::vector<std::string>{"l_hip", "l_shoulder", "neck", "r_hip", "r_shoulder"}));
  ParticleOptions o;
  Pose previous = Pose::Identity(t.num_joints()), centre = previous;
  centre.translation.x() = 0.1;
  const auto a = ParticleHypotheses(previous, centre, limbs, o, 7);
  const auto b = ParticleHypotheses(previous, centre, limbs, o, 7);
  const auto c = ParticleHypotheses(previous, centre, limbs, o, 8);
  ASSERT_EQ(a.size(), 1 + o.step_scales.size() + o.hypotheses);
  EXPECT_NEAR(a[1].translation.x(), 0.1 - 2 * 0.1, 1e-12);  // step scale -2
  EXPECT_NEAR(a[2].translation.x(), 0.2, 1e-12);            // step scale 1
  for (size_t k = 0; k < a.size(); ++k) EXPECT_EQ(a[k].ToVector(), b[k].ToVector());
  EXPECT_NE(a.back().ToVector(), c.back().ToVector());
  // A random hypothesis moves one limb only.
  const Eigen::VectorXd d = centre.LocalCoordinates(a[3]);
  int moved = 0;
  for (int j = 0; j < t.num_joints(); ++j) moved += d.segment<3>(JointParameterIndex(j)).norm() > 0;
  EXPECT_EQ(moved, static_cast<int>(limbs[0].size()));
}

TEST_F(ParticlePredictorTest, FitterExposesTheDataTermInformation) {
  EMFitter fitter(model_, Options(PredictionModel::kKalman));
  fitter.SetInitialPose(truth_[0]);
  fitter.FitFrame(scans_[0]);
  const Eigen::MatrixXd& h = fitter.frame_information();
  const int p = truth_[0].num_parameters();
  ASSERT_EQ(h.rows(), p);
  ASSERT_EQ(h.cols(), p);
  EXPECT_TRUE(h.allFinite());
  EXPECT_LT((h - h.transpose()).norm(), 1e-9 * h.norm());
  // Translation is well observed; twist about the forearm (elbow's twist axis) much less than
  // its swing.
  const int elbow = JointParameterIndex(5);
  const Eigen::Vector3d twist = model_.joints[5].twist_axis;
  const Eigen::Vector3d swing = twist.unitOrthogonal();
  const double twist_info = twist.dot(h.block<3, 3>(elbow, elbow) * twist);
  const double swing_info = swing.dot(h.block<3, 3>(elbow, elbow) * swing);
  EXPECT_LT(twist_info, 0.5 * swing_info);
  EXPECT_GT(h(kTranslationIndex, kTranslationIndex), swing_info);
}

}  // namespace
}  // namespace artex
