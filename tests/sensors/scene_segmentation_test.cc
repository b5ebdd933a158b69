#include "sensors/scene_segmentation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "models/error.h"
#include "models/skinning.h"
#include "sensors/preprocess.h"
#include "sensors/virtual_kinect.h"
#include "tests/sensors/small_synth.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
constexpr double kDeg = 3.14159265358979323846 / 180.0;

SynthOptions SmallOptions() { return testing_util::SmallSynthOptions(3, 0); }

const SynthSubject& SmallSubject() {
  static const SynthSubject subject = PrepareSynthSubject(SmallOptions());
  return subject;
}

struct Rendered {
  Calibration calibration;
  cv::Mat depth;
  DepthDiagnostics diagnostics;
};

// One virtual Kinect frame of the default scene (floor y = 0, back wall, subject near the
// origin) seen from `eye`.
Rendered Render(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, int frame = 1) {
  SynthOptions o = SmallOptions();
  o.kinect.depth_eye = eye;
  o.kinect.depth_target = target;
  const SynthSubject& s = SmallSubject();
  Eigen::MatrixX3d posed;
  Skinning(s.subject).Apply(s.poses[frame], &posed);
  const VirtualKinect kinect(o.kinect, s.subject, s.texture_bgr);
  Rendered r;
  r.calibration = kinect.calibration();
  r.depth = kinect.RenderDepth(frame, &posed, &r.diagnostics);
  return r;
}

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) / kDeg;
}

double Iou(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat i, u;
  cv::bitwise_and(a, b, i);
  cv::bitwise_or(a, b, u);
  const int un = cv::countNonZero(u);
  return un ? static_cast<double>(cv::countNonZero(i)) / un : 0.0;
}

TEST(SceneSegmentationTest, FindsTheFloorAndTheWallOfTheVirtualRoom) {
  const Rendered r = Render({0.3, 1.2, 2.5}, {0.0, 1.0, 0.0});
  const Eigen::Matrix3d rot = r.calibration.depth.world_to_camera.linear();
  const Eigen::Vector3d true_up = rot * Eigen::Vector3d::UnitY();
  const std::vector<ScenePlane> planes = DetectScenePlanes(
      r.depth, r.calibration.depth, r.calibration.depth_distortion, r.calibration.depth_scale,
      Eigen::Vector3d(0, -1, 0), PlaneDetectionOptions());
  int floors = 0, walls = 0;
  for (const ScenePlane& p : planes) {
    if (p.kind == PlaneKind::kFloor) {
      ++floors;
      EXPECT_LT(AngleDeg(p.normal, true_up), 1.5);
      EXPECT_NEAR(p.offset, 1.2, 0.02);  // the camera's height above the floor
    } else if (p.kind == PlaneKind::kWall) {
      ++walls;
      const Eigen::Vector3d wall_normal = rot * Eigen::Vector3d::UnitZ();
      EXPECT_LT(AngleDeg(p.normal, wall_normal), 1.5);
      EXPECT_NEAR(p.offset, 2.5 + 1.5, 0.05);  // wall at z = -1.5, camera at z = 2.5
    }
  }
  EXPECT_EQ(floors, 1);
  EXPECT_EQ(walls, 1);
}

TEST(SceneSegmentationTest, WorldFrameFromTheFloorStandsUpAndFacesTheCamera) {
  // Cameras at several heights, pitched down: up and height from the floor alone.
  for (const Eigen::Vector3d& eye :
       {Eigen::Vector3d(0.3, 1.6, 2.8), Eigen::Vector3d(-0.5, 0.8, 3.0)}) {
    const Rendered r = Render(eye, {0.0, 0.9, 0.0});
    const Eigen::Vector3d true_up =
        r.calibration.depth.world_to_camera.linear() * Eigen::Vector3d::UnitY();
    const WorldFrameEstimate e =
        EstimateWorldFrame(r.depth, r.calibration.depth, r.calibration.depth_distortion,
                           r.calibration.depth_scale, std::nullopt, WorldFrameOptions());
    std::ostringstream planes;
    for (const ScenePlane& p : e.planes)
      planes << PlaneKindName(p.kind) << " " << p.extent[0] << "x" << p.extent[1] << " cover "
             << p.coverage << " fraction " << p.inlier_fraction << "; ";
    EXPECT_EQ(e.source, WorldFrameSource::kFloor) << planes.str();
    EXPECT_LT(AngleDeg(e.up_camera, true_up), 1.5);
    EXPECT_NEAR(e.camera_height, eye.y(), 0.03);
    // World +Z points from the scene towards the camera (horizontally).
    const Eigen::Vector3d z_world_in_camera = e.world_to_camera.linear().col(2);
    EXPECT_LT(z_world_in_camera.z(), -0.5);
    EXPECT_NEAR(z_world_in_camera.dot(e.up_camera), 0.0, 1e-9);
    // The camera centre is at height camera_height above the origin.
    const Eigen::Vector3d centre = e.world_to_camera.inverse().translation();
    EXPECT_NEAR(centre.y(), e.camera_height, 1e-9);
  }
}

