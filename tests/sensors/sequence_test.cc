#include "sensors/sequence.h"

#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "models/error.h"
#include "models/so3.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

constexpr int kJoints = 2;
constexpr int kFrames = 3;
constexpr int kBackground = 4;

std::string TempFolder(const std::string& name) {
  return testing_util::FreshTempDir("sequence_test_" + name).string();
}

Calibration SmallRig() {
  Calibration c;
  c.depth.width = 48;  // portrait, like the paper's tilted Kinect
  c.depth.height = 64;
  c.depth.fx = c.depth.fy = 58.0;
  c.depth.cx = 23.5;
  c.depth.cy = 31.5;
  c.color.width = 40;
  c.color.height = 52;
  c.color.fx = c.color.fy = 61.25;
  c.color.cx = 19.75;
  c.color.cy = 25.5;
  c.color.world_to_camera.translation() = Eigen::Vector3d(0.025, 0, 0);
  c.color_distortion.k1 = 0.01;
  return c;
}

struct Recorded {
  std::vector<Frame> frames;
  std::vector<cv::Mat> background;
  std::vector<GroundTruthFrame> truth;
  cv::Mat texture;
};

Recorded MakeData(const Calibration& c, uint64_t seed) {
  cv::RNG rng(seed);  // local generator: no global random state
  Recorded r;
  for (int i = 0; i < kFrames; ++i) {
    Frame f;
    f.index = i;
    f.depth_timestamp = 1305031102.175304 + i / 30.0;
    f.color_timestamp = f.depth_timestamp + 0.0031 * (i + 1);
    f.depth.create(c.depth.height, c.depth.width, CV_16UC1);
    f.color.create(c.color.height, c.color.width, CV_8UC3);
    rng.fill(f.depth, cv::RNG::UNIFORM, 0, 65535);
    rng.fill(f.color, cv::RNG::UNIFORM, 0, 255);
    r.frames.push_back(f);
    GroundTruthFrame t;
    t.pose = Pose::Identity(kJoints);
    t.pose.scale = 1.0 + 0.01 * i;
    t.pose.translation = Eigen::Vector3d(0.1 * i, 0.9, -0.2);
    t.pose.rotation = ExpSO3(Eigen::Vector3d(0.1, 0.2 * i, -0.3));
    t.pose.joint_rotations[1] = ExpSO3(Eigen::Vector3d(0.0, 0.5, 0.25 * i));
    t.vertices.resize(7 + i, 3);
    for (int r = 0; r < t.vertices.rows(); ++r) {
      for (int k = 0; k < 3; ++k) t.vertices(r, k) = rng.uniform(-1.0, 1.0);
    }
    r.truth.push_back(t);
  }
  for (int i = 0; i < kBackground; ++i) {
    cv::Mat d(c.depth.height, c.depth.width, CV_16UC1);
    rng.fill(d, cv::RNG::UNIFORM, 0, 65535);
    r.background.push_back(d);
  }
  r.texture.create(16, 16, CV_8UC3);
  rng.fill(r.texture, cv::RNG::UNIFORM, 0, 255);
  return r;
}

void WriteSequence(const std::string& folder, const Calibration& c, const Recorded& r) {
  SequenceWriter w(folder, c);
  for (const cv::Mat& b : r.background) w.AddBackgroundFrame(b);
  for (int i = 0; i < kFrames; ++i) {
    w.AddFrame(r.frames[i]);
    w.AddGroundTruth(r.frames[i].index, r.truth[i]);
  }
  w.SetGroundTruthTexture(r.texture);
  std::ofstream(w.subject_path()) << "glb";
  w.Finish();
}

bool Same(const cv::Mat& a, const cv::Mat& b) {
  return a.type() == b.type() && a.size() == b.size() && cv::norm(a, b, cv::NORM_INF) == 0;
}

