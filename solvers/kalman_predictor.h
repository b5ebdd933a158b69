// Kalman filter over the pose tangent space (docs/fitting.md "Prediction"): the state is a pose
// x (on the manifold), a velocity v and optionally an acceleration a (P-vectors in the pose
// tangent layout of models/pose.h, per frame); the time update moves x <- x (+) (v + a / 2)
// with the fitter's retraction (Pose::Retracted), v <- v + a, and adds white-noise process
// covariance on the highest derivative. The measurement is an accepted EM pose z; the
// innovation is x.LocalCoordinates(z), its covariance
//   R = (information_scale * H + diag(measurement_noise)^-2)^-1,
// where H is the data term's Gauss-Newton information J^T J of the frame's last M-step
// (EMFitter::frame_information()), so directions the scan observes poorly (twist about limb
// axes) are measured with a large variance and smoothed more. Error-state (multiplicative)
// update: the correction of x is retracted, velocity and acceleration are added.
#pragma once

#include <Eigen/Core>
#include <string>

#include "energies/fitting_term.h"
#include "models/pose.h"

namespace artex {

struct KalmanOptions {
  // State order: false = position + velocity (constant velocity model), true = position +
  // velocity + acceleration (constant acceleration model).
  bool acceleration = false;
  // Process noise: standard deviation per frame of the white noise driving the highest
  // derivative (acceleration per frame^2, or jerk per frame^3 with `acceleration`), per
  // parameter group (scale units, m, rad, rad); the discrete white-noise covariance of a
  // continuous integrator chain over one frame.
  PoseGroupWeights process_noise = {1e-4, 0.01, 0.02, 0.05};
  // Measurement: R = (information_scale * H + diag(measurement_noise)^-2)^-1. information_scale
  // (1/m^2) is the number of effectively independent scan points over their residual
  // variance, H the information of the normalised data term (a weighted mean of squared
  // distances); 0 ignores H (R = diag(measurement_noise^2)).
  double information_scale = 1e6;
  // Standard deviation of an unobserved direction (scale units, m, rad, rad): the measurement
  // variance without information, the upper bound with it.
  PoseGroupWeights measurement_noise = {0.01, 0.01, 0.02, 0.05};
  // Standard deviation of the initial velocity (per frame) and acceleration (per frame^2).
  PoseGroupWeights initial_velocity_std = {1e-3, 0.02, 0.05, 0.1};
  PoseGroupWeights initial_acceleration_std = {1e-4, 0.01, 0.02, 0.05};

  bool IsValid(std::string* error) const;
};

class KalmanPosePredictor {
 public:
  // Throws artex::Error on invalid options.
  explicit KalmanPosePredictor(const KalmanOptions& options);

  void Reset();
  bool initialized() const { return initialized_; }
  // Time update to this frame, then the measurement update with `pose`; the first call
  // initialises x = pose, v = a = 0. information: P x P or empty (no information). Throws
  // artex::Error on a joint count that differs from the first pose's or a wrong-size matrix.
  void Observe(const Pose& pose, const Eigen::MatrixXd& information);
  // Time update only (a frame without measurement).
  void Skip();
  // The predicted pose of the next frame, x (+) (v + a / 2); the last pose before the first.
  Pose Predict() const;

  const Pose& mean() const { return mean_; }
  const Eigen::VectorXd& velocity() const { return velocity_; }
  const Eigen::VectorXd& acceleration() const { return acceleration_; }  // zero without
  const Eigen::MatrixXd& covariance() const { return covariance_; }      // (kP) x (kP)

 private:
  void TimeUpdate();
  int order() const { return options_.acceleration ? 3 : 2; }

  KalmanOptions options_;
  bool initialized_ = false;
  Pose mean_;
  Eigen::VectorXd velocity_, acceleration_;
  Eigen::MatrixXd covariance_;
  Eigen::MatrixXd transition_, process_;  // F and Q (kP x kP), built at initialisation
};

}  // namespace artex
