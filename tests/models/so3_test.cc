#include "models/so3.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace artex {
namespace {

constexpr double kPi = 3.14159265358979323846;

Eigen::Vector3d RandomUnit(std::mt19937_64& rng) {
  std::normal_distribution<double> normal;
  return Eigen::Vector3d(normal(rng), normal(rng), normal(rng)).normalized();
}

double Uniform(std::mt19937_64& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

void ExpectRotation(const Eigen::Matrix3d& r) {
  EXPECT_LT((r * r.transpose() - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  EXPECT_NEAR(r.determinant(), 1.0, 1e-12);
}

TEST(So3Test, SkewIsCrossProduct) {
  const Eigen::Vector3d w(0.3, -1.2, 2.5), v(-0.7, 0.1, 0.4);
  EXPECT_LT((Skew(w) * v - w.cross(v)).norm(), 1e-15);
  EXPECT_EQ((Skew(w) + Skew(w).transpose()).norm(), 0.0);
}

TEST(So3Test, ExpMatchesAngleAxis) {
  std::mt19937_64 rng(1);
  for (int i = 0; i < 100; ++i) {
    const Eigen::Vector3d axis = RandomUnit(rng);
    const double angle = Uniform(rng, -3.0, 3.0);
    const Eigen::Matrix3d r = ExpSO3(axis * angle);
    ExpectRotation(r);
    EXPECT_LT((r - Eigen::AngleAxisd(angle, axis).toRotationMatrix()).norm(), 1e-13);
  }
  EXPECT_EQ(ExpSO3(Eigen::Vector3d::Zero()), Eigen::Matrix3d::Identity());
  // Small angles: first order I + [w]x.
  const Eigen::Vector3d tiny(1e-9, -2e-9, 3e-9);
  EXPECT_LT((ExpSO3(tiny) - (Eigen::Matrix3d::Identity() + Skew(tiny))).norm(), 1e-17);
}

TEST(So3Test, ExpLogRoundTrip) {
  std::mt19937_64 rng(2);
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d axis = RandomUnit(rng);
    double angle = Uniform(rng, 0.0, kPi - 1e-6);
    if (i % 10 == 0) angle = 1e-10;
    if (i % 10 == 1) angle = kPi - 1e-6;
    if (i % 10 == 2) angle = 0.0;
    const Eigen::Vector3d w = axis * angle;
    const Eigen::Vector3d back = LogSO3(ExpSO3(w));
    EXPECT_LT((back - w).norm(), 1e-9) << "angle " << angle;
    EXPECT_LE(back.norm(), kPi + 1e-12);
    // Log(Exp(w)) is also consistent for the other direction.
    const Eigen::Matrix3d r = ExpSO3(w);
    EXPECT_LT((ExpSO3(LogSO3(r)) - r).norm(), 1e-12);
  }
  // Beyond pi the logarithm wraps to the shorter rotation.
  const Eigen::Vector3d axis(0, 0, 1);
  EXPECT_LT((LogSO3(ExpSO3(axis * (kPi + 0.5))) - (-axis * (kPi - 0.5))).norm(), 1e-12);
}

TEST(So3Test, SwingTwistRecomposes) {
  std::mt19937_64 rng(3);
  for (int i = 0; i < 200; ++i) {
    const Eigen::Vector3d axis = RandomUnit(rng);
    const Eigen::Matrix3d r = ExpSO3(RandomUnit(rng) * Uniform(rng, 0.0, 3.0));
    const SwingTwist st = DecomposeSwingTwist(r, axis);
    ExpectRotation(st.swing);
    ExpectRotation(st.twist);
    EXPECT_LT((st.swing * st.twist - r).norm(), 1e-12);
    // Twist is a rotation about the axis by twist_angle.
    EXPECT_LT((st.twist * axis - axis).norm(), 1e-12);
    EXPECT_LT((st.twist - Eigen::AngleAxisd(st.twist_angle, axis).toRotationMatrix()).norm(),
              1e-12);
    EXPECT_GT(st.twist_angle, -kPi - 1e-12);
    EXPECT_LE(st.twist_angle, kPi + 1e-12);
    // Swing axis is perpendicular to the twist axis.
    const Eigen::Vector3d swing_vector = LogSO3(st.swing);
    EXPECT_NEAR(swing_vector.dot(axis), 0.0, 1e-12);
  }
}

TEST(So3Test, SwingTwistRecoversKnownFactors) {
  std::mt19937_64 rng(4);
  for (int i = 0; i < 100; ++i) {
    const Eigen::Vector3d axis = RandomUnit(rng);
    Eigen::Vector3d perpendicular = RandomUnit(rng);
    perpendicular = (perpendicular - axis * axis.dot(perpendicular)).normalized();
    const double swing_angle = Uniform(rng, 0.0, 2.5);
    const double twist_angle = Uniform(rng, -3.0, 3.0);
    const Eigen::Matrix3d swing = ExpSO3(perpendicular * swing_angle);
    const Eigen::Matrix3d twist = ExpSO3(axis * twist_angle);
    // A non-unit axis is normalised.
    const SwingTwist st = DecomposeSwingTwist(swing * twist, 2.5 * axis);
    EXPECT_NEAR(st.twist_angle, twist_angle, 1e-11);
    EXPECT_LT((st.swing - swing).norm(), 1e-11);
    EXPECT_LT((st.twist - twist).norm(), 1e-11);
  }
  // Pure twist, pure swing, and the sign of the twist.
  const Eigen::Vector3d a(0, 1, 0);
  SwingTwist st = DecomposeSwingTwist(ExpSO3(a * 0.8), a);
  EXPECT_NEAR(st.twist_angle, 0.8, 1e-14);
  EXPECT_LT((st.swing - Eigen::Matrix3d::Identity()).norm(), 1e-14);
  st = DecomposeSwingTwist(ExpSO3(-a * 0.8), a);
  EXPECT_NEAR(st.twist_angle, -0.8, 1e-14);
  st = DecomposeSwingTwist(ExpSO3(Eigen::Vector3d(0.6, 0, 0.3)), a);
  EXPECT_NEAR(st.twist_angle, 0.0, 1e-14);
  EXPECT_LT((st.twist - Eigen::Matrix3d::Identity()).norm(), 1e-14);
  // 180-degree swing: twist undefined, reported as zero, swing keeps the rotation.
  st = DecomposeSwingTwist(ExpSO3(Eigen::Vector3d(kPi, 0, 0)), a);
  EXPECT_EQ(st.twist_angle, 0.0);
  EXPECT_LT((st.swing - ExpSO3(Eigen::Vector3d(kPi, 0, 0))).norm(), 1e-12);
}

TEST(So3Test, ProjectToRotation) {
  std::mt19937_64 rng(5);
  for (int i = 0; i < 50; ++i) {
    const Eigen::Matrix3d r = ExpSO3(RandomUnit(rng) * Uniform(rng, 0.0, 3.0));
    Eigen::Matrix3d noisy = r;
    for (int k = 0; k < 9; ++k) noisy(k / 3, k % 3) += Uniform(rng, -1e-3, 1e-3);
    const Eigen::Matrix3d p = ProjectToRotation(noisy);
    ExpectRotation(p);
    EXPECT_LT((p - r).norm(), 1e-2);
    EXPECT_LT((ProjectToRotation(r) - r).norm(), 1e-12);
  }
  // A reflection is mapped to a proper rotation.
  const Eigen::Matrix3d reflection = Eigen::Vector3d(1, 1, -1).asDiagonal();
  ExpectRotation(ProjectToRotation(reflection));
}

}  // namespace
}  // namespace artex
