// Jacobians of every fitting term against central finite differences through Pose::Retracted
// (at delta = 0 and away from it), the block-sparse normal equations against the dense
// Evaluate path, and the residual definitions.
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "energies/fitting_term.h"
#include "energies/joint_coupling_term.h"
#include "energies/joint_limit_term.h"
#include "energies/one_to_many_correspondence.h"
#include "energies/one_to_one_correspondence.h"
#include "energies/pose_smoothness_term.h"
#include "energies/silhouette_term.h"
#include "energies/unobserved_joint_term.h"
#include "energies/upright_term.h"
#include "energies/tikhonov_term.h"
#include "models/error.h"
#include "models/so3.h"
#include "tests/solvers/fitting_test_util.h"

namespace artex {
namespace {

using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

class FittingTermsTest : public ::testing::Test {
 protected:
  FittingTermsTest()
      : model_(testing_util::MakeStickTemplate(4, 8)), skinning_(model_), rng_(1234) {
    anchor_ = testing_util::RandomPose(model_.num_joints(), 0.4, 0.6, 0.3, &rng_, 1.1);
    p_ = anchor_.num_parameters();
    std::normal_distribution<double> n(0.0, 1.0);
    delta_ = Eigen::VectorXd::Zero(p_);
    for (int i = 0; i < p_; ++i) delta_[i] = 0.15 * n(rng_);
  }

  Eigen::VectorXd Residuals(const FittingTerm& term, const Eigen::VectorXd& delta) {
    FitEvaluation eval;
    PrepareFitEvaluation(&skinning_, anchor_, delta, true, false, &eval);
    Eigen::VectorXd r(term.num_residuals());
    EXPECT_TRUE(term.Evaluate(eval, r.data(), nullptr));
    return r;
  }

  // Analytic d r / d delta vs central differences of r(anchor.Retracted(delta +- h e_i)).
  void CheckJacobian(const FittingTerm& term, const Eigen::VectorXd& delta, double tol = 1e-6) {
    FitEvaluation eval;
    PrepareFitEvaluation(&skinning_, anchor_, delta, true, true, &eval);
    const int m = term.num_residuals();
    Eigen::VectorXd r(m);
    RowMajor j(m, p_);
    ASSERT_TRUE(term.Evaluate(eval, r.data(), j.data()));
    EXPECT_LT((r - Residuals(term, delta)).cwiseAbs().maxCoeff(), 1e-12);
    ASSERT_GT(j.cwiseAbs().maxCoeff(), 0.0) << term.name() << ": Jacobian is identically zero";
    const double h = 1e-6;
    double worst = 0.0;
    for (int i = 0; i < p_; ++i) {
      Eigen::VectorXd plus = delta, minus = delta;
      plus[i] += h;
      minus[i] -= h;
      const Eigen::VectorXd fd = (Residuals(term, plus) - Residuals(term, minus)) / (2.0 * h);
      const double err = (fd - j.col(i)).cwiseAbs().maxCoeff() / (1.0 + fd.cwiseAbs().maxCoeff());
      worst = std::max(worst, err);
      EXPECT_LT(err, tol) << term.name() << ": column " << i;
    }
    RecordProperty(term.name() + "_worst_relative_jacobian_error", std::to_string(worst));
  }

  // Block-sparse normal equations vs J^T J, J^T r from the dense Evaluate.
  void CheckNormalEquations(const FittingTerm& term, const Eigen::VectorXd& delta) {
    FitEvaluation eval;
    PrepareFitEvaluation(&skinning_, anchor_, delta, true, true, &eval);
    const int m = term.num_residuals();
    Eigen::VectorXd r(m);
    RowMajor j(m, p_);
    ASSERT_TRUE(term.Evaluate(eval, r.data(), j.data()));
    Eigen::MatrixXd jtj = Eigen::MatrixXd::Zero(p_, p_);
    Eigen::VectorXd jtr = Eigen::VectorXd::Zero(p_);
    const double cost = term.AccumulateNormalEquations(eval, &jtj, &jtr);
    const Eigen::MatrixXd ref_jtj = j.transpose() * j;
    const Eigen::VectorXd ref_jtr = j.transpose() * r;
    EXPECT_NEAR(cost, r.squaredNorm(), 1e-10 * (1.0 + r.squaredNorm()));
    EXPECT_NEAR(term.Cost(eval), r.squaredNorm(), 1e-10 * (1.0 + r.squaredNorm()));
    EXPECT_LT((jtj - ref_jtj).cwiseAbs().maxCoeff(), 1e-9 * (1.0 + ref_jtj.cwiseAbs().maxCoeff()));
    EXPECT_LT((jtr - ref_jtr).cwiseAbs().maxCoeff(), 1e-9 * (1.0 + ref_jtr.cwiseAbs().maxCoeff()));
  }

