// The .artx stream end to end: a sender writes poses and a changing atlas (VP9), the receiver
// plays it back (poses within the quantisation bound, atlas within the codec's PSNR), joins
// mid-stream at the next keyframe, and reports truncated and bit-flipped streams with the
// byte offset and frame, resuming at the next keyframe.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <opencv2/imgproc.hpp>
#include <random>

#include "models/error.h"
#include "models/so3.h"
#include "models/template_generator.h"
#include "stream/stream_player.h"
#include "stream/stream_sender.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
constexpr int kFrames = 24;
constexpr int kKeyframeInterval = 8;
constexpr int kAtlas = 256;

Pose MotionPose(int frame, int joints) {
  Pose p = Pose::Identity(joints);
  const double t = frame / 30.0;
  p.translation = Eigen::Vector3d(0.5 * t, 0.0, 2.5);
  p.rotation = ExpSO3(Eigen::Vector3d(0.0, 0.4 * std::sin(t), 0.0));
  for (int j = 0; j < joints; ++j)
    p.joint_rotations[j] = ExpSO3(Eigen::Vector3d(0.3 * std::sin(3 * t + j), 0.1 * j, 0.0));
  return p;
}

// A textured atlas whose one region changes per frame (as incremental texturing does).
cv::Mat Atlas(int frame) {
  cv::Mat a(kAtlas, kAtlas, CV_8UC3);
  for (int y = 0; y < kAtlas; ++y)
    for (int x = 0; x < kAtlas; ++x)
      a.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<uchar>(128 + 90 * std::sin(x / 9.0)),
                                        static_cast<uchar>(128 + 90 * std::cos(y / 13.0)),
                                        static_cast<uchar>((x + y) / 2));
  cv::rectangle(a, cv::Rect(8 * frame % 200, 40, 48, 48), cv::Scalar(20, 200, 240), cv::FILLED);
  return a;
}

class StreamTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    BodyShapeOptions shape;
    shape.resolution = 0;
    tmpl_ = new Template(GenerateTemplate(shape));
    const fs::path path =
        fs::temp_directory_path() / ("artex_stream_test_" + std::to_string(::getpid()) + ".artx");
    StreamOptions o;
    o.keyframe_interval = kKeyframeInterval;
    o.video.bitrate_kbps = 1500;
    PinholeCamera camera;
    StreamSender sender(path.string(), *tmpl_, camera, 30.0, kAtlas, true, o);
    std::vector<int> frames(tmpl_->num_triangles(), 0);
    for (int f = 0; f < kFrames; ++f) {
      frames[f] = -1;  // coverage changes too
      sender.AddFrame(f, MotionPose(f, tmpl_->num_joints()), Atlas(f), &frames);
    }
    summary_ = new StreamSummary(sender.Finish());
    std::ifstream in(path, std::ios::binary);
    bytes_ = new std::vector<uint8_t>(std::istreambuf_iterator<char>(in),
                                      std::istreambuf_iterator<char>{});
    fs::remove(path);
    // Record offsets from a clean pass.
    offsets_ = new std::vector<std::size_t>();
    StreamPlayer player(std::make_unique<StreamReader>(*bytes_, "clean"));
    PlayedFrame f;
    while (player.Next(&f)) offsets_->push_back(f.offset);
  }
  static void TearDownTestSuite() {
    delete tmpl_;
    delete summary_;
    delete bytes_;
    delete offsets_;
  }
  static std::vector<PlayedFrame> Play(const std::vector<uint8_t>& bytes, int from_frame,
                                       std::vector<StreamIssue>* issues) {
    StreamPlayer player(std::make_unique<StreamReader>(bytes, "test"), from_frame);
    std::vector<PlayedFrame> out;
    PlayedFrame f;
    while (player.Next(&f)) out.push_back(f);
    if (issues) *issues = player.issues();
    return out;
  }

  static Template* tmpl_;
  static StreamSummary* summary_;
  static std::vector<uint8_t>* bytes_;
  static std::vector<std::size_t>* offsets_;
};

Template* StreamTest::tmpl_ = nullptr;
StreamSummary* StreamTest::summary_ = nullptr;
std::vector<uint8_t>* StreamTest::bytes_ = nullptr;
std::vector<std::size_t>* StreamTest::offsets_ = nullptr;