std::string ReaderError(const std::string& folder) {
  try {
    SequenceReader reader(folder);
  } catch (const Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "no artex::Error for " << folder;
  return "";
}

std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

void Replace(const std::string& path, const std::string& from, const std::string& to) {
  std::string text = ReadText(path);
  const size_t at = text.find(from);
  ASSERT_NE(at, std::string::npos) << from << " in " << path;
  text.replace(at, from.size(), to);
  std::ofstream(path, std::ios::trunc) << text;
}

TEST(SequenceTest, RoundTripIsIdentical) {
  const std::string folder = TempFolder("roundtrip");
  const Calibration c = SmallRig();
  const Recorded r = MakeData(c, 1);
  WriteSequence(folder, c, r);
  for (const auto& e : fs::recursive_directory_iterator(folder)) {
    EXPECT_EQ(e.path().string().find(".partial"), std::string::npos) << e.path();
  }

  SequenceReader reader(folder);
  ASSERT_EQ(reader.num_frames(), kFrames);
  EXPECT_EQ(reader.folder(), folder);
  EXPECT_EQ(reader.calibration().depth.width, 48);
  EXPECT_EQ(reader.calibration().color.cx, 19.75);
  EXPECT_EQ(reader.calibration().color_distortion.k1, 0.01);
  EXPECT_EQ(reader.calibration().color.world_to_camera.translation().x(), 0.025);
  for (int i = 0; i < kFrames; ++i) {
    Frame f;
    std::string warning;
    ASSERT_TRUE(reader.ReadFrame(i, &f, &warning)) << warning;
    EXPECT_EQ(f.index, r.frames[i].index);
    EXPECT_EQ(f.depth_timestamp, r.frames[i].depth_timestamp);  // exact
    EXPECT_EQ(f.color_timestamp, r.frames[i].color_timestamp);
    EXPECT_TRUE(Same(f.depth, r.frames[i].depth));
    EXPECT_TRUE(Same(f.color, r.frames[i].color));
  }
  const std::vector<cv::Mat> background = reader.ReadBackgroundFrames();
  ASSERT_EQ(background.size(), static_cast<size_t>(kBackground));
  for (int i = 0; i < kBackground; ++i) EXPECT_TRUE(Same(background[i], r.background[i]));

  ASSERT_TRUE(reader.has_ground_truth());
  for (int i = 0; i < kFrames; ++i) {
    const GroundTruthFrame t = reader.ReadGroundTruth(i);
    ASSERT_EQ(t.pose.num_joints(), kJoints);
    EXPECT_LT((t.pose.ToVector() - r.truth[i].pose.ToVector()).norm(), 1e-12);
    ASSERT_EQ(t.vertices.rows(), r.truth[i].vertices.rows());
    // float32 storage
    EXPECT_LT((t.vertices - r.truth[i].vertices).cwiseAbs().maxCoeff(), 1e-7);
  }
  EXPECT_TRUE(Same(cv::imread(reader.GroundTruthTexturePath(), cv::IMREAD_UNCHANGED), r.texture));
  EXPECT_EQ(ReadText(reader.GroundTruthSubjectPath()), "glb");
}

TEST(SequenceTest, SequenceWithoutOptionalPartsReads) {
  const std::string folder = TempFolder("minimal");
  const Calibration c = SmallRig();
  const Recorded r = MakeData(c, 2);
  SequenceWriter w(folder, c);
  w.AddFrame(r.frames[0]);
  w.Finish();
  SequenceReader reader(folder);
  EXPECT_EQ(reader.num_frames(), 1);
  EXPECT_FALSE(reader.has_ground_truth());
  EXPECT_TRUE(reader.ReadBackgroundFrames().empty());
  EXPECT_EQ(reader.GroundTruthTexturePath(), "");
  EXPECT_EQ(reader.GroundTruthSubjectPath(), "");
  EXPECT_THROW(reader.ReadGroundTruth(0), Error);
  EXPECT_THROW(w.AddFrame(r.frames[1]), Error);  // after Finish
}

TEST(SequenceTest, UnfinishedOrEmptyFoldersAreErrors) {
  const std::string empty = TempFolder("empty");
  EXPECT_NE(ReaderError(empty).find("empty folder"), std::string::npos);
  EXPECT_NE(ReaderError(empty + "/absent").find("absent"), std::string::npos);

  const std::string unfinished = TempFolder("unfinished");
  const Calibration c = SmallRig();
  const Recorded r = MakeData(c, 3);
  {
    SequenceWriter w(unfinished, c);
    w.AddFrame(r.frames[0]);
  }  // no Finish()
  const std::string msg = ReaderError(unfinished);
  EXPECT_NE(msg.find("frames.csv"), std::string::npos) << msg;
}

TEST(SequenceTest, MalformedCalibrationNamesTheFile) {
  const std::string folder = TempFolder("bad_calibration");
  const Calibration c = SmallRig();
  WriteSequence(folder, c, MakeData(c, 4));
  Replace(folder + "/calibration.yaml", "fx: 58", "fx: fifty-eight");
  const std::string msg = ReaderError(folder);
  EXPECT_NE(msg.find("calibration.yaml"), std::string::npos) << msg;
  EXPECT_NE(msg.find("depth.fx"), std::string::npos) << msg;
  EXPECT_NE(msg.find("fifty-eight"), std::string::npos) << msg;
}

TEST(SequenceTest, TimestampsOutOfOrderAreErrors) {
  const std::string folder = TempFolder("order");
  const Calibration c = SmallRig();
  const Recorded r = MakeData(c, 5);
  WriteSequence(folder, c, r);
  // Frame 2 gets the depth timestamp of frame 0.
  std::string text = ReadText(folder + "/frames.csv");
  const size_t line3 = text.find("\n2,");
  ASSERT_NE(line3, std::string::npos);
  const size_t start = line3 + 3, end = text.find(',', start);
  text.replace(start, end - start, "1305031102.0");
  std::ofstream(folder + "/frames.csv", std::ios::trunc) << text;
  const std::string msg = ReaderError(folder);
  EXPECT_NE(msg.find("frames.csv"), std::string::npos) << msg;
  EXPECT_NE(msg.find("line 4"), std::string::npos) << msg;  // header + 3 rows
  EXPECT_NE(msg.find("depth_timestamp"), std::string::npos) << msg;
  EXPECT_NE(msg.find("1305031102.0"), std::string::npos) << msg;

  // The writer refuses them too.
  SequenceWriter w(TempFolder("order_writer"), c);
  w.AddFrame(r.frames[1]);
  Frame earlier = r.frames[2];
  earlier.depth_timestamp = r.frames[0].depth_timestamp;
  EXPECT_THROW(w.AddFrame(earlier), Error);
}

TEST(SequenceTest, MalformedRowsAreErrors) {
  const std::string folder = TempFolder("rows");
  const Calibration c = SmallRig();
  WriteSequence(folder, c, MakeData(c, 6));
  const std::string frames = folder + "/frames.csv";
  const std::string good = ReadText(frames);
  Replace(frames, "\n1,", "\n1,abc,");
  std::string msg = ReaderError(folder);
  EXPECT_NE(msg.find("line 3"), std::string::npos) << msg;
  EXPECT_NE(msg.find("columns"), std::string::npos) << msg;

  std::ofstream(frames, std::ios::trunc) << good;
  Replace(frames, "index,depth", "idx,depth");
  msg = ReaderError(folder);
  EXPECT_NE(msg.find("header"), std::string::npos) << msg;

  std::ofstream(frames, std::ios::trunc) << good;
  Replace(folder + "/groundtruth/poses.csv", "\n1,", "\n1,2,");
  msg = ReaderError(folder);
  EXPECT_NE(msg.find("poses.csv"), std::string::npos) << msg;
  EXPECT_NE(msg.find("line 3"), std::string::npos) << msg;
}

TEST(SequenceTest, BadFramesAreSkippedWithAWarning) {
  const std::string folder = TempFolder("bad_frames");
  const Calibration c = SmallRig();
  const Recorded r = MakeData(c, 7);
  WriteSequence(folder, c, r);
  fs::remove(folder + "/depth/000001.png");
  cv::imwrite(folder + "/depth/000002.png",
              cv::Mat(c.depth.height, c.depth.width, CV_8UC1, cv::Scalar(100)));
  cv::imwrite(folder + "/color/000000.png",
              cv::Mat(c.color.height + 1, c.color.width, CV_8UC3, cv::Scalar(1, 2, 3)));
  SequenceReader reader(folder);
  Frame f;
  std::string warning;
  EXPECT_FALSE(reader.ReadFrame(0, &f, &warning));
  EXPECT_NE(warning.find("color/000000.png"), std::string::npos) << warning;
  EXPECT_NE(warning.find("size"), std::string::npos) << warning;
  EXPECT_NE(warning.find("40x52"), std::string::npos) << warning;
  EXPECT_NE(warning.find("40x53"), std::string::npos) << warning;
  warning.clear();
  EXPECT_FALSE(reader.ReadFrame(1, &f, &warning));
  EXPECT_NE(warning.find("depth/000001.png"), std::string::npos) << warning;
  EXPECT_NE(warning.find("missing"), std::string::npos) << warning;
  warning.clear();
  EXPECT_FALSE(reader.ReadFrame(2, &f, &warning));
  EXPECT_NE(warning.find("depth/000002.png"), std::string::npos) << warning;
  EXPECT_NE(warning.find("16-bit"), std::string::npos) << warning;
  EXPECT_NE(warning.find("CV_8UC1"), std::string::npos) << warning;
  EXPECT_THROW(reader.ReadFrame(3, &f, &warning), Error);

  // A corrupt ground-truth vertex file is an error naming it.
  std::ofstream(folder + "/groundtruth/vertices/000001.bin", std::ios::trunc) << "AXV1xx";
  try {
    reader.ReadGroundTruth(1);
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("000001.bin"), std::string::npos) << e.what();
  }
}

