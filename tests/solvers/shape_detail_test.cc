#include "solvers/shape_detail.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <utility>

#include "models/error.h"
#include "models/normals.h"
#include "models/skinning.h"
#include "models/so3.h"
#include "solvers/shape_estimator.h"
#include "tests/solvers/fitting_test_util.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

using testing_util::CoarseTemplate;

// A camera at the origin looking along +Z that sees the whole body 2.5 m away.
PinholeCamera WideCamera() {
  PinholeCamera camera;
  camera.fx = camera.fy = 300.0;
  return camera;
}

// The subject turned by `yaw_deg` about +Y, 2.5 m in front of the camera.
Pose Turned(const Template& t, double yaw_deg) {
  Pose p = Pose::Identity(t.num_joints());
  p.translation = Eigen::Vector3d(0.0, 0.0, 2.5);
  p.rotation = ExpSO3(Eigen::Vector3d(0.0, yaw_deg * M_PI / 180.0, 0.0));
  return p;
}

// A smooth field along the body's height: +-6 mm, 1.26 m per period.
Eigen::VectorXd Bumps(const Template& t) {
  Eigen::VectorXd d(t.num_vertices());
  for (int v = 0; v < t.num_vertices(); ++v) d[v] = 0.006 * std::sin(5.0 * t.vertices(v, 1));
  return d;
}

struct Frames {
  std::vector<Pose> poses;
  std::vector<Scan> scans;
  std::vector<const Scan*> pointers;
};

// The subject seen from four sides.
Frames FourSides(const Template& posed_as, const Template& subject) {
  Frames f;
  for (double yaw : {0.0, 90.0, 180.0, 270.0}) {
    f.poses.push_back(Turned(posed_as, yaw));
    f.scans.push_back(testing_util::VertexScan(subject, f.poses.back()));
  }
  for (const Scan& s : f.scans) f.pointers.push_back(&s);
  return f;
}

// A template fitted to scans of a subject whose surface is the template's moved along its
// normals by a known smooth field recovers that field (no bias bins: the field is not
// zero-mean); with the frames' means removed, the field less its mean is recovered instead.
TEST(ShapeDetailTest, RecoversKnownOffsetsFromNoiseFreeScans) {
  const Template& t = CoarseTemplate();
  const Eigen::VectorXd truth = Bumps(t);
  const Template subject = ApplySurfaceDetail(t, truth);
  const Frames frames = FourSides(t, subject);
  ShapeDetailOptions options;
  options.bias_bins = 0;
  options.smoothness = 0.5;
  options.iterations = 3;
  ShapeDetailSummary summary;
  const Eigen::VectorXd d =
      EstimateSurfaceDetail(t, frames.pointers, frames.poses, WideCamera(), options, &summary);
  ASSERT_EQ(d.size(), t.num_vertices());
  EXPECT_EQ(summary.frames, 4);
  EXPECT_EQ(summary.iterations, 3);
  EXPECT_GT(summary.observed_vertices, t.num_vertices() * 8 / 10);
  const double rms_truth = std::sqrt(truth.squaredNorm() / truth.size());
  const double rms_error = std::sqrt((d - truth).squaredNorm() / truth.size());
  EXPECT_LT(rms_error, 0.15 * rms_truth) << "rms truth " << rms_truth << ", error " << rms_error;
  EXPECT_LT(summary.residual_after, 0.2 * summary.residual_before);
  EXPECT_EQ(summary.at_bound, 0);

  // With a constant 4 mm more, the frames' means take the constant away.
  const Eigen::VectorXd shifted = (truth.array() + 0.004).matrix();
  const Frames moved = FourSides(t, ApplySurfaceDetail(t, shifted));
  options.bias_bins = 1;
  options.bias_per_segment = false;
  const Eigen::VectorXd centred =
      EstimateSurfaceDetail(t, moved.pointers, moved.poses, WideCamera(), options, &summary);
  EXPECT_NEAR(summary.frame_mean_residual, 0.004 + truth.mean(), 0.002);
  const Eigen::VectorXd expected = (truth.array() - truth.mean()).matrix();
  const double rms_centred = std::sqrt((centred - expected).squaredNorm() / truth.size());
  EXPECT_LT(rms_centred, 0.25 * rms_truth) << rms_centred;
  // The bound holds.
  options.max_offset = 0.002;
  const Eigen::VectorXd bounded =
      EstimateSurfaceDetail(t, moved.pointers, moved.poses, WideCamera(), options, &summary);
  EXPECT_LE(bounded.cwiseAbs().maxCoeff(), 0.002);
  EXPECT_GT(summary.at_bound, 0);

  // By default each segment's mean (per facing bin) is taken away: a field constant on every
  // segment (a segment's size, the girths' part) leaves next to nothing.
  Eigen::VectorXd sizes(t.num_vertices());
  for (int v = 0; v < t.num_vertices(); ++v) sizes[v] = 0.003 * (t.vertex_joint[v] % 3 - 1);
  const Frames sized = FourSides(t, ApplySurfaceDetail(t, sizes));
  const Eigen::VectorXd left = EstimateSurfaceDetail(t, sized.pointers, sized.poses, WideCamera(),
                                                     ShapeDetailOptions(), &summary);
  const double rms_sizes = std::sqrt(sizes.squaredNorm() / sizes.size());
  EXPECT_LT(std::sqrt(left.squaredNorm() / left.size()), 0.25 * rms_sizes);
  EXPECT_GT(summary.observations, t.num_vertices());
  ShapeDetailOptions unbinned;
  unbinned.bias_bins = 0;
  const Eigen::VectorXd kept =
      EstimateSurfaceDetail(t, sized.pointers, sized.poses, WideCamera(), unbinned, &summary);
  EXPECT_GT(std::sqrt(kept.squaredNorm() / kept.size()), 0.75 * rms_sizes);
}