  CorrespondenceTargets RandomTargets() {
    Eigen::MatrixX3d posed;
    skinning_.Apply(anchor_, &posed);
    std::normal_distribution<double> n(0.0, 0.02);
    std::uniform_real_distribution<double> u(0.0, 3.0);
    CorrespondenceTargets targets;
    targets.weight.resize(model_.num_vertices());
    targets.mean.resize(model_.num_vertices(), 3);
    for (int t = 0; t < model_.num_vertices(); ++t) {
      targets.weight[t] = t % 7 == 0 ? 0.0 : u(rng_);  // some vertices without correspondence
      targets.mean.row(t) = posed.row(t) + Eigen::RowVector3d(n(rng_), n(rng_), n(rng_));
    }
    return targets;
  }

  NearestTargets RandomNearest() {
    const CorrespondenceTargets c = RandomTargets();
    NearestTargets targets;
    targets.weight = (c.weight.array() > 0.0).cast<double>();
    targets.point = c.mean;
    targets.normal.resize(c.size(), 3);
    std::normal_distribution<double> n(0.0, 1.0);
    for (int t = 0; t < c.size(); ++t) {
      targets.normal.row(t) = Eigen::RowVector3d(n(rng_), n(rng_), n(rng_)).normalized();
    }
    targets.index = Eigen::VectorXi::Zero(c.size());
    return targets;
  }

