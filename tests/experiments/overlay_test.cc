// The overlay of a fitted template over input frames (experiments/overlay.h, `artex overlay`):
// the ground-truth pose of a synthetic sequence, rendered through the depth camera, covers the
// subject's depth pixels; the command writes one PNG per frame and a contact sheet, and takes
// the world frame from RUN/calibration.yaml when present.
#include "experiments/overlay.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>

#include "models/skinning.h"
#include "models/template_io.h"
#include "sensors/sequence.h"
#include "sensors/virtual_kinect.h"
#include "tests/solvers/virtual_kinect_scans.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

constexpr int kFrames = 5;

class OverlayTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(testing_util::FreshTempDir("overlay_test"));
    SynthOptions options = testing_util::SmallSequenceOptions(kFrames);
    options.motion.type = MotionType::kArmRaise;
    options.kinect.SetNoiseLevel(NoiseLevel::kOff);
    options.background_frames = 2;
    SynthesizeSequence(options, Sequence());
    // A "run" whose fitted poses are the ground truth.
    fs::create_directories(Run());
    fs::copy_file(Sequence() + "/groundtruth/poses.csv", Run() + "/poses.csv");
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
    dir_ = nullptr;
  }

  static std::string Sequence() { return (*dir_ / "sequence").string(); }
  static std::string Run() { return (*dir_ / "run").string(); }
  static std::string Subject() { return Sequence() + "/groundtruth/subject.glb"; }

  static int Cli(const std::string& args) {
    const std::string command = "'" + std::string(ARTEX_BINARY) + "' " + args + " > '" +
                                (*dir_ / "out.txt").string() + "' 2>&1";
    const int raw = std::system(command.c_str());
    return WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  }
  static std::string CliOutput() {
    std::ifstream in(*dir_ / "out.txt");
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  }

  static fs::path* dir_;
};

fs::path* OverlayTest::dir_ = nullptr;

double IoU(const cv::Mat& a, const cv::Mat& b) {
  const double inter = cv::countNonZero(a & b), uni = cv::countNonZero(a | b);
  return uni > 0 ? inter / uni : 0.0;
}

// Pixels where the subject is: valid depth in front of the empty scene by more than 5 cm.
cv::Mat SubjectPixels(const cv::Mat& depth, const cv::Mat& background, double depth_scale) {
  cv::Mat d, b;
  depth.convertTo(d, CV_64F, 1.0 / depth_scale);
  background.convertTo(b, CV_64F, 1.0 / depth_scale);
  return (depth > 0) & ((background == 0) | (d < b - 0.05));
}

TEST_F(OverlayTest, GroundTruthPoseCoversTheSubjectsDepthPixels) {
  SequenceReader reader(Sequence());
  const cv::Mat background = reader.ReadBackgroundFrames().at(0);
  const Template subject = ReadTemplateGlb(Subject());
  const Skinning skinning(subject);
  OverlayOptions options;
  options.background = OverlayBackground::kDepth;
  for (int i = 0; i < reader.num_frames(); ++i) {
    Frame frame;
    std::string warning;
    ASSERT_TRUE(reader.ReadFrame(i, &frame, &warning)) << warning;
    const Pose pose = reader.ReadGroundTruth(i).pose;
    Eigen::MatrixX3d posed;
    skinning.Apply(pose, &posed);
    const OverlayImage overlay =
        RenderOverlay(frame, reader.calibration(), subject, posed, options);
    ASSERT_EQ(overlay.image.size(), frame.depth.size());
    const cv::Mat truth = SubjectPixels(frame.depth, background, reader.calibration().depth_scale);
    ASSERT_GT(cv::countNonZero(truth), 1000) << "frame " << i;
    const double iou = IoU(overlay.mask, truth);
    EXPECT_GT(iou, 0.9) << "frame " << i;
    // The same pose 15 cm to the side covers the subject much worse: the test can fail.
    Pose shifted = pose;
    shifted.translation.x() += 0.15;
    skinning.Apply(shifted, &posed);
    const double off =
        IoU(RenderOverlay(frame, reader.calibration(), subject, posed, options).mask, truth);
    EXPECT_LT(off, iou - 0.3) << "frame " << i;
    if (i == 0) {
      std::printf("overlay IoU frame 0: %.3f (shifted 15 cm: %.3f)\n", iou, off);
    }
  }
}