TEST(SceneSegmentationTest, NoFloorFallsBackToGravityThenToTheCameraConvention) {
  cv::Mat depth(120, 160, CV_16UC1, cv::Scalar(0));
  PinholeCamera cam;
  cam.width = 160;
  cam.height = 120;
  cam.fx = cam.fy = 130;
  cam.cx = 79.5;
  cam.cy = 59.5;
  WorldFrameOptions o;
  const WorldFrameEstimate plain =
      EstimateWorldFrame(depth, cam, Distortion(), 1000.0, std::nullopt, o);
  EXPECT_EQ(plain.source, WorldFrameSource::kCameraConvention);
  EXPECT_LT(AngleDeg(plain.up_camera, {0, -1, 0}), 1e-9);
  EXPECT_NEAR(plain.camera_height, o.assumed_camera_height, 1e-12);
  // An identity world-to-camera never flips the template: world up maps to image up.
  EXPECT_LT((plain.world_to_camera.linear() * Eigen::Vector3d::UnitY() - Eigen::Vector3d(0, -1, 0))
                .norm(),
            1e-12);
  const Eigen::Vector3d tilted = Eigen::Vector3d(0.2, -1.0, 0.3).normalized();
  const WorldFrameEstimate g = EstimateWorldFrame(depth, cam, Distortion(), 1000.0, tilted, o);
  EXPECT_EQ(g.source, WorldFrameSource::kGravity);
  EXPECT_LT(AngleDeg(g.up_camera, tilted), 1e-9);
  EXPECT_GT(g.camera_pitch_deg, 10.0);  // up tilted towards +z: the camera looks down
}

TEST(SceneSegmentationTest, SegmentsTheSubjectWithoutBackgroundFrames) {
  const Rendered r = Render({0.3, 1.2, 2.5}, {0.0, 1.0, 0.0});
  const Eigen::Vector3d up =
      r.calibration.depth.world_to_camera.linear() * Eigen::Vector3d::UnitY();
  SubjectSegmenter seg(r.calibration.depth, r.calibration.depth_distortion,
                       r.calibration.depth_scale, up, SubjectSegmentationOptions());
  cv::Mat mask;
  SegmentationStats stats;
  seg.Segment(r.depth, &mask, &stats);
  cv::Mat truth = r.diagnostics.subject_mask.clone();
  truth.setTo(0, r.depth == 0);
  const double iou = Iou(mask, truth);
  EXPECT_GT(iou, 0.9) << "subject pixels " << stats.subject_pixels;
  EXPECT_GT(stats.subject_height, 1.4);
  EXPECT_LT(stats.subject_height, 1.9);
  // Everything in range would be the room: far more than the subject.
  EXPECT_GT(stats.candidate_pixels, 0);
  EXPECT_GT(cv::countNonZero(r.depth), 3 * cv::countNonZero(mask));
  // The next frame keeps the same subject.
  seg.Segment(Render({0.3, 1.2, 2.5}, {0.0, 1.0, 0.0}, 2).depth, &mask, &stats);
  EXPECT_TRUE(stats.tracked);
}

TEST(SceneSegmentationTest, NobodyInViewGivesAnEmptyMaskAndAChoiceLater) {
  SynthOptions o = SmallOptions();
  const SynthSubject& s = SmallSubject();
  const VirtualKinect kinect(o.kinect, s.subject, s.texture_bgr);
  const cv::Mat empty = kinect.RenderDepth(0, nullptr);
  const Eigen::Vector3d up =
      kinect.calibration().depth.world_to_camera.linear() * Eigen::Vector3d::UnitY();
  SubjectSegmenter seg(kinect.calibration().depth, kinect.calibration().depth_distortion,
                       kinect.calibration().depth_scale, up, SubjectSegmentationOptions());
  cv::Mat mask;
  SegmentationStats stats;
  seg.Segment(empty, &mask, &stats);
  EXPECT_EQ(stats.subject_pixels, 0);
  EXPECT_EQ(cv::countNonZero(mask), 0);
  // Zero depth everywhere: no plane, no subject, no crash.
  seg.Segment(cv::Mat(empty.size(), CV_16UC1, cv::Scalar(0)), &mask, &stats);
  EXPECT_EQ(stats.subject_pixels, 0);
  // The person enters: chosen anew.
  Eigen::MatrixX3d posed;
  Skinning(s.subject).Apply(s.poses[1], &posed);
  seg.Segment(kinect.RenderDepth(1, &posed), &mask, &stats);
  EXPECT_GT(stats.subject_pixels, 1000);
  EXPECT_FALSE(stats.tracked);
}