  Template model_;
  Skinning skinning_;
  std::mt19937_64 rng_;
  Pose anchor_;
  int p_ = 0;
  Eigen::VectorXd delta_;
};

TEST(So3JacobianTest, LeftJacobianMatchesExponentialMap) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  for (double angle : {0.0, 1e-7, 0.3, 2.0, 3.0}) {
    const Eigen::Vector3d w = Eigen::Vector3d(n(rng), n(rng), n(rng)).normalized() * angle;
    const Eigen::Matrix3d jl = LeftJacobianSO3(w);
    EXPECT_LT((jl * LeftJacobianInverseSO3(w) - Eigen::Matrix3d::Identity()).norm(), 1e-9);
    // Exp(w + h e_i) Exp(w)^T = Exp(h J_l e_i) to first order.
    const double h = 1e-6;
    for (int i = 0; i < 3; ++i) {
      Eigen::Vector3d e = Eigen::Vector3d::Zero();
      e[i] = h;
      const Eigen::Vector3d fd =
          (LogSO3(ExpSO3(w + e) * ExpSO3(w).transpose()) -
           LogSO3(ExpSO3(w - e) * ExpSO3(w).transpose())) /
          (2.0 * h);
      EXPECT_LT((fd - jl.col(i)).norm(), 1e-6) << "angle " << angle;
    }
  }
}

TEST(CorrespondenceWeightTest, FollowsEquationFour) {
  OneToManyOptions o;
  o.epsilon = 1e-4;
  o.lambda_color = 2.0;
  EXPECT_DOUBLE_EQ(CorrespondenceWeight(0.5, 0.01, 0.02, o), 0.5 / (0.01 + 2.0 * 0.02 + 1e-4));
  EXPECT_EQ(CorrespondenceWeight(-0.2, 0.01, 0.0, o), 0.0);  // back-facing pairs
  EXPECT_EQ(CorrespondenceWeight(0.0, 0.0, 0.0, o), 0.0);
  EXPECT_GT(CorrespondenceWeight(1.0, 0.0, 0.0, o), CorrespondenceWeight(1.0, 1e-3, 0.0, o));
  o.epsilon = 0.0;
  std::string error;
  EXPECT_FALSE(o.IsValid(&error));
  EXPECT_NE(error.find("epsilon"), std::string::npos);
}

TEST_F(FittingTermsTest, OneToManyJacobian) {
  const CorrespondenceTargets targets = RandomTargets();
  OneToManyCorrespondenceTerm term(&targets, 0.7);
  CheckJacobian(term, Eigen::VectorXd::Zero(p_));
  CheckJacobian(term, delta_);
  CheckNormalEquations(term, Eigen::VectorXd::Zero(p_));
  CheckNormalEquations(term, delta_);
}

TEST_F(FittingTermsTest, OneToManyResidualIsWeightedDistanceToMean) {
  const CorrespondenceTargets targets = RandomTargets();
  OneToManyCorrespondenceTerm term(&targets, 0.5);
  Eigen::MatrixX3d posed;
  skinning_.Apply(anchor_.Retracted(delta_), &posed);
  double expected = 0.0;
  for (int t = 0; t < targets.size(); ++t) {
    expected += 0.5 * targets.weight[t] * (posed.row(t) - targets.mean.row(t)).squaredNorm();
  }
  EXPECT_NEAR(Residuals(term, delta_).squaredNorm(), expected, 1e-12 * (1.0 + expected));
}

TEST_F(FittingTermsTest, OneToOnePointToPointJacobian) {
  const NearestTargets targets = RandomNearest();
  OneToOneCorrespondenceTerm term(&targets, IcpMetric::kPointToPoint, 2.0);
  EXPECT_EQ(term.num_residuals(), 3 * model_.num_vertices());
  CheckJacobian(term, delta_);
  CheckNormalEquations(term, delta_);
}

TEST_F(FittingTermsTest, OneToOnePointToPlaneJacobian) {
  const NearestTargets targets = RandomNearest();
  OneToOneCorrespondenceTerm term(&targets, IcpMetric::kPointToPlane, 2.0);
  EXPECT_EQ(term.num_residuals(), model_.num_vertices());
  CheckJacobian(term, Eigen::VectorXd::Zero(p_));
  CheckJacobian(term, delta_);
  CheckNormalEquations(term, delta_);
  // Point-to-plane ignores motion within the tangent plane.
  Eigen::MatrixX3d posed;
  skinning_.Apply(anchor_.Retracted(delta_), &posed);
  const Eigen::VectorXd r = Residuals(term, delta_);
  for (int t = 0; t < targets.size(); ++t) {
    const double expected = std::sqrt(2.0 * targets.weight[t]) *
                            targets.normal.row(t).dot(posed.row(t) - targets.point.row(t));
    EXPECT_NEAR(r[t], expected, 1e-12);
  }
}

TEST_F(FittingTermsTest, TikhonovJacobianAndValues) {
  TikhonovOptions options;
  options.update = {0.5, 2.0, 3.0, 4.0};
  options.temporal = {1.0, 5.0, 6.0, 7.0};
  const Pose previous = testing_util::RandomPose(model_.num_joints(), 0.5, 0.5, 0.2, &rng_);
  TikhonovTerm term(options, model_.num_joints(), &previous);
  EXPECT_EQ(term.num_residuals(), 2 * p_);
  CheckJacobian(term, delta_);
  CheckJacobian(term, Eigen::VectorXd::Zero(p_));
  const Eigen::VectorXd r = Residuals(term, delta_);
  // Update part: sqrt(Gamma) delta.
  EXPECT_NEAR(r[kScaleIndex], std::sqrt(0.5) * delta_[kScaleIndex], 1e-12);
  EXPECT_NEAR(r[JointParameterIndex(2) + 1], 2.0 * delta_[JointParameterIndex(2) + 1], 1e-12);
  // Temporal part: zero at the previous pose.
  anchor_ = previous;
  EXPECT_LT(Residuals(term, Eigen::VectorXd::Zero(p_)).tail(p_).norm(), 1e-12);
  // Without a previous pose there is no temporal part.
  TikhonovTerm update_only(options, model_.num_joints(), nullptr);
  EXPECT_EQ(update_only.num_residuals(), p_);
}

TEST_F(FittingTermsTest, JointLimitJacobianAndHinge) {
  JointLimitOptions options;
  options.weight = 3.0;
  options.default_min = Eigen::Vector3d::Constant(-0.1);
  options.default_max = Eigen::Vector3d::Constant(0.15);
  ASSERT_TRUE(options.IsValid(model_.num_joints(), nullptr));
  JointLimitTerm term(options, model_.num_joints());
  // Joint angles ~0.4 rad: most components outside the box (away from the hinge kink).
  CheckJacobian(term, delta_, 1e-5);
  // Inside the box: zero residuals.
  anchor_ = Pose::Identity(model_.num_joints());
  EXPECT_EQ(Residuals(term, Eigen::VectorXd::Zero(p_)).norm(), 0.0);
  // A single component beyond the box.
  anchor_.joint_rotations[2] = ExpSO3(Eigen::Vector3d(0.25, 0.0, 0.0));
  const Eigen::VectorXd r = Residuals(term, Eigen::VectorXd::Zero(p_));
  EXPECT_NEAR(r[6], std::sqrt(3.0) * 0.1, 1e-12);
  EXPECT_NEAR(r.norm(), std::sqrt(3.0) * 0.1, 1e-12);
  options.per_joint_min.resize(2);
  EXPECT_FALSE(options.IsValid(model_.num_joints(), nullptr));
}

TEST_F(FittingTermsTest, JointCouplingJacobianAndDifference) {
  const std::vector<std::string> names = model_.JointNames();
  ASSERT_GE(names.size(), 4u);
  JointCouplingOptions options;
  options.weight = 2.0;
  options.pairs = {{names[1], names[2]}, {names[0], names[3]}};
  ASSERT_TRUE(options.IsValid(nullptr));
  JointCouplingTerm term(options, names);
  EXPECT_EQ(term.num_residuals(), 6);
  CheckJacobian(term, delta_, 1e-5);
  // Both joints turned alike: no residual; turned against each other: sqrt(w) times the
  // difference of the rotation vectors.
  anchor_ = Pose::Identity(model_.num_joints());
  const Eigen::Vector3d w(0.2, -0.1, 0.3);
  anchor_.joint_rotations[1] = ExpSO3(w);
  anchor_.joint_rotations[2] = ExpSO3(w);
  EXPECT_LT(Residuals(term, Eigen::VectorXd::Zero(p_)).norm(), 1e-12);
  anchor_.joint_rotations[2] = ExpSO3(-w);
  const Eigen::VectorXd r = Residuals(term, Eigen::VectorXd::Zero(p_));
  EXPECT_LT((r.head<3>() - std::sqrt(2.0) * 2.0 * w).norm(), 1e-12);
  EXPECT_EQ(r.tail<3>().norm(), 0.0);
  // A pair with a joint the template lacks is skipped (and named), a pair of one joint invalid.
  options.pairs = {{names[1], "no_such_joint"}, {names[1], names[2]}};
  EXPECT_EQ(JointCouplingTerm(options, names).num_residuals(), 3);
  EXPECT_EQ(JointCouplingTerm::MissingJoints(options, names), "no_such_joint");
  options.pairs = {{names[1], names[1]}};
  EXPECT_FALSE(options.IsValid(nullptr));
  options.pairs = {{names[1], names[2]}};
  options.weight = -1.0;
  EXPECT_FALSE(options.IsValid(nullptr));
}

TEST_F(FittingTermsTest, AnatomicalLimitsMirrorAndOverride) {
  JointBox left, right;
  ASSERT_TRUE(AnatomicalJointBox("l_hip", &left));
  ASSERT_TRUE(AnatomicalJointBox("r_hip", &right));
  EXPECT_FALSE(AnatomicalJointBox("tail", &left));
  ASSERT_TRUE(AnatomicalJointBox("l_hip", &left));
  // Mirrored through x = 0: x limits equal, y and z negated and swapped.
  EXPECT_EQ(right.min.x(), left.min.x());
  EXPECT_EQ(right.max.z(), -left.min.z());
  EXPECT_EQ(right.min.z(), -left.max.z());
  // Hip flexion (-x: the leg forwards) is allowed far beyond extension (+x).
  EXPECT_LT(left.min.x(), -2.0);
  EXPECT_LT(left.max.x(), 0.7);
  JointBox knee;
  ASSERT_TRUE(AnatomicalJointBox("l_knee", &knee));
  EXPECT_GT(knee.max.x(), 2.0);   // bends backwards
  EXPECT_GT(knee.min.x(), -0.3);  // not forwards

  JointLimitOptions options;
  options.weight = 1.0;
  options.preset = JointLimitPreset::kAnatomical;
  options.joints["b"] = JointBox{Eigen::Vector3d::Constant(-0.2), Eigen::Vector3d::Constant(0.2)};
  const JointLimitOptions resolved = ResolveJointLimits(options, {"a", "b", "l_knee"});
  ASSERT_EQ(resolved.per_joint_min.size(), 3u);
  EXPECT_EQ(resolved.per_joint_min[0], options.default_min);  // unknown name: the default box
  EXPECT_EQ(resolved.per_joint_max[1], Eigen::Vector3d::Constant(0.2));  // the override
  EXPECT_EQ(resolved.per_joint_max[2], knee.max);
  options.joints["no_such_joint"] = JointBox{};
  EXPECT_THROW(ResolveJointLimits(options, {"a", "b"}), Error);
}

TEST_F(FittingTermsTest, UprightJacobianAndHinge) {
  UprightOptions options;
  options.weight = 2.0;
  options.max_tilt_deg = 5.0;
  ASSERT_TRUE(options.IsValid(nullptr));
  // The random anchor and delta tilt the root joint by tens of degrees: beyond the margin.
  UprightTerm term(options, 0);
  CheckJacobian(term, delta_, 1e-5);
  UprightTerm global_only(options, -1);
  CheckJacobian(global_only, delta_, 1e-5);
  // Upright: no residual. Tilted 40 degrees about z by the global rotation: 35 degrees beyond.
  anchor_ = Pose::Identity(model_.num_joints());
  EXPECT_EQ(Residuals(term, Eigen::VectorXd::Zero(p_))[0], 0.0);
  anchor_.rotation = ExpSO3(Eigen::Vector3d(0.0, 0.0, 40.0 * M_PI / 180.0));
  EXPECT_NEAR(Residuals(term, Eigen::VectorXd::Zero(p_))[0], std::sqrt(2.0) * 35.0 * M_PI / 180.0,
              1e-12);
  // A pelvis turned back by the same amount makes the lower body upright again.
  anchor_.joint_rotations[0] = ExpSO3(Eigen::Vector3d(0.0, 0.0, -40.0 * M_PI / 180.0));
  EXPECT_NEAR(Residuals(term, Eigen::VectorXd::Zero(p_))[0], 0.0, 1e-12);
  options.max_tilt_deg = 180.0;
  EXPECT_FALSE(options.IsValid(nullptr));
}

TEST_F(FittingTermsTest, PoseSmoothnessJacobianAndPrediction) {
  const Pose before = testing_util::RandomPose(model_.num_joints(), 0.3, 0.3, 0.1, &rng_);
  const Pose previous = before.Retracted(Eigen::VectorXd::Constant(p_, 0.05));
  PoseSmoothnessTerm term({1.0, 2.0, 3.0, 4.0}, before, previous);
  CheckJacobian(term, delta_);
  // Constant velocity: the prediction continues the same tangent step.
  const Pose& prediction = term.prediction();
  EXPECT_NEAR(prediction.scale, previous.scale + 0.05, 1e-12);
  EXPECT_LT((prediction.translation - (2.0 * previous.translation - before.translation)).norm(),
            1e-12);
  const Eigen::Matrix3d expected_rotation =
      previous.rotation * before.rotation.transpose() * previous.rotation;
  EXPECT_LT((prediction.rotation - expected_rotation).norm(), 1e-9);
  anchor_ = prediction;
  EXPECT_LT(Residuals(term, Eigen::VectorXd::Zero(p_)).norm(), 1e-9);
}

// Silhouette term: lateral residuals on some vertices, depth residuals on others, none on the
// rest; the Jacobian and the normal equations against the dense path.
TEST_F(FittingTermsTest, SilhouetteJacobianAndResiduals) {
  Eigen::MatrixX3d posed;
  skinning_.Apply(anchor_, &posed);
  const int t_count = model_.num_vertices();
  SilhouetteTargets targets;
  targets.weight.setZero(t_count);
  targets.depth_weight.setZero(t_count);
  targets.target = posed;
  const Eigen::Matrix3d r = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized())
                                .toRotationMatrix();  // a camera not aligned with the world
  targets.axis_u = r.col(0).transpose().replicate(t_count, 1);
  targets.axis_v = r.col(1).transpose().replicate(t_count, 1);
  targets.axis_z = r.col(2).transpose().replicate(t_count, 1);
  std::normal_distribution<double> n(0.0, 0.03);
  for (int t = 0; t < t_count; ++t) {
    targets.target.row(t) += Eigen::RowVector3d(n(rng_), n(rng_), n(rng_));
    if (t % 3 == 0) {
      targets.weight[t] = 1.0;
      ++targets.violations;
    } else if (t % 3 == 1 && t % 2 == 0) {
      targets.depth_weight[t] = 0.5;
      ++targets.violations;
      ++targets.depth_violations;
    }
  }
  SilhouetteTerm term(&targets, 0.8);
  EXPECT_EQ(term.num_residuals(), 3 * t_count);
  CheckJacobian(term, Eigen::VectorXd::Zero(p_));
  CheckJacobian(term, delta_);
  CheckNormalEquations(term, Eigen::VectorXd::Zero(p_));
  CheckNormalEquations(term, delta_);
  skinning_.Apply(anchor_.Retracted(delta_), &posed);
  const Eigen::VectorXd res = Residuals(term, delta_);
  for (int t = 0; t < t_count; ++t) {
    const Eigen::RowVector3d d = posed.row(t) - targets.target.row(t);
    EXPECT_NEAR(res[3 * t], std::sqrt(0.8 * targets.weight[t]) * r.col(0).dot(d.transpose()),
                1e-12);
    EXPECT_NEAR(res[3 * t + 2],
                std::sqrt(0.8 * targets.depth_weight[t]) * r.col(2).dot(d.transpose()), 1e-12);
  }
}

