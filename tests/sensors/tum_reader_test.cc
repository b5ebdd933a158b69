#include "sensors/tum_reader.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iomanip>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>

#include "models/error.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

constexpr int kWidth = 32;
constexpr int kHeight = 24;
constexpr int kFrames = 6;
constexpr double kStart = 1305031102.175304;

std::string TempFolder(const std::string& name) {
  const fs::path p = fs::path(::testing::TempDir()) / ("artex_tum_test_" + name);
  fs::remove_all(p);
  fs::create_directories(p / "rgb");
  fs::create_directories(p / "depth");
  return p.string();
}

std::string Stamp(double t) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(6) << t;
  return s.str();
}

// Depth frame k shows a flat scene at 1 + 0.25 k metres (TUM: 5000 units per metre); colour
// frame k is filled with the value 10 k + 5 in its blue channel. Colour timestamps lag the
// depth ones by 12 ms (within the default 20 ms window, while the neighbouring frame is 21 ms
// away); one extra colour frame has no depth partner and one depth frame has no colour one.
std::string WriteTum(const std::string& name, bool with_intrinsics = true) {
  const std::string folder = TempFolder(name);
  std::ofstream rgb(folder + "/rgb.txt"), depth(folder + "/depth.txt");
  rgb << "# color images\n# file: 'rgbd_dataset_freiburg1_xyz.bag'\n# timestamp filename\n";
  depth << "# depth maps\n# file: 'rgbd_dataset_freiburg1_xyz.bag'\n# timestamp filename\n";
  for (int k = 0; k < kFrames; ++k) {
    const double td = kStart + k / 30.0;
    const double tc = td + 0.012;
    const std::string dn = "depth/" + Stamp(td) + ".png", cn = "rgb/" + Stamp(tc) + ".png";
    cv::imwrite(folder + "/" + dn,
                cv::Mat(kHeight, kWidth, CV_16UC1, cv::Scalar(5000 * (1 + 0.25 * k))));
    cv::imwrite(folder + "/" + cn, cv::Mat(kHeight, kWidth, CV_8UC3, cv::Scalar(10 * k + 5, 0, 0)));
    depth << Stamp(td) << " " << dn << "\n";
    rgb << Stamp(tc) << " " << cn << "\n";
  }
  // Unmatched entries (their files need not exist).
  rgb << Stamp(kStart + 10.0) << " rgb/lonely.png\n";
  depth << Stamp(kStart + 20.0) << " depth/lonely.png\n";
  if (with_intrinsics) {
    std::ofstream(folder + "/camera.yaml")
        << "# Freiburg 1 colour camera\nwidth: 32\nheight: 24\nfx: 517.3\nfy: 516.5\n"
           "cx: 15.5\ncy: 11.5\nk1: 0.2624\nk2: -0.9531\np1: -0.0054\np2: 0.0026\nk3: 1.1633\n";
  }
  return folder;
}

TEST(TumReaderTest, AssociatesByNearestTimestampAndScalesDepth) {
  const std::string folder = WriteTum("basic");
  TumReader reader(folder);
  ASSERT_EQ(reader.num_frames(), kFrames);
  EXPECT_EQ(reader.num_unmatched_color(), 1);
  EXPECT_EQ(reader.num_unmatched_depth(), 1);
  const Calibration& c = reader.calibration();
  EXPECT_EQ(c.depth_scale, 5000.0);
  EXPECT_EQ(c.depth.width, kWidth);
  EXPECT_EQ(c.depth.fx, 517.3);
  EXPECT_EQ(c.color.fy, 516.5);
  EXPECT_EQ(c.depth_distortion.k3, 1.1633);
  EXPECT_TRUE(c.DepthToColor().matrix().isIdentity(0));
  EXPECT_TRUE(reader.ReadBackgroundFrames().empty());
  for (int k = 0; k < kFrames; ++k) {
    Frame f;
    std::string warning;
    ASSERT_TRUE(reader.ReadFrame(k, &f, &warning)) << warning;
    EXPECT_EQ(f.index, k);
    EXPECT_NEAR(f.depth_timestamp, kStart + k / 30.0, 1e-6);
    EXPECT_NEAR(f.color_timestamp - f.depth_timestamp, 0.012, 1e-6);
    EXPECT_EQ(f.color.at<cv::Vec3b>(3, 4)[0], 10 * k + 5);  // the right colour frame
    EXPECT_NEAR(f.depth.at<uint16_t>(3, 4) / c.depth_scale, 1 + 0.25 * k, 1e-9);  // metres
  }
}

