// The Kalman pose predictor on synthetic trajectories with a known optimum: a constant-
// acceleration trajectory (every rotation about a fixed axis, so the tangent increments add
// exactly) is predicted exactly by the acceleration model and with a lag by constant velocity;
// with noisy measurements and no process noise the filter's prediction equals the batch
// weighted least-squares quadratic fit (with the same prior on velocity and acceleration); the
// measurement information steers how far the filter follows each direction.
#include "solvers/kalman_predictor.h"

#include <gtest/gtest.h>

#include <Eigen/Cholesky>
#include <random>

#include "models/error.h"
#include "solvers/prediction.h"

namespace artex {
namespace {

constexpr int kJoints = 5;

// Tangent offset of frame f from the base pose: c(f) = v0 f + a0 f^2 / 2, every rotation block
// along its own fixed axis.
struct Trajectory {
  Pose base = Pose::Identity(kJoints);
  Eigen::VectorXd v0, a0;
  Trajectory() {
    std::mt19937_64 rng(7);
    std::normal_distribution<double> g(0.0, 1.0);
    const int p = base.num_parameters();
    v0.resize(p);
    a0.resize(p);
    base.translation = Eigen::Vector3d(0.1, 0.9, 2.0);
    for (int block = 0; block < (p - 1) / 3; ++block) {
      const int i = 1 + 3 * block;
      Eigen::Vector3d axis(g(rng), g(rng), g(rng));
      axis.normalize();
      if (block == 0) {  // translation (m)
        v0.segment<3>(i) = 0.01 * Eigen::Vector3d(g(rng), g(rng), g(rng));
        a0.segment<3>(i) = 0.002 * Eigen::Vector3d(g(rng), g(rng), g(rng));
      } else {  // a rotation (rad) about its own fixed axis
        v0.segment<3>(i) = 0.005 * g(rng) * axis;
        a0.segment<3>(i) = 0.0003 * g(rng) * axis;
      }
    }
    v0[kScaleIndex] = 0.0;
    a0[kScaleIndex] = 0.0;
  }
  Eigen::VectorXd Offset(int f) const { return f * v0 + 0.5 * f * f * a0; }
  Pose At(int f) const { return base.Retracted(Offset(f)); }
};

double TangentError(const Pose& a, const Pose& b) { return a.LocalCoordinates(b).norm(); }

TEST(KalmanPredictorTest, ConstantAccelerationModelPredictsAConstantAccelerationExactly) {
  const Trajectory t;
  KalmanOptions ca;
  ca.acceleration = true;
  KalmanPosePredictor kalman_ca(ca);
  KalmanPosePredictor kalman_cv{KalmanOptions()};
  PredictionOptions cv_options;
  cv_options.model = PredictionModel::kConstantVelocity;
  const auto cv = PosePredictor::Create(cv_options);
  const int frames = 40;
  double ca_error = 0.0, kalman_cv_error = 0.0, cv_error = 0.0;
  for (int f = 0; f < frames; ++f) {
    const Pose z = t.At(f);
    kalman_ca.Observe(z, Eigen::MatrixXd());
    kalman_cv.Observe(z, Eigen::MatrixXd());
    cv->Observe(z, Eigen::MatrixXd());
    if (f == frames - 1) {
      const Pose next = t.At(f + 1);
      ca_error = TangentError(kalman_ca.Predict(), next);
      kalman_cv_error = TangentError(kalman_cv.Predict(), next);
      cv_error = TangentError(cv->Predict(), next);
    }
  }
  // Constant velocity misses by exactly the acceleration (one frame's second difference).
  EXPECT_NEAR(cv_error, t.a0.norm(), 1e-9);
  // The acceleration model has no steady-state error on a quadratic (noise-free data).
  EXPECT_LT(ca_error, 1e-3 * cv_error) << ca_error;
  // The velocity-only Kalman filter lags behind an acceleration.
  EXPECT_GT(kalman_cv_error, 0.1 * cv_error);
  EXPECT_NEAR(kalman_ca.acceleration().norm(), t.a0.norm(), 1e-2 * t.a0.norm());
}

TEST(KalmanPredictorTest, NoisyMeasurementsWithoutProcessNoiseGiveTheLeastSquaresFit) {
  // Zero process noise: x_f = x0 + v0 f + a0 f^2 / 2 exactly, so the filter is the recursive
  // form of the batch problem min sum_f |z_f - x_f|^2 / s^2 + |v0|^2 / sv^2 + |a0|^2 / sa^2.
  const Trajectory t;
  KalmanOptions o;
  o.acceleration = true;
  o.process_noise = {0.0, 0.0, 0.0, 0.0};
  o.information_scale = 0.0;
  const double s = 0.01, sv = 0.05, sa = 0.01;
  o.measurement_noise = {s, s, s, s};
  o.initial_velocity_std = {sv, sv, sv, sv};
  o.initial_acceleration_std = {sa, sa, sa, sa};
  KalmanPosePredictor kalman(o);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> g(0.0, s);
  const int frames = 25;
  std::vector<Eigen::Vector3d> measured;
  for (int f = 0; f < frames; ++f) {
    Pose z = t.At(f);
    z.translation += Eigen::Vector3d(g(rng), g(rng), g(rng));
    measured.push_back(z.translation);
    kalman.Observe(z, Eigen::MatrixXd());
  }
  // Batch solution per translation axis (the translation is Euclidean).
  for (int axis = 0; axis < 3; ++axis) {
    Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
    Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
    for (int f = 0; f < frames; ++f) {
      const Eigen::Vector3d row(1.0, f, 0.5 * f * f);
      normal += row * row.transpose() / (s * s);
      rhs += row * measured[f][axis] / (s * s);
    }
    normal(1, 1) += 1.0 / (sv * sv);
    normal(2, 2) += 1.0 / (sa * sa);
    const Eigen::Vector3d theta = normal.ldlt().solve(rhs);
    const double n = frames;
    const double optimum = theta[0] + theta[1] * n + 0.5 * theta[2] * n * n;
    EXPECT_NEAR(kalman.Predict().translation[axis], optimum, 1e-8) << "axis " << axis;
  }
}

TEST(KalmanPredictorTest, InformationDecidesHowFarEachDirectionFollows) {
  // Two directions jump by the same amount; the well-observed one (large information) is
  // followed, the unobserved one (no information: measurement_noise) is smoothed.
  KalmanOptions o;
  o.information_scale = 1.0;
  o.process_noise.joints = 0.005;  // steady-state gain ~0.36 at measurement_noise 0.05
  KalmanPosePredictor kalman(o);
  Pose pose = Pose::Identity(kJoints);
  const int p = pose.num_parameters();
  const int observed = JointParameterIndex(0), unobserved = JointParameterIndex(1);
  Eigen::MatrixXd information = Eigen::MatrixXd::Zero(p, p);
  information(observed, observed) = 1e8;
  for (int f = 0; f < 30; ++f) kalman.Observe(pose, information);
  Eigen::VectorXd jump = Eigen::VectorXd::Zero(p);
  jump[observed] = jump[unobserved] = 0.2;
  kalman.Observe(pose.Retracted(jump), information);
  const Eigen::VectorXd moved = pose.LocalCoordinates(kalman.mean());
  EXPECT_GT(moved[observed], 0.19);
  EXPECT_LT(moved[unobserved], 0.5 * moved[observed]);
  EXPECT_GT(moved[unobserved], 0.0);
}

TEST(KalmanPredictorTest, InvalidInputsThrow) {
  KalmanOptions bad;
  bad.measurement_noise.joints = 0.0;
  EXPECT_THROW(KalmanPosePredictor{bad}, Error);
  KalmanPosePredictor kalman{KalmanOptions()};
  kalman.Observe(Pose::Identity(kJoints), Eigen::MatrixXd());
  EXPECT_THROW(kalman.Observe(Pose::Identity(kJoints), Eigen::MatrixXd::Zero(3, 3)), Error);
  EXPECT_THROW(kalman.Observe(Pose::Identity(kJoints + 1), Eigen::MatrixXd()), Error);
  PredictionOptions particle;
  particle.model = PredictionModel::kParticle;
  particle.particle.base = PredictionModel::kParticle;
  EXPECT_THROW(PosePredictor::Create(particle), Error);
}

}  // namespace
}  // namespace artex