// A camera looking at the template: vertices beside a foreground strip are outside the
// silhouette and get the strip's nearest pixel as target; vertices behind the observed
// background are hidden; vertices outside the image never violate.
TEST_F(FittingTermsTest, SilhouetteViolationsFollowTheMap) {
  PinholeCamera camera;
  camera.width = 64;
  camera.height = 48;
  camera.fx = camera.fy = 60.0;
  camera.cx = 31.5;
  camera.cy = 23.5;
  cv::Mat depth(48, 64, CV_16UC1, cv::Scalar(3000));  // a wall at 3 m (1000 units/m)
  cv::Mat mask(48, 64, CV_8UC1, cv::Scalar(0));
  mask.colRange(28, 36).setTo(255);  // the subject: a vertical strip
  depth.colRange(28, 36).setTo(2000);
  SilhouetteOptions options;
  options.raster_width = 64;
  options.edge_margin_px = 1.0;
  const auto map = BuildSilhouetteMap(depth, 1000.0, mask, camera, options);
  ASSERT_EQ(map->width, 64);
  EXPECT_FALSE(map->zero_depth_free);  // the wall has depth: a real recording
  EXPECT_GT(map->free_pixels, 40 * 48);
  Eigen::MatrixX3d points(5, 3);
  points.row(0) = camera.Unproject(10.0, 20.0, 2.0).transpose();  // beside the strip, in front
  points.row(1) = camera.Unproject(31.0, 20.0, 2.0).transpose();  // on the strip
  points.row(2) = camera.Unproject(10.0, 20.0, 3.5).transpose();  // behind the wall: hidden
  points.row(3) = camera.Unproject(-20.0, 20.0, 2.0).transpose(); // outside the image
  points.row(4) = camera.Unproject(50.0, 10.0, 1.0).transpose();  // beside, other side
  SilhouetteTermOptions term_options;
  SilhouetteTargets targets;
  FindSilhouetteViolations(*map, points, term_options, &targets);
  EXPECT_EQ(targets.violations, 2);
  EXPECT_EQ(targets.weight[0], 1.0);
  EXPECT_EQ(targets.weight[1] + targets.weight[2] + targets.weight[3], 0.0);
  EXPECT_EQ(targets.weight[4], 1.0);
  double z = 0.0;
  const Eigen::Vector2d q0 = camera.Project(targets.target.row(0).transpose(), &z);
  EXPECT_NEAR(z, 2.0, 1e-9);  // at the vertex's depth
  EXPECT_NEAR(q0.x(), 28.0, 1e-6);  // the strip's nearest column
  EXPECT_NEAR(q0.y(), 20.0, 1e-6);
  const Eigen::Vector2d q4 = camera.Project(targets.target.row(4).transpose());
  EXPECT_NEAR(q4.x(), 35.0, 1e-6);
  // In front of the subject: only with front_weight.
  points.row(1) = camera.Unproject(31.0, 20.0, 1.5).transpose();
  FindSilhouetteViolations(*map, points, term_options, &targets);
  EXPECT_EQ(targets.depth_violations, 0);
  term_options.front_weight = 1.0;
  FindSilhouetteViolations(*map, points, term_options, &targets);
  EXPECT_EQ(targets.depth_violations, 1);
  EXPECT_NEAR((camera.world_to_camera * targets.target.row(1).transpose()).z(), 2.0, 1e-9);
  // Zero depth around a subject that is all the valid depth: a pre-segmented recording.
  depth.setTo(0);
  depth.colRange(28, 36).setTo(2000);
  const auto presegmented = BuildSilhouetteMap(depth, 1000.0, mask, camera, options);
  EXPECT_TRUE(presegmented->zero_depth_free);
  options.zero_depth = ZeroDepthMeaning::kUnknown;
  const auto unknown = BuildSilhouetteMap(depth, 1000.0, mask, camera, options);
  EXPECT_EQ(unknown->free_pixels, 0);
  // Bad input names what is wrong.
  try {
    BuildSilhouetteMap(cv::Mat(10, 10, CV_8UC1), 1000.0, mask, camera, options);
    FAIL() << "accepted a wrong depth image";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("CV_16UC1"), std::string::npos);
  }
}

