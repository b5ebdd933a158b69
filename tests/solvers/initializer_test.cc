// Multi-hypothesis initialisation (solvers/initializer.h) on the virtual Kinect: a person
// facing away or standing sideways is initialised with the right facing (global yaw within 45
// degrees of the truth) and a good fit, and stays tracked; a person cropped to the upper body
// by a close camera gets a scale within 5 % of the truth (the default scale options).
#include "solvers/initializer.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include "models/error.h"
#include "models/skinning.h"
#include "models/so3.h"
#include "models/template_generator.h"
#include "solvers/em_fitter.h"
#include "tests/solvers/virtual_kinect_scans.h"

namespace artex {
namespace {

constexpr int kFrames = 30;
constexpr double kRadToDeg = 180.0 / M_PI;

double YawDifferenceDeg(const Pose& a, const Pose& b) {
  double d = (YawOfRotation(a.rotation) - YawOfRotation(b.rotation)) * kRadToDeg;
  while (d > 180.0) d -= 360.0;
  while (d < -180.0) d += 360.0;
  return std::abs(d);
}

// The scale of the tracking template that matches the subject's stature.
double TrueScale() { return DefaultSubjectShape().height / BodyShapeOptions().height; }

struct Tracked {
  InitResult init;
  std::vector<Pose> poses;
  std::vector<FitQuality> quality;
  double scale_estimate = 0.0;
  // Re-initialisation of the middle frame after Reset(true) (as after a lost frame).
  InitResult reinit;
  int reinit_frame = 0;
  bool reinit_scale_free = true;
};

// The scan and the depth camera of `data` frame `frame` in a world rotated by `m` (e.g. with
// y down); the initialiser is told the new up direction.
InitResult InitializeInRotatedWorld(const testing_util::KinectScans& data, int frame,
                                    const Eigen::Matrix3d& m, const Template& tmpl) {
  Scan scan = data.scans[frame];
  scan.points = (scan.points * m.transpose()).eval();
  scan.normals = (scan.normals * m.transpose()).eval();
  PinholeCamera camera = data.depth_camera;
  Eigen::Isometry3d rotation = Eigen::Isometry3d::Identity();
  rotation.linear() = m;
  camera.world_to_camera = data.depth_camera.world_to_camera * rotation.inverse();
  InitializerOptions options;
  options.world_up = m * Eigen::Vector3d::UnitY();
  EMFitter fitter(tmpl, EMFitterOptions());
  return InitializeFit(&fitter, scan, camera, options);
}

Tracked InitializeAndTrack(const testing_util::KinectScans& data, const Template& tmpl,
                           const EMFitterOptions& fitting = EMFitterOptions()) {
  Tracked t;
  EMFitter fitter(tmpl, fitting);
  t.init = InitializeFit(&fitter, data.scans[0], data.depth_camera, InitializerOptions());
  Eigen::MatrixX3d posed;
  for (size_t i = 0; i < data.scans.size(); ++i) {
    if (i > 0) fitter.FitFrame(data.scans[i]);
    t.poses.push_back(fitter.pose());
    fitter.skinning().Apply(fitter.pose(), &posed);
    t.quality.push_back(EvaluateFitQuality(posed, tmpl.triangles, data.scans[i], data.depth_camera,
                                           FitQualityOptions()));
  }
  t.scale_estimate = fitter.scale_estimate();
  fitter.Reset(true);
  t.reinit_scale_free = fitter.ScaleIsFree();
  t.reinit_frame = static_cast<int>(data.scans.size()) / 2;
  t.reinit =
      InitializeFit(&fitter, data.scans[t.reinit_frame], data.depth_camera, InitializerOptions());
  return t;
}

void PrintInit(const std::string& what, const InitResult& r) {
  std::printf("[%s] %s\n", what.c_str(), r.BriefReport().c_str());
  for (size_t h = 0; h < r.hypotheses.size(); ++h) {
    const InitHypothesis& x = r.hypotheses[h];
    std::printf("  %c yaw %6.1f arms %4.0f: ICP rms %.1f mm, scale %.3f -> %.3f, %s%s%s\n",
                static_cast<int>(h) == r.chosen ? '*' : ' ', x.yaw_deg, x.arm_angle_deg,
                x.icp.rms * 1e3, x.icp.pose.scale, x.pose.scale,
                x.icp_quality.BriefReport().c_str(), x.fitted ? "\n                -> EM: " : "",
                x.fitted ? x.quality.BriefReport().c_str() : "");
  }
}

class InitializerFacingTest : public ::testing::TestWithParam<double> {};

TEST_P(InitializerFacingTest, ChoosesTheTrueFacingAndTracks) {
  const double subject_yaw = GetParam();
  SynthOptions options = testing_util::TestSynthOptions(kFrames);
  options.subject_yaw_deg = subject_yaw;
  const testing_util::KinectScans data = testing_util::SynthesizeScans(
      options, "initializer_yaw" + std::to_string(static_cast<int>(subject_yaw)));
  ASSERT_EQ(static_cast<int>(data.scans.size()), kFrames);
  const Template tmpl = GenerateTemplate();
  const Tracked t = InitializeAndTrack(data, tmpl);
  PrintInit("subject yaw " + std::to_string(subject_yaw), t.init);
  ASSERT_TRUE(t.init.ok);
  // 4 yaws x 3 arm poses, and at most one arm refinement of the best fit.
  int symmetric = 0;
  for (const InitHypothesis& h : t.init.hypotheses) symmetric += std::isfinite(h.arm_angle_deg);
  EXPECT_EQ(symmetric, 12);
  EXPECT_LE(t.init.hypotheses.size(), 13u);
  EXPECT_LT(YawDifferenceDeg(t.init.pose, data.truth[0]), 45.0)
      << "chosen yaw " << YawOfRotation(t.init.pose.rotation) * kRadToDeg << ", truth "
      << YawOfRotation(data.truth[0].rotation) * kRadToDeg;
  EXPECT_EQ(t.init.quality.label, FitQualityLabel::kGood) << t.init.quality.BriefReport();
  int good = 0;
  double worst_yaw = 0.0;
  for (int i = 0; i < kFrames; ++i) {
    worst_yaw = std::max(worst_yaw, YawDifferenceDeg(t.poses[i], data.truth[i]));
    good += t.quality[i].label == FitQualityLabel::kGood;
  }
  std::printf(
      "subject yaw %.0f: %d / %d frames good, worst yaw error %.1f deg, scale %.4f "
      "(stature ratio %.4f), init %.0f ms\n",
      subject_yaw, good, kFrames, worst_yaw, t.scale_estimate, TrueScale(),
      t.init.total_seconds * 1e3);
  RecordProperty("init_ms", std::to_string(t.init.total_seconds * 1e3));
  PrintInit("re-initialisation of frame " + std::to_string(t.reinit_frame), t.reinit);
  // Re-initialisation with the kept scale estimate.
  EXPECT_FALSE(t.reinit_scale_free);
  ASSERT_TRUE(t.reinit.ok);
  EXPECT_EQ(t.reinit.pose.scale, t.scale_estimate);
  EXPECT_LT(YawDifferenceDeg(t.reinit.pose, data.truth[t.reinit_frame]), 45.0);
  EXPECT_EQ(t.reinit.quality.label, FitQualityLabel::kGood) << t.reinit.quality.BriefReport();
  // The same first frame in a world with y down (as a TUM recording's camera frame).
  const Eigen::Matrix3d flip = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const InitResult flipped = InitializeInRotatedWorld(data, 0, flip, tmpl);
  ASSERT_TRUE(flipped.ok);
  EXPECT_EQ(flipped.quality.label, FitQualityLabel::kGood) << flipped.quality.BriefReport();
  // Back in the original world, the facing is the truth's.
  Pose unflipped = flipped.pose;
  unflipped.rotation = flip.transpose() * flipped.pose.rotation;
  EXPECT_LT(YawDifferenceDeg(unflipped, data.truth[0]), 45.0);
  // While tracking, a side view constrains the yaw less (measured worst 42 degrees at 90).
  EXPECT_LT(worst_yaw, 60.0);
  EXPECT_EQ(good, kFrames);
}

INSTANTIATE_TEST_SUITE_P(SubjectYaws, InitializerFacingTest, ::testing::Values(180.0, 90.0, -90.0),
                         [](const ::testing::TestParamInfo<double>& info) {
                           const int yaw = static_cast<int>(info.param);
                           return yaw < 0 ? "minus" + std::to_string(-yaw) : std::to_string(yaw);
                         });

TEST(InitializerTest, KneeHyperextensionIsTheForwardBendOfTheShank) {
  const Template tmpl = testing_util::CoarseTemplate();
  const Skinning skinning(tmpl);
  const int l_knee = tmpl.FindJoint("l_knee"), r_knee = tmpl.FindJoint("r_knee");
  ASSERT_GE(l_knee, 0);
  ASSERT_GE(r_knee, 0);
  const auto knee = [&](const Pose& pose) {
    Eigen::MatrixX3d centers;
    skinning.PosedJointCenters(pose, &centers);
    return KneeHyperextensionDeg(tmpl, centers);
  };
  Pose pose = Pose::Identity(tmpl.num_joints());
  const double rest = knee(pose);
  EXPECT_LT(std::abs(rest), 5.0) << "the rest legs are nearly straight";
  // A knee bends back by a rotation about its +x axis (the walk's flexion): the larger of the
  // two legs is then the straight one.
  pose.joint_rotations[l_knee] = ExpSO3(Eigen::Vector3d(0.6, 0.0, 0.0));
  EXPECT_NEAR(knee(pose), rest, 1e-9);
  pose.joint_rotations[r_knee] = ExpSO3(Eigen::Vector3d(0.6, 0.0, 0.0));
  EXPECT_LT(knee(pose), -25.0);
  // Bent the other way, forwards, by 0.4 rad (23 degrees).
  pose.joint_rotations[r_knee] = ExpSO3(Eigen::Vector3d(-0.4, 0.0, 0.0));
  EXPECT_GT(knee(pose), 18.0);
  EXPECT_LT(knee(pose), 28.0);
  // The whole body turned round, or turned and translated: the same bend relative to its front.
  const double bent = knee(pose);
  pose.rotation = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitY()).toRotationMatrix();
  pose.translation = Eigen::Vector3d(0.4, -0.1, 2.0);
  EXPECT_NEAR(knee(pose), bent, 1e-9);
  // A twist of the knee about its y axis (nearly the shank's) of the same 0.4 rad bends it far
  // less.
  pose.joint_rotations[r_knee] = ExpSO3(Eigen::Vector3d(0.0, 0.4, 0.0));
  EXPECT_LT(std::abs(knee(pose)), 5.0);
  // Without the joints: not measured.
  Template renamed = tmpl;
  renamed.joints[l_knee].name = "knee_left";
  EXPECT_TRUE(std::isnan(KneeHyperextensionDeg(renamed, Eigen::MatrixX3d::Zero(
                                                             tmpl.num_joints(), 3))));
}

// Frame 48 of the walk: mid-stride with the arms out, the template turned round explains the
// depth better (quality score 0.876 against 0.830) than the one facing the camera as the
// subject does; its knees then bend forwards (docs/fitting.md "How often the first frame is
// wrong").
TEST(InitializerTest, AFitWithAKneeBentForwardsRanksLast) {
  SynthOptions options = testing_util::TestSynthOptions(2);
  options.motion.frame_step = 48;  // frames 0 and 48 of the walk
  const testing_util::KinectScans data =
      testing_util::SynthesizeScans(options, "initializer_knee");
  ASSERT_EQ(data.scans.size(), 2u);
  const Template tmpl = GenerateTemplate();
  const auto initialise = [&](double max_knee_deg) {
    EMFitter fitter(tmpl, EMFitterOptions());
    InitializerOptions init;
    init.max_knee_hyperextension_deg = max_knee_deg;
    return InitializeFit(&fitter, data.scans[1], data.depth_camera, init);
  };
  const InitResult by_score = initialise(0.0);
  const InitResult result = initialise(InitializerOptions().max_knee_hyperextension_deg);
  PrintInit("knees not checked", by_score);
  PrintInit("knees checked", result);
  ASSERT_TRUE(by_score.ok);
  ASSERT_TRUE(result.ok);
  // Without the check the best score is the body turned round, knees bent forwards.
  EXPECT_GT(YawDifferenceDeg(by_score.pose, data.truth[1]), 135.0);
  EXPECT_GT(by_score.hypotheses[by_score.chosen].knee_hyperextension_deg, 10.0);
  EXPECT_EQ(by_score.knees_bent_forwards, 0);
  // With it that fit ranks last, and the chosen one faces as the subject does.
  EXPECT_GE(result.knees_bent_forwards, 1);
  EXPECT_LE(result.hypotheses[result.chosen].knee_hyperextension_deg, 10.0);
  EXPECT_LT(YawDifferenceDeg(result.pose, data.truth[1]), 45.0)
      << "chosen yaw " << YawOfRotation(result.pose.rotation) * kRadToDeg << ", truth "
      << YawOfRotation(data.truth[1].rotation) * kRadToDeg;
}

TEST(InitializerTest, UpperBodyCroppedByTheImageGetsTheTrueScale) {
  SynthOptions options = testing_util::TestSynthOptions(kFrames);
  options.kinect.depth_eye = Eigen::Vector3d(0.0, 1.3, 1.0);
  options.kinect.depth_target = Eigen::Vector3d(0.0, 1.2, 0.0);
  const testing_util::KinectScans data = testing_util::SynthesizeScans(options, "initializer_crop");
  ASSERT_EQ(static_cast<int>(data.scans.size()), kFrames);
  // The legs are out of view: no scan point below the hips (~0.9 m).
  for (const Scan& scan : data.scans) {
    ASSERT_GT(scan.size(), 1000);
    EXPECT_GT(scan.points.col(1).minCoeff(), 0.7);
  }
  const Template tmpl = GenerateTemplate();
  const Tracked t = InitializeAndTrack(data, tmpl);
  PrintInit("upper body", t.init);
  ASSERT_TRUE(t.init.ok);
  // The extent-based coarse scale of the former default for comparison.
  IcpInitOptions extent;
  extent.scale_from_extent = true;
  const double extent_scale =
      AlignByIcp(Skinning(tmpl), Pose::Identity(tmpl.num_joints()), data.scans[0], extent)
          .pose.scale;
  const double error = t.scale_estimate / TrueScale() - 1.0;
  std::printf(
      "upper body: first frame scale %.4f, estimate %.4f (truth %.4f, error %+.1f %%); "
      "extent-based ICP %.4f\n",
      t.init.pose.scale, t.scale_estimate, TrueScale(), 100.0 * error, extent_scale);
  RecordProperty("cropped_scale_error_percent", std::to_string(100.0 * error));
  EXPECT_LT(std::abs(error), 0.05);
  EXPECT_LT(YawDifferenceDeg(t.init.pose, data.truth[0]), 45.0);
  int good = 0;
  for (const FitQuality& q : t.quality) good += q.label == FitQualityLabel::kGood;
  EXPECT_GE(good, kFrames * 9 / 10);
}

// Frames dropped while the tracker was busy (live mode): the subject's limbs (the walk is in
// place) and, in a second scan shifted sideways, the whole subject have moved on. Frame 0 is
// initialised, frames 1-5 tracked, then frame 5 + kGap follows. RefitFromPose (the better start
// of the last pose and the last pose moved onto the scan, fitted with wider radii) explains it
// better than tracking the same frame from the stale pose, and places the subject.
TEST(InitializerTest, RefitAfterAGapRecoversTheSubject) {
  constexpr int kGap = 24;
  const testing_util::KinectScans data =
      testing_util::SynthesizeScans(testing_util::TestSynthOptions(6 + kGap), "initializer_gap");
  const Template tmpl = GenerateTemplate();
  EMFitter fitter(tmpl, EMFitterOptions());
  ASSERT_TRUE(InitializeFit(&fitter, data.scans[0], data.depth_camera, InitializerOptions()).ok);
  for (int i = 1; i <= 5; ++i) ASSERT_TRUE(fitter.FitFrame(data.scans[i]).ok());
  const Pose before_gap = fitter.pose();
  const int after = 5 + kGap;
  double limb_change_deg = 0.0;  // how far the limbs moved during the gap
  for (int j = 0; j < data.truth[after].num_joints(); ++j) {
    const Eigen::AngleAxisd d(data.truth[after].joint_rotations[j] *
                              data.truth[5].joint_rotations[j].transpose());
    limb_change_deg = std::max(limb_change_deg, d.angle() * kRadToDeg);
  }
  EXPECT_GT(limb_change_deg, 20.0);
  for (const double shift : {0.0, 0.25}) {
    Scan scan = data.scans[after];
    scan.points.col(0).array() += shift;
    const auto quality = [&](const Pose& pose) {
      Eigen::MatrixX3d posed;
      fitter.skinning().Apply(pose, &posed);
      return EvaluateFitQuality(posed, tmpl.triangles, scan, data.depth_camera,
                                FitQualityOptions());
    };
    // Fitters whose history is the last pose, its scale settled (as after the scale estimation).
    EMFitterOptions settled;
    settled.scale_mode = ScaleMode::kFixed;
    EMFitter tracker(tmpl, settled);  // tracked across the gap from the stale pose
    tracker.SetDepthCamera(data.depth_camera);
    tracker.AcceptPose(data.scans[5], before_gap);
    const FitSummary tracked = tracker.FitFrame(scan);
    const FitQuality tracked_quality = quality(tracker.pose());
    EMFitter refitter(tmpl, settled);
    refitter.AcceptPose(data.scans[5], before_gap);
    const FitSummary refit =
        RefitFromPose(&refitter, scan, data.depth_camera, before_gap, GapRefitOptions());
    const FitQuality refit_quality = quality(refitter.pose());
    const Eigen::Vector3d expected =
        before_gap.translation + (data.truth[after].translation - data.truth[5].translation) +
        Eigen::Vector3d(shift, 0.0, 0.0);
    const double translation_error = (refitter.pose().translation - expected).norm();
    std::printf("gap of %d frames (limbs %.0f deg), scan shifted %.0f mm: refit %d iterations, "
                "%s, translation error %.0f mm; tracked %d iterations, %s\n",
                kGap, limb_change_deg, 1e3 * shift, refit.iterations,
                refit_quality.BriefReport().c_str(), 1e3 * translation_error, tracked.iterations,
                tracked_quality.BriefReport().c_str());
    ASSERT_TRUE(refit.ok());
    EXPECT_EQ(refit_quality.label, FitQualityLabel::kGood) << refit_quality.BriefReport();
    EXPECT_GT(refit_quality.score, tracked_quality.score + 0.01);
    EXPECT_LT(translation_error, 0.03);
    // The scale estimate is kept, the history restarts from the refitted frame.
    EXPECT_EQ(refitter.pose().scale, before_gap.scale);
    EXPECT_EQ(refitter.frames_fitted(), 1);
  }
  GapRefitOptions bad;
  bad.radii = {0.0};
  EXPECT_THROW(RefitFromPose(&fitter, data.scans[after], data.depth_camera, before_gap, bad),
               Error);
  EXPECT_THROW(RefitFromPose(&fitter, data.scans[after], data.depth_camera, Pose::Identity(3),
                             GapRefitOptions()),
               Error);
}

// The first frame's initialisation of a live run takes ~20 frames at 30 Hz, and the walking
// subject steps meanwhile. Refitted from the last pose (legs together), both template legs
// tend to settle in one scan leg, a fit the quality labels take for good; the starts with the
// legs in stride (GapRefitOptions::leg_stride_deg) find the stepping legs.
TEST(InitializerTest, RefitAfterAGapFindsTheSteppingLegs) {
  constexpr int kAfter = 20;
  const testing_util::KinectScans data =
      testing_util::SynthesizeScans(testing_util::TestSynthOptions(kAfter + 1), "initializer_legs");
  const Template tmpl = GenerateTemplate();
  const Skinning skinning(tmpl);
  EMFitterOptions settled;
  settled.scale_mode = ScaleMode::kFixed;
  EMFitter first(tmpl, settled);
  ASSERT_TRUE(InitializeFit(&first, data.scans[0], data.depth_camera, InitializerOptions()).ok);
  ASSERT_TRUE(first.FitFrame(data.scans[1]).ok());
  const Pose before_gap = first.pose();
  const Scan& scan = data.scans[kAfter];
  Eigen::MatrixX3d truth_joints;
  skinning.PosedJointCenters(data.truth[kAfter], &truth_joints);
  struct Result {
    FitSummary fit;
    FitQuality quality;
    double joint_error_mm = 0.0;
  };
  const auto refit = [&](double stride_deg) {
    GapRefitOptions options;
    options.leg_stride_deg = stride_deg;
    EMFitter fitter(tmpl, settled);
    fitter.AcceptPose(data.scans[1], before_gap);
    Result r;
    r.fit = RefitFromPose(&fitter, scan, data.depth_camera, before_gap, options);
    Eigen::MatrixX3d posed, joints;
    skinning.Apply(fitter.pose(), &posed);
    skinning.PosedJointCenters(fitter.pose(), &joints);
    r.quality =
        EvaluateFitQuality(posed, tmpl.triangles, scan, data.depth_camera, FitQualityOptions());
    r.joint_error_mm = 1e3 * (joints - truth_joints).rowwise().norm().mean();
    return r;
  };
  const Result single = refit(0.0), stride = refit(20.0);
  std::printf("gap of %d frames: one start %d iterations, joint error %.1f mm, %s; legs in "
              "stride %d iterations, joint error %.1f mm, %s\n",
              kAfter - 1, single.fit.iterations, single.joint_error_mm,
              single.quality.BriefReport().c_str(), stride.fit.iterations, stride.joint_error_mm,
              stride.quality.BriefReport().c_str());
  ASSERT_TRUE(stride.fit.ok());
  // The kept fit is the best of three, the first of which is the one-start fit.
  EXPECT_GE(stride.quality.score, single.quality.score);
  EXPECT_GT(stride.fit.iterations, single.fit.iterations);  // every fit's iterations count
  EXPECT_LT(stride.joint_error_mm, 25.0);
  GapRefitOptions bad;
  bad.leg_stride_deg = 90.0;
  EMFitter fitter(tmpl, settled);
  EXPECT_THROW(RefitFromPose(&fitter, scan, data.depth_camera, before_gap, bad), Error);
}

// The same pose bit for bit.
bool SamePose(const Pose& a, const Pose& b) {
  bool same = a.scale == b.scale && a.translation == b.translation && a.rotation == b.rotation &&
              a.num_joints() == b.num_joints();
  for (int j = 0; same && j < a.num_joints(); ++j) {
    same = a.joint_rotations[j] == b.joint_rotations[j];
  }
  return same;
}

// The hypotheses' ICP alignments, their quality and the EM candidates' fits (each in its own
// copy of the fitter) run as concurrent oneTBB tasks; each writes only its own hypothesis, so
// every figure of the initialisation is the same bit for bit as with one thread. (Under
// ThreadSanitizer, scripts/test: the tasks share the scan, the skinning and the options.)
TEST(InitializerTest, ConcurrentHypothesesEqualOneThread) {
  const testing_util::KinectScans data =
      testing_util::SynthesizeScans(testing_util::TestSynthOptions(1), "initializer_concurrent");
  const Template tmpl = GenerateTemplate();
  const auto run = [&](int threads) {
    std::unique_ptr<tbb::global_control> limit;
    if (threads > 0) {
      limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    static_cast<size_t>(threads));
    }
    EMFitter fitter(tmpl, EMFitterOptions());
    return InitializeFit(&fitter, data.scans[0], data.depth_camera, InitializerOptions());
  };
  const InitResult one = run(1), all = run(0);
  ASSERT_TRUE(one.ok);
  EXPECT_EQ(all.ok, one.ok);
  EXPECT_EQ(all.chosen, one.chosen);
  EXPECT_TRUE(SamePose(all.pose, one.pose));
  EXPECT_EQ(all.quality.score, one.quality.score);
  ASSERT_EQ(all.hypotheses.size(), one.hypotheses.size());
  for (size_t i = 0; i < one.hypotheses.size(); ++i) {
    const InitHypothesis &a = all.hypotheses[i], &b = one.hypotheses[i];
    EXPECT_EQ(a.yaw_deg, b.yaw_deg) << i;
    EXPECT_EQ(a.icp.iterations, b.icp.iterations) << i;
    EXPECT_EQ(a.icp.rms, b.icp.rms) << i;
    EXPECT_TRUE(SamePose(a.icp.pose, b.icp.pose)) << i;
    EXPECT_EQ(a.icp_quality.score, b.icp_quality.score) << i;
    EXPECT_TRUE(SamePose(a.pose, b.pose)) << i;
    EXPECT_EQ(a.quality.score, b.quality.score) << i;
  }
}