TEST_F(StreamTest, RoundTripWithinQuantisationAndCodecBounds) {
  EXPECT_EQ(summary_->frames, kFrames);
  EXPECT_EQ(summary_->keyframes, kFrames / kKeyframeInterval);
  std::vector<StreamIssue> issues;
  const std::vector<PlayedFrame> played = Play(*bytes_, 0, &issues);
  EXPECT_TRUE(issues.empty());
  ASSERT_EQ(static_cast<int>(played.size()), kFrames);
  const PoseCodecOptions steps;
  double worst_psnr = 1e9;
  for (int f = 0; f < kFrames; ++f) {
    EXPECT_EQ(played[f].frame, f);
    EXPECT_EQ(played[f].keyframe, f % kKeyframeInterval == 0);
    const Eigen::VectorXd a = MotionPose(f, tmpl_->num_joints()).ToVector();
    const Eigen::VectorXd b = played[f].pose.ToVector();
    for (int i = 0; i < a.size(); ++i)
      EXPECT_LE(std::abs(a[i] - b[i]), 0.5 * PoseParameterStep(i, steps) + 1e-12);
    worst_psnr = std::min(worst_psnr, ImagePsnr(played[f].atlas, Atlas(f)));
    EXPECT_EQ(played[f].textured[f], 0);
    if (f + 1 < tmpl_->num_triangles()) {
      EXPECT_EQ(played[f].textured[f + 1], 1);
    }
  }
  std::printf("atlas PSNR >= %.2f dB; pose %.2f kbit/s, texture %.1f kbit/s; hand error %.3f mm\n",
              worst_psnr, summary_->pose_kbps, summary_->texture_kbps, summary_->max_hand_error_mm);
  EXPECT_GT(worst_psnr, 30.0);
  EXPECT_LT(summary_->max_hand_error_mm, 1.0);
}

TEST_F(StreamTest, JoinsMidStreamAtTheNextKeyframe) {
  std::vector<StreamIssue> issues;
  const std::vector<PlayedFrame> played = Play(*bytes_, 10, &issues);
  EXPECT_TRUE(issues.empty());
  ASSERT_EQ(static_cast<int>(played.size()), kFrames - 16);
  EXPECT_EQ(played.front().frame, 16);
  EXPECT_TRUE(played.front().keyframe);
  // The joined receiver has the same atlas as one that played from the start.
  const std::vector<PlayedFrame> all = Play(*bytes_, 0, nullptr);
  EXPECT_EQ(cv::norm(played.back().atlas, all.back().atlas, cv::NORM_INF), 0.0);
}

TEST_F(StreamTest, TruncatedStreamReportsOffsetAndFrame) {
  const std::size_t cut = (*offsets_)[13] + 30;
  std::vector<uint8_t> bytes(bytes_->begin(), bytes_->begin() + cut);
  std::vector<StreamIssue> issues;
  const std::vector<PlayedFrame> played = Play(bytes, 0, &issues);
  ASSERT_EQ(played.size(), 13u);
  ASSERT_EQ(issues.size(), 1u);
  EXPECT_EQ(issues[0].offset, (*offsets_)[13]);
  EXPECT_EQ(issues[0].frame, 13);
  EXPECT_NE(issues[0].what.find("truncated"), std::string::npos) << issues[0].what;
  // A truncated header is an error naming the header.
  std::vector<uint8_t> header(bytes_->begin(), bytes_->begin() + 100);
  try {
    StreamReader reader(header, "short.artx");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("header"), std::string::npos) << e.what();
  }
}

TEST_F(StreamTest, BitFlipResumesAtTheNextKeyframe) {
  std::vector<uint8_t> bytes = *bytes_;
  const std::size_t at = (*offsets_)[5] + 40;  // inside frame 5's payload
  bytes[at] ^= 0x10;
  std::vector<StreamIssue> issues;
  const std::vector<PlayedFrame> played = Play(bytes, 0, &issues);
  ASSERT_FALSE(issues.empty());
  EXPECT_EQ(issues[0].offset, (*offsets_)[5]);
  EXPECT_EQ(issues[0].frame, 5);
  // Frames 5-7 are lost (5 damaged, 6 and 7 predicted from it); 8 is a keyframe.
  ASSERT_EQ(static_cast<int>(played.size()), kFrames - 3);
  EXPECT_EQ(played[5].frame, 8);
  EXPECT_TRUE(played[5].keyframe);
  const std::vector<PlayedFrame> clean = Play(*bytes_, 0, nullptr);
  EXPECT_EQ(cv::norm(played.back().atlas, clean.back().atlas, cv::NORM_INF), 0.0);
}

TEST_F(StreamTest, RandomDamageNeverCrashes) {
  std::mt19937 rng(11);
  std::uniform_int_distribution<std::size_t> where((*offsets_)[0], bytes_->size() - 1);
  for (int trial = 0; trial < 12; ++trial) {
    std::vector<uint8_t> bytes = *bytes_;
    for (int k = 0; k < 1 + trial; ++k) bytes[where(rng)] ^= static_cast<uint8_t>(1u << (k % 8));
    if (trial % 3 == 2) bytes.resize(where(rng));
    std::vector<StreamIssue> issues;
    const std::vector<PlayedFrame> played = Play(bytes, 0, &issues);
    EXPECT_LE(played.size(), static_cast<std::size_t>(kFrames));
    for (const PlayedFrame& f : played) EXPECT_TRUE(f.pose.AllFinite());
  }
}

}  // namespace
}  // namespace artex