TEST_F(FittingTermsTest, UnobservedJointsArePulledTowardsTheReference) {
  Eigen::VectorXi vertex_joint(6);
  vertex_joint << 0, 0, 1, 1, 1, 2;
  Eigen::VectorXd matched(6);
  matched << 1.0, 0.0, 0.0, 0.0, 0.5, 0.0;
  // Joint 0: 1 of 2 matched; joint 1: 1 of 3; joint 2: 0 of 1; joint 3: no vertices.
  EXPECT_EQ(UnobservedJoints(vertex_joint, matched, 4, 0.4), (std::vector<int>{1, 2}));
  EXPECT_EQ(UnobservedJoints(vertex_joint, matched, 4, 0.3), (std::vector<int>{2}));
  const Pose reference = testing_util::RandomPose(model_.num_joints(), 0.3, 0.5, 0.2, &rng_, 1.0);
  UnobservedJointTerm term(&reference, {1, 3}, 2e-3);
  EXPECT_EQ(term.num_residuals(), p_);
  CheckJacobian(term, delta_);
  // Only the listed joints' rotations have residuals.
  const Eigen::VectorXd r = Residuals(term, delta_);
  for (int i = 0; i < p_; ++i) {
    const bool listed = i >= JointParameterIndex(1) && i < JointParameterIndex(1) + 3;
    const bool listed3 = i >= JointParameterIndex(3) && i < JointParameterIndex(3) + 3;
    if (!listed && !listed3) {
      EXPECT_EQ(r[i], 0.0) << i;
    }
  }
  EXPECT_GT(r.segment<3>(JointParameterIndex(1)).norm(), 0.0);
  UnobservedJointOptions o;
  o.min_observed_fraction = 1.5;
  std::string error;
  EXPECT_FALSE(o.IsValid(&error));
  EXPECT_NE(error.find("min_observed_fraction"), std::string::npos);
}

}  // namespace
}  // namespace artex