TEST(TumReaderTest, WindowAndOffsetControlTheAssociation) {
  const std::string folder = WriteTum("window");
  TumReaderOptions narrow;
  narrow.max_time_difference = 0.01;  // the 12 ms lag no longer fits
  EXPECT_THROW(TumReader(folder, narrow), Error);
  narrow.time_offset = -0.012;  // ... unless the colour clock is corrected
  TumReader shifted(folder, narrow);
  EXPECT_EQ(shifted.num_frames(), kFrames);
  TumReaderOptions wide;
  wide.max_time_difference = 0.05;  // neighbours fit too; pairs stay one-to-one and nearest
  TumReader reader(folder, wide);
  ASSERT_EQ(reader.num_frames(), kFrames);
  for (int k = 0; k < kFrames; ++k) {
    EXPECT_EQ(reader.color_file(k).substr(4, 17), Stamp(kStart + k / 30.0 + 0.012)) << k;
  }
}

TEST(TumReaderTest, OneToOneGreedyPairing) {
  const std::string folder = TempFolder("greedy");
  std::ofstream(folder + "/depth.txt") << "300.000 depth/a.png\n300.010 depth/b.png\n";
  std::ofstream(folder + "/rgb.txt") << "300.008 rgb/a.png\n";
  std::ofstream(folder + "/camera.yaml") << "{width: 4, height: 3, fx: 5, fy: 5, cx: 1.5, cy: 1}";
  TumReader reader(folder);
  ASSERT_EQ(reader.num_frames(), 1);
  EXPECT_EQ(reader.depth_file(0), "depth/b.png");  // the nearer depth frame wins
  EXPECT_EQ(reader.num_unmatched_depth(), 1);
}

TEST(TumReaderTest, BadInputGivesErrorsOrWarnings) {
  {
    const std::string folder = WriteTum("no_intrinsics", false);
    try {
      TumReader reader(folder);
      ADD_FAILURE() << "no error";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("camera.yaml"), std::string::npos) << e.what();
    }
    TumReaderOptions defaults;
    defaults.freiburg1_defaults = true;
    TumReader reader(folder, defaults);
    EXPECT_EQ(reader.calibration().depth.fx, 517.3);
    EXPECT_EQ(reader.calibration().depth.width, 640);
    Frame f;
    std::string warning;
    EXPECT_FALSE(reader.ReadFrame(0, &f, &warning));  // 32 x 24 images vs 640 x 480
    EXPECT_NE(warning.find("640x480"), std::string::npos) << warning;
  }
  {
    const std::string folder = WriteTum("order");
    std::ofstream(folder + "/rgb.txt", std::ios::app) << "100.0 rgb/early.png\n";
    try {
      TumReader reader(folder);
      ADD_FAILURE() << "no error";
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find("rgb.txt"), std::string::npos) << msg;
      EXPECT_NE(msg.find("line 11"), std::string::npos) << msg;
      EXPECT_NE(msg.find("increasing"), std::string::npos) << msg;
    }
  }
  {
    const std::string folder = WriteTum("garbage");
    std::ofstream(folder + "/depth.txt", std::ios::app) << "soon depth/x.png\n";
    EXPECT_THROW(TumReader{folder}, Error);
  }
  {
    const std::string folder = WriteTum("bad_yaml");
    std::ofstream(folder + "/camera.yaml", std::ios::trunc) << "width: 32\nheight: 24\nfx: -1\n";
    try {
      TumReader reader(folder);
      ADD_FAILURE() << "no error";
    } catch (const Error& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find("camera.yaml"), std::string::npos) << msg;
      EXPECT_NE(msg.find("'fx'"), std::string::npos) << msg;
    }
  }
  {
    const std::string folder = WriteTum("frames");
    TumReader reader(folder);
    const std::string depth1 = folder + "/" + reader.depth_file(1);
    fs::remove(depth1);
    cv::imwrite(folder + "/" + reader.depth_file(2), cv::Mat(kHeight, kWidth, CV_8UC1));
    Frame f;
    std::string warning;
    EXPECT_FALSE(reader.ReadFrame(1, &f, &warning));
    EXPECT_NE(warning.find(reader.depth_file(1)), std::string::npos) << warning;
    EXPECT_FALSE(reader.ReadFrame(2, &f, &warning));
    EXPECT_NE(warning.find("16-bit"), std::string::npos) << warning;
    EXPECT_TRUE(reader.ReadFrame(3, &f, &warning));
  }
  EXPECT_THROW(TumReader(TempFolder("missing") + "/nothing"), Error);
}

}  // namespace
}  // namespace artex
