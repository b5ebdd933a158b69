// Tracking real Kinect recordings as users bring them (TUM RGB-D layout, camera.yaml, no
// calibration.yaml, no empty-scene frames, no ground truth), read in place from the shared
// data folder and skipped when it is absent (docs/real-data.md). What must hold without
// ground truth: the world frame stands the template up (head above chest in the image, in
// every frame), the foreground is one person, and the template lies on that person.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <utility>
#include <vector>

#include "experiments/config.h"
#include "experiments/pipeline.h"
#include "experiments/pose_csv.h"
#include "models/skinning.h"
#include "models/template_generator.h"
#include "models/template_io.h"
#include "sensors/calibration.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

fs::path Recording(const std::string& name) { return fs::path(ARTEX_SHARED_DATA) / "real" / name; }

fs::path OutDir(const std::string& name) {
  return fs::temp_directory_path() / ("artex_real_" + name + "_" + std::to_string(::getpid()));
}

struct TrackedRun {
  PipelineResult result;
  fs::path out;
};

TrackedRun Track(const std::string& name,
                 const std::vector<std::pair<std::string, std::string>>& settings = {}) {
  TrackedRun run;
  run.out = OutDir(name);
  fs::remove_all(run.out);
  Config config;
  config.Set("pipeline.texture", "false");
  config.Set("pipeline.export_glb", "false");
  config.Set("pipeline.export_foreground", "true");
  for (const auto& [key, value] : settings) config.Set(key, value);
  const PipelineOptions options = LoadPipelineOptions(config);
  run.result = RunPipeline(Recording(name).string(), "", options, config, run.out.string());
  std::printf("[%s] %zu frames: %d good, %d doubtful, %d lost (%d failed), %d initialisations\n",
              name.c_str(), run.result.frames.size(), run.result.good_frames,
              run.result.doubtful_frames, run.result.lost_frames, run.result.failed_frames,
              run.result.initialisations);
  for (const FrameRecord& f : run.result.frames) {
    std::printf("  frame %d: %s, scale %.3f, subject pixels %d\n", f.frame,
                f.quality.BriefReport().c_str(), f.fit.scale, f.segmentation.subject_pixels);
  }
  return run;
}

// Image rows of the head and chest joints of every fitted frame, projected with the run's
// calibration (its estimated world frame).
struct Uprightness {
  int frames = 0;
  int upright = 0;  // head above the chest in the image
};

Uprightness CheckUpright(const TrackedRun& run) {
  // A shape.retrack run tracked with the subject's template of its first pass.
  const fs::path subject = run.out / "shape_pass" / "subject.glb";
  const Template tmpl = fs::exists(subject) ? ReadTemplateGlb(subject.string()) : GenerateTemplate();
  const Skinning skinning(tmpl);
  const Calibration calibration = ReadCalibration((run.out / "calibration.yaml").string());
  const int head = tmpl.FindJoint("head"), chest = tmpl.FindJoint("chest");
  Uprightness u;
  for (const auto& [frame, pose] :
       ReadPoseCsv((run.out / "poses.csv").string(), tmpl.num_joints())) {
    Eigen::MatrixX3d joints;
    skinning.PosedJointCenters(pose, &joints);
    const Eigen::Vector2d h = calibration.depth.Project(joints.row(head).transpose());
    const Eigen::Vector2d c = calibration.depth.Project(joints.row(chest).transpose());
    ++u.frames;
    u.upright += h.y() < c.y() - 10.0;  // rows grow downwards
  }
  return u;
}

// Frames whose fit raises a shin into the image: skeltrack shows the upper body, the knees are
// below the image border, so a shin in view is a leg lifted to explain a hand or the scan's edge.
int FramesWithAShinInView(const TrackedRun& run) {
  const fs::path subject = run.out / "shape_pass" / "subject.glb";
  const Template tmpl = fs::exists(subject) ? ReadTemplateGlb(subject.string()) : GenerateTemplate();
  const Skinning skinning(tmpl);
  const Calibration calibration = ReadCalibration((run.out / "calibration.yaml").string());
  const int shins[] = {tmpl.FindJoint("l_knee"), tmpl.FindJoint("r_knee")};
  const PinholeCamera& camera = calibration.depth;
  int frames = 0;
  for (const auto& [frame, pose] :
       ReadPoseCsv((run.out / "poses.csv").string(), tmpl.num_joints())) {
    Eigen::MatrixX3d posed;
    skinning.Apply(pose, &posed);
    bool raised = false;
    for (int shin : shins) {
      int total = 0, inside = 0;
      for (Eigen::Index v = 0; v < posed.rows(); ++v) {
        if (tmpl.vertex_joint[v] != shin) continue;
        ++total;
        double z = 0.0;
        const Eigen::Vector2d p = camera.Project(posed.row(v).transpose(), &z);
        inside += z > 0.0 && p.x() >= 0 && p.y() >= 0 && p.x() < camera.width &&
                  p.y() < camera.height;
      }
      raised |= total > 0 && inside > 0.25 * total;
    }
    if (raised) std::printf("  frame %d: a shin in view\n", frame);
    frames += raised;
  }
  return frames;
}