// Scans of the template itself give no offsets, and the template is unchanged by them.
TEST(ShapeDetailTest, TheTemplatesOwnScansGiveNoOffsets) {
  const Template& t = CoarseTemplate();
  const Frames frames = FourSides(t, t);
  ShapeDetailSummary summary;
  const Eigen::VectorXd d = EstimateSurfaceDetail(t, frames.pointers, frames.poses, WideCamera(),
                                                  ShapeDetailOptions(), &summary);
  EXPECT_LT(d.cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT(summary.residual_before, 1e-9);
  EXPECT_GT(summary.observations, 0);
  const Template same = ApplySurfaceDetail(t, d);
  EXPECT_LT((same.vertices - t.vertices).cwiseAbs().maxCoeff(), 1e-9);
  // No frames: no offsets.
  const Eigen::VectorXd none =
      EstimateSurfaceDetail(t, {}, {}, WideCamera(), ShapeDetailOptions(), &summary);
  EXPECT_EQ(none.size(), t.num_vertices());
  EXPECT_EQ(none.cwiseAbs().maxCoeff(), 0.0);
}

TEST(ShapeDetailTest, RejectsBadInput) {
  const Template& t = CoarseTemplate();
  const Frames frames = FourSides(t, t);
  ShapeDetailOptions bad;
  bad.max_tangential = 0.0;
  std::string why;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_NE(why.find("shape.detail.max_tangential"), std::string::npos) << why;
  EXPECT_THROW(EstimateSurfaceDetail(t, frames.pointers, frames.poses, WideCamera(), bad), Error);
  bad = ShapeDetailOptions();
  bad.iterations = 0;
  EXPECT_FALSE(bad.IsValid(&why));
  bad = ShapeDetailOptions();
  bad.prior_weight = 0.0;  // unseen vertices would be undetermined
  EXPECT_FALSE(bad.IsValid(&why));
  std::vector<Pose> fewer(frames.poses.begin(), frames.poses.end() - 1);
  EXPECT_THROW(EstimateSurfaceDetail(t, frames.pointers, fewer, WideCamera(), ShapeDetailOptions()),
               Error);
  std::vector<Pose> wrong = frames.poses;
  wrong[1] = Pose::Identity(t.num_joints() - 1);
  EXPECT_THROW(EstimateSurfaceDetail(t, frames.pointers, wrong, WideCamera(), ShapeDetailOptions()),
               Error);
  EXPECT_THROW(ApplySurfaceDetail(t, Eigen::VectorXd::Zero(t.num_vertices() - 1)), Error);
  ShapeOptions shape;
  shape.detail.smoothness = -1.0;
  EXPECT_FALSE(shape.IsValid(&why));
  EXPECT_NE(why.find("shape.detail.smoothness"), std::string::npos) << why;
}

// With detail on, the estimator's subject template after the last round is the shape model's
// with the estimated offsets along its normals, estimated from that round's frames and
// detail.frames more (pending until then), or from those kept when FinishDetail is called
// first; without a depth camera none are estimated.
TEST(ShapeDetailTest, TheEstimatorsSubjectTemplateCarriesTheDetail) {
  const Template& t = CoarseTemplate();
  const Template subject = ApplySurfaceDetail(t, Bumps(t));
  ShapeOptions options;
  options.mode = ShapeMode::kBonesGirth;
  options.calibration_frames = 4;
  options.calibration_stride = 1;
  options.calibration_rounds = 1;
  options.iterations_per_stage = 2;
  options.max_fit_vertices = 0;
  options.detail.enabled = true;
  // more: frames after the round (-1: no depth camera); finish: the sequence ends after one.
  for (const auto& [more, finish] : {std::pair(0, false), std::pair(2, false),
                                     std::pair(3, true), std::pair(-1, false)}) {
    options.detail.frames = std::max(more, 0);
    ShapeEstimator estimator(t, options);
    if (more >= 0) estimator.SetDepthCamera(WideCamera(), OutOfViewOptions());
    const Frames frames = FourSides(t, subject);
    for (int f = 0; f < 4; ++f) {
      const bool changed = estimator.AddFrame(frames.scans[f], frames.poses[f], true);
      EXPECT_EQ(changed, f == 3) << f;
    }
    EXPECT_TRUE(estimator.calibrated());
    EXPECT_EQ(estimator.DetailPending(), more > 0);
    for (int f = 0; f < (finish ? 1 : more); ++f) {
      EXPECT_EQ(estimator.detail().size(), 0);
      const bool changed = estimator.AddFrame(frames.scans[f], frames.poses[f], true);
      EXPECT_EQ(changed, f == more - 1) << f;
    }
    EXPECT_EQ(estimator.FinishDetail(), finish);
    EXPECT_FALSE(estimator.DetailPending());
    EXPECT_FALSE(estimator.FinishDetail());  // nothing left to do
    const Template shaped = estimator.model().Apply(estimator.parameters());
    const Template with = estimator.SubjectTemplate();
    if (more < 0) {
      EXPECT_EQ(estimator.detail().size(), 0);
      EXPECT_EQ(with.vertices, shaped.vertices);
      continue;
    }
    ASSERT_EQ(estimator.detail().size(), t.num_vertices());
    EXPECT_GT(estimator.detail().cwiseAbs().maxCoeff(), 1e-3);
    EXPECT_EQ(with.vertices, ApplySurfaceDetail(shaped, estimator.detail()).vertices);
    EXPECT_EQ(with.triangles, shaped.triangles);
    EXPECT_EQ(estimator.detail_summary().frames, 4 + (finish ? 1 : more));
  }
}

}  // namespace
}  // namespace artex
