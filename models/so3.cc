#include "models/so3.h"

#include <cmath>

#include <Eigen/SVD>

namespace artex {

Eigen::Matrix3d Skew(const Eigen::Vector3d& w) {
  Eigen::Matrix3d s;
  s << 0.0, -w.z(), w.y(), w.z(), 0.0, -w.x(), -w.y(), w.x(), 0.0;
  return s;
}

Eigen::Matrix3d ExpSO3(const Eigen::Vector3d& w) {
  const double theta2 = w.squaredNorm();
  const Eigen::Matrix3d k = Skew(w);
  double a, b;
  if (theta2 < 1e-16) {
    a = 1.0 - theta2 / 6.0;
    b = 0.5 - theta2 / 24.0;
  } else {
    const double theta = std::sqrt(theta2);
    a = std::sin(theta) / theta;
    b = (1.0 - std::cos(theta)) / theta2;
  }
  return Eigen::Matrix3d::Identity() + a * k + b * k * k;
}

Eigen::Vector3d LogSO3(const Eigen::Matrix3d& r) {
  const Eigen::AngleAxisd aa(Eigen::Quaterniond(r).normalized());
  double angle = aa.angle();
  Eigen::Vector3d axis = aa.axis();
  if (angle > M_PI) {
    angle = 2.0 * M_PI - angle;
    axis = -axis;
  }
  return axis * angle;
}

SwingTwist DecomposeSwingTwist(const Eigen::Matrix3d& r, const Eigen::Vector3d& axis) {
  const Eigen::Quaterniond q = Eigen::Quaterniond(r).normalized();
  const Eigen::Vector3d a = axis.normalized();
  const double p = q.vec().dot(a);
  SwingTwist st;
  const double n = std::sqrt(p * p + q.w() * q.w());
  if (n < 1e-12) {
    st.twist.setIdentity();
    st.swing = r;
    st.twist_angle = 0.0;
    return st;
  }
  Eigen::Quaterniond twist(q.w() / n, a.x() * p / n, a.y() * p / n, a.z() * p / n);
  if (twist.w() < 0.0) twist.coeffs() = -twist.coeffs();
  st.twist_angle = 2.0 * std::atan2(twist.vec().dot(a), twist.w());
  st.twist = twist.toRotationMatrix();
  st.swing = (q * twist.conjugate()).toRotationMatrix();
  return st;
}

Eigen::Matrix3d ProjectToRotation(const Eigen::Matrix3d& m) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * d * svd.matrixV().transpose();
}

}  // namespace artex