TEST(RealRecordingsTest, FivePeopleOneSubjectUprightOnThatPerson) {
  if (!fs::exists(Recording("pcl-five-people") / "depth.txt")) {
    GTEST_SKIP() << "real recordings absent (" << Recording("pcl-five-people") << ")";
  }
  const TrackedRun run = Track("pcl-five-people");
  ASSERT_EQ(run.result.frames.size(), 1u);
  const FrameRecord& f = run.result.frames[0];
  // Five people in the room: several person-sized components, one chosen.
  EXPECT_GE(f.segmentation.person_sized, 3);
  EXPECT_GT(f.segmentation.subject_height, 1.3);
  EXPECT_LT(f.segmentation.subject_height, 2.0);
  const cv::Mat mask =
      cv::imread((run.out / "foreground" / "000000.png").string(), cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(mask.empty());
  cv::Mat labels, stats, centroids;
  const int n = cv::connectedComponentsWithStats(mask, labels, stats, centroids, 8);
  int large = 0;
  for (int k = 1; k < n; ++k) large += stats.at<int>(k, cv::CC_STAT_AREA) > 500;
  EXPECT_EQ(large, 1) << "the foreground is one person";
  // One person wide: well under two shoulder widths at its depth.
  EXPECT_LT(f.segmentation.subject_width, 0.8);
  const Uprightness u = CheckUpright(run);
  EXPECT_EQ(u.upright, u.frames);
  // The template lies on that person: most of its vertices project into the foreground.
  const Template tmpl = GenerateTemplate();
  const Calibration calibration = ReadCalibration((run.out / "calibration.yaml").string());
  const auto poses = ReadPoseCsv((run.out / "poses.csv").string(), tmpl.num_joints());
  Eigen::MatrixX3d posed;
  Skinning(tmpl).Apply(poses[0].second, &posed);
  int inside = 0;
  for (Eigen::Index v = 0; v < posed.rows(); ++v) {
    const Eigen::Vector2d p = calibration.depth.Project(posed.row(v).transpose());
    const int x = static_cast<int>(std::lround(p.x())), y = static_cast<int>(std::lround(p.y()));
    inside += x >= 0 && y >= 0 && x < mask.cols && y < mask.rows && mask.at<uint8_t>(y, x) > 0;
  }
  std::printf("[pcl-five-people] %.1f%% of the template's vertices project into the foreground\n",
              100.0 * inside / posed.rows());
  EXPECT_GT(inside, 0.6 * posed.rows());
  fs::remove_all(run.out);
}

TEST(RealRecordingsTest, SkeltrackEveryFrameUpright) {
  if (!fs::exists(Recording("skeltrack") / "depth.txt")) {
    GTEST_SKIP() << "real recordings absent (" << Recording("skeltrack") << ")";
  }
  // The twelve frames are stills of different poses, not a continuous recording: with the
  // built-in defaults (pipeline.reinitialise_on: auto) the re-initialisations that replace
  // tracking make every doubted frame initialised again (docs/real-data.md).
  const TrackedRun run = Track("skeltrack");
  ASSERT_EQ(run.result.frames.size(), 12u);
  // Measured: 6 good, 6 doubtful, 0 lost, no leg raised, mean depth residual 38.0 mm (before
  // the neck and head were coupled, fitting.joint_coupling: 7 good, 37.9 mm, with a head leaning
  // into the shoulder and two arms twisted behind the body; before the legs below the image
  // were held, fitting.out_of_view, with reinitialise_on doubtful: 6 good, 6 doubtful, legs
  // lifted beside the body; with the former default reinitialise_on lost: 3 good, 8 doubtful,
  // 1 lost). The labels are knife-edge (the shape test below): the residual is bounded too.
  EXPECT_EQ(run.result.lost_frames, 0);
  EXPECT_GE(run.result.good_frames, 6) << "good for half of the frames";
  double residual = 0.0;
  for (const FrameRecord& f : run.result.frames) residual += f.quality.depth_residual_m;
  EXPECT_LT(residual / static_cast<double>(run.result.frames.size()), 0.0395)
      << "mean depth residual (m)";
  EXPECT_EQ(FramesWithAShinInView(run), 0) << "the legs stay below the image";
  EXPECT_EQ(run.result.skipped_frames, 0);
  const Uprightness u = CheckUpright(run);
  EXPECT_EQ(u.frames, 12);
  EXPECT_EQ(u.upright, u.frames) << "head above the chest in every frame";
  // The subject was cut out of its background: the foreground keeps nearly all of it.
  for (const FrameRecord& f : run.result.frames) EXPECT_GT(f.segmentation.subject_pixels, 30000);
  fs::remove_all(run.out);
}

// The template's shape is not this person's (a correct fit leaves 12-18 % of the scan more than
// 2.5 cm away, docs/real-data.md): calibrating the subject's shape and tracking the recording
// again with it (shape.retrack) fits every frame upright, none lost, the legs below the image.
TEST(RealRecordingsTest, SkeltrackWithTheSubjectsShapeUprightAndClose) {
  if (!fs::exists(Recording("skeltrack") / "depth.txt")) {
    GTEST_SKIP() << "real recordings absent (" << Recording("skeltrack") << ")";
  }
  // The twelve stills are twelve poses: every accepted frame calibrates (stride 1). With the
  // default stride 2 the three rounds need 9 of the 12 frames accepted after the scale settled,
  // which is knife-edge: with the neck and head coupled (fitting.joint_coupling) one frame
  // fewer was accepted and the shape never calibrated.
  const TrackedRun run = Track("skeltrack", {{"pipeline.reinitialise_on", "doubtful"},
                                             {"shape.mode", "bones_girth"},
                                             {"shape.retrack", "true"},
                                             {"shape.calibration_stride", "1"}});
  ASSERT_EQ(run.result.frames.size(), 12u);
  ASSERT_TRUE(fs::exists(run.out / "shape_pass" / "subject.glb"));
  ASSERT_TRUE(fs::exists(run.out / "shape_pass" / "frames.csv"));
  EXPECT_GE(run.result.shape_calibrated_frame, 0);
  // How many of the 12 frames (11 of them initialisations) come out good is knife-edge: fitting
  // budgets changed by under 1 % (tracking_max_fit_vertices 1990, max_fit_vertices 2990,
  // scale_sample_max_scan_points 1490, init.icp.max_scan_points 1490) gave 4 to 9 good frames,
  // with the E-step's clouds per tracking radius as with one per frame
  // (fitting.tracking_shared_cloud), and the defaults 7 and 6; the frames' mean depth residual
  // stayed within 35.8-38.4 mm in all ten runs (docs/fitting-speed.md, "One cloud per tracking
  // frame"). So the mean residual is bounded, and a third of the frames must be good. On a later
  // machine the same build gave 39.2 mm; with the observed depth as the median of each raster
  // pixel's front layer instead of its nearest point (fitting.quality.layer_gap) 39.5 mm: the
  // first pass's poses are the same, its frames' residuals move by -0.7 to +1.0 mm, and frame 8's
  // re-initialisation chose the template facing the camera, as in the other frames, instead of
  // facing away (docs/fitting.md, "Initialisation and fit quality").
  double residual = 0.0;
  for (const FrameRecord& f : run.result.frames) residual += f.quality.depth_residual_m;
  residual /= static_cast<double>(run.result.frames.size());
  EXPECT_LT(residual, 0.0405) << "mean depth residual (m)";
  EXPECT_GE(run.result.good_frames, 4) << "good for a third of the frames";
  EXPECT_LE(FramesWithAShinInView(run), 1) << "the legs stay below the image";
  EXPECT_EQ(run.result.lost_frames, 0);
  const Uprightness u = CheckUpright(run);
  EXPECT_EQ(u.frames, 12);
  EXPECT_EQ(u.upright, u.frames) << "head above the chest in every frame";
  fs::remove_all(run.out);
}

}  // namespace
}  // namespace artex