TEST_F(OverlayTest, CommandWritesFramesAndAContactSheet) {
  ASSERT_TRUE(fs::exists(ARTEX_BINARY)) << ARTEX_BINARY;
  const std::string out = (*dir_ / "overlay_depth").string();
  ASSERT_EQ(Cli("overlay -q '" + Sequence() + "' '" + Run() + "' -o '" + out +
                "' --over depth -t '" + Subject() + "'"),
            0)
      << CliOutput();
  SequenceReader reader(Sequence());
  for (int i = 0; i < kFrames; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "/%06d.png", i);
    ASSERT_TRUE(fs::exists(out + name)) << out + name;
  }
  const cv::Mat sheet = cv::imread(out + "/overview.png");
  ASSERT_FALSE(sheet.empty());
  EXPECT_EQ(sheet.cols, 3 * 320);  // 5 frames: 3 columns of 320-pixel tiles, 2 rows
  EXPECT_EQ(sheet.rows, 2 * 240);
  // The file is the library's overlay of that frame (same template, pose and camera).
  const Template subject = ReadTemplateGlb(Subject());
  const Skinning skinning(subject);
  Frame frame;
  std::string warning;
  ASSERT_TRUE(reader.ReadFrame(3, &frame, &warning));
  Eigen::MatrixX3d posed;
  skinning.Apply(reader.ReadGroundTruth(3).pose, &posed);
  OverlayOptions options;
  options.background = OverlayBackground::kDepth;
  const cv::Mat expected =
      RenderOverlay(frame, reader.calibration(), subject, posed, options).image;
  EXPECT_EQ(cv::norm(cv::imread(out + "/000003.png"), expected, cv::NORM_INF), 0.0);

  // Over colour (the default): the colour camera's size; chosen frames only.
  const std::string color = (*dir_ / "overlay_color").string();
  ASSERT_EQ(Cli("overlay -q '" + Sequence() + "' '" + Run() + "' -o '" + color +
                "' --frames 1,4 -t '" + Subject() + "'"),
            0)
      << CliOutput();
  const cv::Mat c = cv::imread(color + "/000004.png");
  EXPECT_EQ(c.cols, 160);
  EXPECT_EQ(c.rows, 204);
  EXPECT_FALSE(fs::exists(color + "/000000.png"));

  // RUN/calibration.yaml (the world frame the run used) replaces the sequence's.
  Calibration moved = reader.calibration();
  moved.depth.world_to_camera.translation().x() += 0.2;
  WriteCalibration(moved, Run() + "/calibration.yaml");
  const std::string shifted = (*dir_ / "overlay_moved").string();
  const int status = Cli("overlay -q '" + Sequence() + "' '" + Run() + "' -o '" + shifted +
                         "' --frames 3 --over depth -t '" + Subject() + "'");
  fs::remove(Run() + "/calibration.yaml");
  ASSERT_EQ(status, 0) << CliOutput();
  const cv::Mat moved_expected = RenderOverlay(frame, moved, subject, posed, options).image;
  const cv::Mat moved_file = cv::imread(shifted + "/000003.png");
  EXPECT_EQ(cv::norm(moved_file, moved_expected, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(moved_file, expected, cv::NORM_INF), 0.0);

  // A frame without a pose, and a strip to one file.
  EXPECT_EQ(Cli("overlay -q '" + Sequence() + "' '" + Run() + "' -o '" + shifted + "' --frames 9"),
            1);
  EXPECT_NE(CliOutput().find("frame 9"), std::string::npos) << CliOutput();
  const std::string strip = (*dir_ / "strip.png").string();
  ASSERT_EQ(Cli("overlay -q '" + Sequence() + "' '" + Run() + "' -o '" + strip +
                "' --frames 0,2 --scale 0.5 --over depth"),
            0)
      << CliOutput();
  const cv::Mat s = cv::imread(strip);
  EXPECT_EQ(s.cols, 2 * 160);
  EXPECT_EQ(s.rows, 120);
}

// Issue 17: `artex overlay RUN` on `artex track` output found no recording when the track
// command was given a relative path and overlay ran from another directory; the run now names
// the recording by its absolute path (summary.json "sequence").
TEST_F(OverlayTest, RecordingDefaultsFromATrackRunFromAnyDirectory) {
  const std::string run = (*dir_ / "track_run").string();
  const std::string track =
      "cd '" + dir_->string() + "' && '" + std::string(ARTEX_BINARY) +
      "' track sequence -o track_run -q --no-texture --max-frames 2 "
      "--set fitting.max_fit_vertices=800 --set preprocess.background.min_valid_samples=2 > '" +
      (*dir_ / "out.txt").string() + "' 2>&1";
  const int raw = std::system(track.c_str());
  ASSERT_TRUE(WIFEXITED(raw) && WEXITSTATUS(raw) == 0) << CliOutput();
  const std::string out = (*dir_ / "overlay_from_track").string();
  ASSERT_EQ(Cli("overlay -q '" + run + "' -o '" + out + "' --frames 1"), 0) << CliOutput();
  EXPECT_TRUE(fs::exists(out + "/000001.png"));
}

}  // namespace
}  // namespace artex
