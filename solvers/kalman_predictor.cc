#include "solvers/kalman_predictor.h"

#include <Eigen/Cholesky>
#include <cmath>
#include <sstream>

#include "models/error.h"

namespace artex {

namespace {

// Positive and finite in every group.
bool Positive(const PoseGroupWeights& w) {
  for (double v : {w.scale, w.translation, w.rotation, w.joints}) {
    if (!(std::isfinite(v) && v > 0.0)) return false;
  }
  return true;
}

}  // namespace

bool KalmanOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  std::string inner;
  if (!process_noise.IsValid(&inner)) {
    msg << "process_noise." << inner;
  } else if (!Positive(measurement_noise)) {
    msg << "measurement_noise: expected finite values > 0 in every group";
  } else if (!Positive(initial_velocity_std) || !Positive(initial_acceleration_std)) {
    msg << "initial_velocity_std/initial_acceleration_std: expected finite values > 0";
  } else if (!(std::isfinite(information_scale) && information_scale >= 0.0)) {
    msg << "information_scale: expected a finite value >= 0, found " << information_scale;
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

KalmanPosePredictor::KalmanPosePredictor(const KalmanOptions& options) : options_(options) {
  std::string error;
  if (!options.IsValid(&error)) throw Error("kalman options: " + error);
}

void KalmanPosePredictor::Reset() { initialized_ = false; }

void KalmanPosePredictor::TimeUpdate() {
  Eigen::VectorXd step = velocity_;
  if (options_.acceleration) step += 0.5 * acceleration_;
  mean_.Retract(step);
  if (options_.acceleration) velocity_ += acceleration_;
  covariance_ = transition_ * covariance_ * transition_.transpose() + process_;
  covariance_ = 0.5 * (covariance_ + covariance_.transpose()).eval();
}

void KalmanPosePredictor::Skip() {
  if (initialized_) TimeUpdate();
}

void KalmanPosePredictor::Observe(const Pose& pose, const Eigen::MatrixXd& information) {
  const int p = pose.num_parameters();
  if (information.size() != 0 && (information.rows() != p || information.cols() != p)) {
    std::ostringstream msg;
    msg << "kalman measurement information: expected " << p << " x " << p << ", found "
        << information.rows() << " x " << information.cols();
    throw Error(msg.str());
  }
  const int k = order();
  const int n = k * p;
  const int joints = pose.num_joints();
  const Eigen::VectorXd noise = options_.measurement_noise.Expand(joints);
  Eigen::MatrixXd measurement_information = noise.array().square().inverse().matrix().asDiagonal();
  if (information.size() != 0 && options_.information_scale > 0.0) {
    measurement_information +=
        options_.information_scale * 0.5 * (information + information.transpose());
  }
  const Eigen::LDLT<Eigen::MatrixXd> info_ldlt(measurement_information);
  const Eigen::MatrixXd r = info_ldlt.solve(Eigen::MatrixXd::Identity(p, p));

  if (!initialized_ || mean_.num_parameters() != p) {
    if (initialized_) {
      std::ostringstream msg;
      msg << "kalman measurement: expected " << mean_.num_joints() << " joints, found " << joints;
      throw Error(msg.str());
    }
    mean_ = pose;
    velocity_ = Eigen::VectorXd::Zero(p);
    acceleration_ = Eigen::VectorXd::Zero(p);
    covariance_ = Eigen::MatrixXd::Zero(n, n);
    covariance_.topLeftCorner(p, p) = r;
    const Eigen::VectorXd v0 = options_.initial_velocity_std.Expand(joints);
    covariance_.block(p, p, p, p) = v0.array().square().matrix().asDiagonal();
    if (k == 3) {
      const Eigen::VectorXd a0 = options_.initial_acceleration_std.Expand(joints);
      covariance_.block(2 * p, 2 * p, p, p) = a0.array().square().matrix().asDiagonal();
    }
    // F (integrator chain over one frame) and Q (white noise on the highest derivative).
    const Eigen::VectorXd q2 = options_.process_noise.Expand(joints).array().square();
    Eigen::MatrixXd f1(k, k), q1(k, k);
    if (k == 2) {
      f1 << 1, 1, 0, 1;
      q1 << 1.0 / 3, 1.0 / 2, 1.0 / 2, 1;
    } else {
      f1 << 1, 1, 0.5, 0, 1, 1, 0, 0, 1;
      q1 << 1.0 / 20, 1.0 / 8, 1.0 / 6, 1.0 / 8, 1.0 / 3, 1.0 / 2, 1.0 / 6, 1.0 / 2, 1;
    }
    transition_ = Eigen::MatrixXd::Zero(n, n);
    process_ = Eigen::MatrixXd::Zero(n, n);
    for (int a = 0; a < k; ++a) {
      for (int b = 0; b < k; ++b) {
        for (int i = 0; i < p; ++i) {
          transition_(a * p + i, b * p + i) = f1(a, b);
          process_(a * p + i, b * p + i) = q1(a, b) * q2[i];
        }
      }
    }
    initialized_ = true;
    return;
  }

  TimeUpdate();
  // Measurement update, H = [I 0 (0)]: innovation in the tangent at the prediction.
  const Eigen::VectorXd innovation = mean_.LocalCoordinates(pose);
  const Eigen::MatrixXd s = covariance_.topLeftCorner(p, p) + r;
  const Eigen::LDLT<Eigen::MatrixXd> s_ldlt(0.5 * (s + s.transpose()));
  // K = Sigma[:, x] S^-1 (n x p).
  const Eigen::MatrixXd gain = s_ldlt.solve(covariance_.leftCols(p).transpose()).transpose();
  const Eigen::VectorXd correction = gain * innovation;
  mean_.Retract(correction.head(p));
  velocity_ += correction.segment(p, p);
  if (k == 3) acceleration_ += correction.segment(2 * p, p);
  covariance_ -= gain * covariance_.topRows(p);
  covariance_ = 0.5 * (covariance_ + covariance_.transpose()).eval();
}

Pose KalmanPosePredictor::Predict() const {
  if (!initialized_) return mean_;
  Eigen::VectorXd step = velocity_;
  if (options_.acceleration) step += 0.5 * acceleration_;
  return mean_.Retracted(step);
}

}  // namespace artex