// The reader rejects what the writer refuses: a non-finite ground-truth vertex (issue 20: NaN
// vertices turned the metrics into nonsense).
TEST(SequenceTest, NonFiniteGroundTruthVerticesAreErrors) {
  const std::string folder = TempFolder("nan_truth");
  const Calibration c = SmallRig();
  const Recorded r = MakeData(c, 11);
  WriteSequence(folder, c, r);
  const std::string file = folder + "/groundtruth/vertices/000002.bin";
  std::string bytes = ReadText(file);
  ASSERT_GT(bytes.size(), 8u + 12u * 3u);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(&bytes[8 + 12 * 3 + 4], &nan, 4);  // vertex 3, y (little-endian hosts)
  std::ofstream(file, std::ios::binary | std::ios::trunc) << bytes;
  SequenceReader reader(folder);
  EXPECT_NO_THROW(reader.ReadGroundTruth(1));
  try {
    reader.ReadGroundTruth(2);
    ADD_FAILURE() << "no error for a NaN vertex";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("000002.bin"), std::string::npos) << what;
    EXPECT_NE(what.find("vertex 3"), std::string::npos) << what;
    EXPECT_NE(what.find("finite"), std::string::npos) << what;
  }
}

TEST(SequenceTest, WriterRejectsWrongImages) {
  const Calibration c = SmallRig();
  const Recorded r = MakeData(c, 8);
  SequenceWriter w(TempFolder("writer"), c);
  Frame f = r.frames[0];
  f.depth.convertTo(f.depth, CV_32F);
  EXPECT_THROW(w.AddFrame(f), Error);
  f = r.frames[0];
  f.color = cv::Mat(c.depth.height, c.depth.width, CV_8UC3);
  EXPECT_THROW(w.AddFrame(f), Error);
  EXPECT_THROW(w.AddBackgroundFrame(cv::Mat(3, 3, CV_16UC1)), Error);
  EXPECT_THROW(w.Finish(), Error);  // no frames
}

}  // namespace
}  // namespace artex