TEST(SceneSegmentationTest, RejectsBadOptionsAndImages) {
  SubjectSegmentationOptions o;
  o.max_depth = 0.1;
  std::string why;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("max_depth"), std::string::npos);
  o = SubjectSegmentationOptions();
  o.choice = SubjectChoice::kPixel;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("pixel"), std::string::npos);
  PinholeCamera cam;
  SubjectSegmenter seg(cam, Distortion(), 1000.0, {0, -1, 0}, SubjectSegmentationOptions());
  cv::Mat mask;
  EXPECT_THROW(seg.Segment(cv::Mat(10, 10, CV_16UC1), &mask), Error);
  EXPECT_THROW(seg.Segment(cv::Mat(480, 640, CV_32FC1), &mask), Error);
}

// Real recordings (read in place; skipped when absent).
struct RealFrame {
  cv::Mat depth;
  PinholeCamera camera;
  double depth_scale = 5000;
};

bool ReadRealFrame(const std::string& name, int index, RealFrame* out) {
  const fs::path dir = fs::path(ARTEX_SHARED_DATA) / "real" / name;
  if (!fs::exists(dir / "depth.txt")) return false;
  std::ifstream list(dir / "depth.txt");
  std::string line;
  int k = 0;
  while (std::getline(list, line)) {
    if (line.empty() || line[0] == '#') continue;
    if (k++ != index) continue;
    std::istringstream fields(line);
    double t;
    std::string file;
    fields >> t >> file;
    out->depth = cv::imread((dir / file).string(), cv::IMREAD_UNCHANGED);
    break;
  }
  out->camera.width = 640;
  out->camera.height = 480;
  out->camera.fx = out->camera.fy = 525.0;
  out->camera.cx = 319.5;
  out->camera.cy = 239.5;
  return !out->depth.empty();
}

TEST(SceneSegmentationRealTest, FivePeopleForegroundIsOnePersonOnAFloor) {
  RealFrame f;
  if (!ReadRealFrame("pcl-five-people", 0, &f)) GTEST_SKIP() << "real recordings absent";
  const WorldFrameEstimate e = EstimateWorldFrame(f.depth, f.camera, Distortion(), f.depth_scale,
                                                  std::nullopt, WorldFrameOptions());
  EXPECT_EQ(e.source, WorldFrameSource::kFloor) << e.Describe();
  EXPECT_LT(AngleDeg(e.up_camera, {0, -1, 0}), 45.0) << e.Describe();
  SubjectSegmenter seg(f.camera, Distortion(), f.depth_scale, e.up_camera,
                       SubjectSegmentationOptions());
  seg.SetPlanes(e.planes);
  cv::Mat mask;
  SegmentationStats stats;
  seg.Segment(f.depth, &mask, &stats);
  EXPECT_GE(stats.person_sized, 2) << "five people walk in the room";
  EXPECT_GT(stats.subject_pixels, 1500);
  EXPECT_GT(stats.subject_height, 1.0);
  EXPECT_LT(stats.subject_height, 2.1);
  // One person: the foreground is one connected blob, far smaller than the valid depth.
  cv::Mat labels;
  EXPECT_EQ(cv::connectedComponents(mask, labels, 8) - 1, 1);
  EXPECT_LT(cv::countNonZero(mask), cv::countNonZero(f.depth) / 4);
}

TEST(SceneSegmentationRealTest, SkeltrackIsAlreadyCutOutAndStaysWhole) {
  RealFrame f;
  if (!ReadRealFrame("skeltrack", 0, &f)) GTEST_SKIP() << "real recordings absent";
  const WorldFrameEstimate e = EstimateWorldFrame(f.depth, f.camera, Distortion(), f.depth_scale,
                                                  std::nullopt, WorldFrameOptions());
  for (const ScenePlane& p : e.planes) EXPECT_EQ(p.kind, PlaneKind::kOther) << e.Describe();
  EXPECT_EQ(e.source, WorldFrameSource::kCameraConvention);
  SubjectSegmenter seg(f.camera, Distortion(), f.depth_scale, e.up_camera,
                       SubjectSegmentationOptions());
  cv::Mat mask;
  SegmentationStats stats;
  seg.Segment(f.depth, &mask, &stats);
  EXPECT_GT(stats.subject_pixels, 0.9 * cv::countNonZero(f.depth));
}

}  // namespace
}  // namespace artex