// A refit's starts (the better start, and the legs in stride each way round) are fitted as
// concurrent oneTBB tasks, each in its own copy of the fitter: the same bit for bit as with one
// thread. (Under ThreadSanitizer, scripts/test.)
TEST(InitializerTest, ConcurrentRefitStartsEqualOneThread) {
  constexpr int kAfter = 6;
  const testing_util::KinectScans data = testing_util::SynthesizeScans(
      testing_util::TestSynthOptions(kAfter + 1), "initializer_refit_concurrent");
  const Template tmpl = GenerateTemplate();
  EMFitterOptions settled;
  settled.scale_mode = ScaleMode::kFixed;
  const auto refit = [&](int threads, Pose* pose) {
    std::unique_ptr<tbb::global_control> limit;
    if (threads > 0) {
      limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    static_cast<size_t>(threads));
    }
    EMFitter fitter(tmpl, settled);
    fitter.AcceptPose(data.scans[0], data.truth[0]);
    const FitSummary fit =
        RefitFromPose(&fitter, data.scans[kAfter], data.depth_camera, data.truth[0], {});
    *pose = fitter.pose();
    return fit;
  };
  Pose one, all;
  const FitSummary fit_one = refit(1, &one), fit_all = refit(0, &all);
  ASSERT_TRUE(fit_one.ok());
  EXPECT_EQ(fit_all.ok(), fit_one.ok());
  EXPECT_EQ(fit_all.iterations, fit_one.iterations);
  EXPECT_TRUE(SamePose(all, one));
}

TEST(InitializerTest, TooFewPointsFailsAsAFrame) {
  BodyShapeOptions coarse;
  coarse.resolution = 0;
  const Template tmpl = GenerateTemplate(coarse);
  EMFitter fitter(tmpl, EMFitterOptions());
  Scan scan;
  scan.points = Eigen::MatrixX3d::Zero(10, 3);
  scan.normals = Eigen::MatrixX3d::Zero(10, 3);
  const InitResult r = InitializeFit(&fitter, scan, PinholeCamera(), InitializerOptions());
  EXPECT_FALSE(r.ok);
  EXPECT_TRUE(r.fit.too_few_points);
  EXPECT_EQ(fitter.frames_fitted(), 1);
  InitializerOptions bad;
  bad.yaws_deg.clear();
  EXPECT_THROW(InitializeFit(&fitter, scan, PinholeCamera(), bad), Error);
  EXPECT_THROW(InitializeFit(nullptr, scan, PinholeCamera(), InitializerOptions()), Error);
}

}  // namespace
}  // namespace artex
