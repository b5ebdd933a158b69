// Fit quality without ground truth (solvers/fit_quality.h) on the virtual Kinect: the true
// subject surface and the tracked fits of a walk are good; the template upside down on the
// person, 1 m beside the person, and against the back wall are lost.
#include "solvers/fit_quality.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "models/error.h"
#include "models/template_generator.h"
#include "solvers/em_fitter.h"
#include "solvers/initializer.h"
#include "tests/solvers/virtual_kinect_scans.h"

namespace artex {
namespace {

constexpr int kFrames = 30;

struct Fixture {
  testing_util::KinectScans data;
  Template subject;  // the rendered body (its true surface)
  std::vector<Eigen::MatrixX3d> subject_posed;
  Template tmpl;             // the tracking template
  std::vector<Pose> fitted;  // tracked poses
  std::vector<FitSummary> fits;
  double wall_z = 0.0;
};

const Fixture& GetFixture() {
  static const Fixture* fixture = [] {
    auto* f = new Fixture;
    const SynthOptions options = testing_util::TestSynthOptions(kFrames);
    f->data = testing_util::SynthesizeScans(options, "fit_quality_test");
    const SynthSubject subject = PrepareSynthSubject(options);
    f->subject = subject.subject;
    const Skinning subject_skinning(f->subject);
    for (const Pose& p : subject.poses) {
      Eigen::MatrixX3d posed;
      subject_skinning.Apply(p, &posed);
      f->subject_posed.push_back(posed);
    }
    f->wall_z = options.kinect.scene.wall_z_m;
    f->tmpl = GenerateTemplate();
    EMFitter fitter(f->tmpl, EMFitterOptions());
    const InitResult init =
        InitializeFit(&fitter, f->data.scans[0], f->data.depth_camera, InitializerOptions());
    f->fitted.push_back(fitter.pose());
    f->fits.push_back(init.fit);
    for (int i = 1; i < static_cast<int>(f->data.scans.size()); ++i) {
      f->fits.push_back(fitter.FitFrame(f->data.scans[i]));
      f->fitted.push_back(fitter.pose());
    }
    return f;
  }();
  return *fixture;
}

FitQuality Evaluate(const Template& model, const Eigen::MatrixX3d& posed, int frame) {
  const Fixture& f = GetFixture();
  return EvaluateFitQuality(posed, model.triangles, f.data.scans[frame], f.data.depth_camera,
                            FitQualityOptions());
}

FitQuality EvaluatePose(const Pose& pose, int frame) {
  const Fixture& f = GetFixture();
  Eigen::MatrixX3d posed;
  Skinning(f.tmpl).Apply(pose, &posed);
  return Evaluate(f.tmpl, posed, frame);
}

TEST(FitQualityTest, TrueSurfaceAndTrackedFitsAreGood) {
  const Fixture& f = GetFixture();
  ASSERT_EQ(static_cast<int>(f.data.scans.size()), kFrames);
  double worst_inlier = 1.0, worst_support = 1.0, worst_residual = 0.0, max_ms = 0.0;
  for (int i = 0; i < kFrames; ++i) {
    const FitQuality truth = Evaluate(f.subject, f.subject_posed[i], i);
    const FitQuality fit = EvaluatePose(f.fitted[i], i);
    if (i % 10 == 0) {
      std::printf("frame %d truth: %s\n         fit: %s\n", i, truth.BriefReport().c_str(),
                  fit.BriefReport().c_str());
    }
    EXPECT_EQ(truth.label, FitQualityLabel::kGood) << "frame " << i << " " << truth.BriefReport();
    EXPECT_EQ(fit.label, FitQualityLabel::kGood) << "frame " << i << " " << fit.BriefReport();
    worst_inlier = std::min({worst_inlier, truth.inlier_fraction, fit.inlier_fraction});
    worst_support = std::min({worst_support, truth.support_fraction, fit.support_fraction});
    worst_residual = std::max({worst_residual, truth.depth_residual_m, fit.depth_residual_m});
    max_ms = std::max(max_ms, 1e3 * fit.seconds);
    EXPECT_GT(fit.scan_samples, 0);
    EXPECT_GT(fit.model_pixels, 0);
    EXPECT_GE(fit.union_pixels, fit.model_pixels);
  }
  std::printf("good fits: worst inliers %.3f, support %.3f, residual %.1f mm; max %.1f ms\n",
              worst_inlier, worst_support, worst_residual * 1e3, max_ms);
  RecordProperty("good_worst_inlier_fraction", std::to_string(worst_inlier));
  RecordProperty("good_worst_support_fraction", std::to_string(worst_support));
  RecordProperty("good_worst_depth_residual_mm", std::to_string(worst_residual * 1e3));
}

TEST(FitQualityTest, WrongFitsAreLost) {
  const Fixture& f = GetFixture();
  for (int i : {0, kFrames / 2, kFrames - 1}) {
    const Pose& good = f.fitted[i];
    // Centre of the fitted body (m, world).
    Eigen::MatrixX3d posed;
    Skinning(f.tmpl).Apply(good, &posed);
    const Eigen::Vector3d centre = posed.colwise().mean().transpose();
    struct Wrong {
      const char* name;
      Pose pose;
    };
    std::vector<Wrong> wrong;
    {  // Upside down about the body centre (rotation about the horizontal axis X).
      Pose p = good;
      const Eigen::Matrix3d flip =
          Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
      p.rotation = flip * good.rotation;
      p.translation = centre + flip * (good.translation - centre);
      wrong.push_back({"upside down", p});
    }
    {
      Pose p = good;
      p.translation.x() += 1.0;
      wrong.push_back({"1 m beside", p});
    }
    {
      Pose p = good;
      p.translation.z() += f.wall_z + 0.15 - centre.z();
      wrong.push_back({"on the wall", p});
    }
    for (const Wrong& w : wrong) {
      const FitQuality q = EvaluatePose(w.pose, i);
      std::printf("frame %d %-12s %s\n", i, w.name, q.BriefReport().c_str());
      EXPECT_EQ(q.label, FitQualityLabel::kLost)
          << w.name << ", frame " << i << ": " << q.BriefReport();
      EXPECT_LT(q.score, EvaluatePose(good, i).score) << w.name;
    }
  }
}

// At high sensor noise (2.5 cm along the viewing ray, the virtual Kinect's `--noise high`) the
// true surface keeps its support: each raster pixel's observed depth is the median of its scan
// points, not their minimum, which lies about 1.5-1.8 sigmas in front of the surface and put
// every right fit out of the 3 cm tolerance (all frames lost). The wrong fits stay lost.
TEST(FitQualityTest, TheTruthKeepsItsSupportInNoisyScans) {
  const Fixture& f = GetFixture();
  std::mt19937_64 rng(7);
  std::normal_distribution<double> noise(0.0, 0.025);
  const Eigen::Vector3d eye = f.data.depth_camera.Center();
  for (int i : {0, kFrames - 1}) {
    Scan noisy = f.data.scans[i];
    for (int s = 0; s < noisy.size(); ++s) {
      const Eigen::Vector3d p = noisy.points.row(s).transpose();
      noisy.points.row(s) = (p + noise(rng) * (p - eye).normalized()).transpose();
    }
    const FitQuality truth = EvaluateFitQuality(f.subject_posed[i], f.subject.triangles, noisy,
                                                f.data.depth_camera, FitQualityOptions());
    std::printf("frame %d, 2.5 cm noise: truth %s\n", i, truth.BriefReport().c_str());
    EXPECT_NE(truth.label, FitQualityLabel::kLost) << truth.BriefReport();
    EXPECT_GT(truth.support_fraction, 0.65) << truth.BriefReport();
    Pose wall = f.fitted[i];
    wall.translation.z() += f.wall_z + 0.15 - wall.translation.z();
    Eigen::MatrixX3d posed;
    Skinning(f.tmpl).Apply(wall, &posed);
    const FitQuality wrong = EvaluateFitQuality(posed, f.tmpl.triangles, noisy, f.data.depth_camera,
                                                FitQualityOptions());
    EXPECT_EQ(wrong.label, FitQualityLabel::kLost) << wrong.BriefReport();
  }
}

// Per-part support (fitting.quality.part_min_support, off by default): a leg raised sideways
// into empty space is an unsupported part, and the frame is not good although the rest of the
// fit still explains the scan; the tracked fit has no unsupported part.
TEST(FitQualityTest, ALegRaisedIntoEmptySpaceIsAnUnsupportedPart) {
  const Fixture& f = GetFixture();
  FitQualityOptions options;
  options.part_min_support = 0.25;
  const Eigen::VectorXi parts = FitQualityParts(f.tmpl.vertex_joint, f.tmpl.JointNames(), options);
  const int l_hip = f.tmpl.FindJoint("l_hip");
  const int l_ankle = f.tmpl.FindJoint("l_ankle");
  for (Eigen::Index v = 0; v < parts.size(); ++v) {
    if (f.tmpl.vertex_joint[v] == l_ankle) {
      EXPECT_EQ(parts[v], -1);  // part_ignore: the feet
    }
  }
  const auto quality = [&](const Pose& pose, int frame) {
    Eigen::MatrixX3d posed;
    Skinning(f.tmpl).Apply(pose, &posed);
    return EvaluateFitQuality(posed, f.tmpl.triangles, f.data.scans[frame], f.data.depth_camera,
                              options, &parts);
  };
  for (int i : {0, kFrames / 2}) {
    const FitQuality fitted = quality(f.fitted[i], i);
    EXPECT_EQ(fitted.unsupported_parts, 0) << fitted.BriefReport();
    Pose raised = f.fitted[i];
    raised.joint_rotations[l_hip] =
        Eigen::AngleAxisd(1.4, Eigen::Vector3d::UnitZ()).toRotationMatrix();  // abducted 80 deg
    const FitQuality q = quality(raised, i);
    std::printf("frame %d leg raised: %s\n", i, q.BriefReport().c_str());
    EXPECT_GE(q.unsupported_parts, 1) << q.BriefReport();
    EXPECT_NE(q.label, FitQualityLabel::kGood) << q.BriefReport();
  }
  Eigen::VectorXi wrong_size = parts.head(10);
  Eigen::MatrixX3d posed;
  Skinning(f.tmpl).Apply(f.fitted[0], &posed);
  EXPECT_THROW(EvaluateFitQuality(posed, f.tmpl.triangles, f.data.scans[0], f.data.depth_camera,
                                  options, &wrong_size),
               Error);
}

TEST(FitQualityTest, EmptyScanAndInvisibleModel) {
  const Fixture& f = GetFixture();
  Scan empty;
  empty.points.resize(0, 3);
  empty.normals.resize(0, 3);
  Eigen::MatrixX3d posed;
  Skinning(f.tmpl).Apply(f.fitted[0], &posed);
  const FitQuality q =
      EvaluateFitQuality(posed, f.tmpl.triangles, empty, f.data.depth_camera, FitQualityOptions());
  EXPECT_EQ(q.inlier_fraction, 0.0);
  EXPECT_EQ(q.support_fraction, 0.0);  // nothing observed under the model
  EXPECT_EQ(q.label, FitQualityLabel::kLost);
  // Behind the camera: nothing rendered.
  Pose behind = f.fitted[0];
  behind.translation.z() += 10.0;
  Skinning(f.tmpl).Apply(behind, &posed);
  const FitQuality b = EvaluateFitQuality(posed, f.tmpl.triangles, f.data.scans[0],
                                          f.data.depth_camera, FitQualityOptions());
  EXPECT_EQ(b.model_pixels, 0);
  EXPECT_EQ(b.label, FitQualityLabel::kLost);
}

TEST(FitQualityTest, InvalidInputThrows) {
  const Fixture& f = GetFixture();
  FitQualityOptions bad;
  bad.inlier_distance = 0.0;
  std::string error;
  EXPECT_FALSE(bad.IsValid(&error));
  EXPECT_NE(error.find("inlier_distance"), std::string::npos);
  FitQualityOptions no_gap;
  no_gap.layer_gap = 0.0;
  EXPECT_FALSE(no_gap.IsValid(&error));
  EXPECT_NE(error.find("layer_gap"), std::string::npos) << error;
  Eigen::MatrixX3d posed;
  Skinning(f.tmpl).Apply(f.fitted[0], &posed);
  EXPECT_THROW(
      EvaluateFitQuality(posed, f.tmpl.triangles, f.data.scans[0], f.data.depth_camera, bad),
      Error);
  Eigen::MatrixX3i tris = f.tmpl.triangles;
  tris(0, 0) = static_cast<int>(posed.rows());
  EXPECT_THROW(
      EvaluateFitQuality(posed, tris, f.data.scans[0], f.data.depth_camera, FitQualityOptions()),
      Error);
  EXPECT_STREQ(FitQualityLabelName(FitQualityLabel::kDoubtful), "doubtful");
}

}  // namespace
}  // namespace artex
