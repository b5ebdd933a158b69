#include "sensors/tum_reader.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iomanip>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>

#include "models/error.h"
#include "tests/error_of.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

constexpr int kWidth = 32;
constexpr int kHeight = 24;
constexpr int kFrames = 6;
constexpr double kStart = 1305031102.175304;

std::string TempFolder(const std::string& name) {
  const fs::path p = testing_util::FreshTempDir("tum_test_" + name);
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
    const std::string msg = ErrorOf([&] { TumReader reader(folder); });
    // Names the file, the keys and the ways out.
    for (const char* part : {"camera.yaml", "width", "height", "fx", "fy", "cx", "cy", "k1", "p2",
                             "depth_scale", "--intrinsics FILE", "fr1", "fr2", "fr3", "kinect"}) {
      EXPECT_NE(msg.find(part), std::string::npos) << part << " in: " << msg;
    }
    TumReaderOptions defaults;
    defaults.SetIntrinsics("fr1");
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
    // Found by the TUM fuzzer: a huge width was converted to int (undefined behaviour); an
    // absurd focal length passed (issue 20).
    const std::string folder = WriteTum("huge");
    std::ofstream(folder + "/camera.yaml", std::ios::trunc)
        << "width: 4.8e31\nheight: 24\nfx: 5\nfy: 5\ncx: 1\ncy: 1\n";
    std::string msg = ErrorOf([&] { TumReader reader(folder); });
    EXPECT_NE(msg.find("at most 16384"), std::string::npos) << msg;
    std::ofstream(folder + "/camera.yaml", std::ios::trunc)
        << "width: 32\nheight: 24\nfx: 1e308\nfy: 5\ncx: 1\ncy: 1\n";
    msg = ErrorOf([&] { TumReader reader(folder); });
    EXPECT_NE(msg.find("depth.fx"), std::string::npos) << msg;
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

TEST(TumReaderTest, PresetsGiveThePublishedIntrinsics) {
  struct Expected {
    const char* name;
    double fx, fy, cx, cy, k1, k3;
  };
  const Expected expected[] = {{"fr1", 517.3, 516.5, 318.6, 255.3, 0.2624, 1.1633},
                               {"fr2", 520.9, 521.0, 325.1, 249.7, 0.2312, 0.9172},
                               {"fr3", 535.4, 539.2, 320.1, 247.6, 0, 0},
                               {"kinect", 525.0, 525.0, 319.5, 239.5, 0, 0}};
  for (const Expected& e : expected) {
    TumReaderOptions options;
    options.SetIntrinsics(e.name);
    ASSERT_NE(options.intrinsics_preset, TumIntrinsicsPreset::kNone) << e.name;
    EXPECT_TRUE(options.intrinsics_path.empty());
    const Calibration c = TumPresetCalibration(options.intrinsics_preset);
    EXPECT_EQ(TumIntrinsicsPresetName(options.intrinsics_preset), e.name);
    EXPECT_EQ(c.depth.width, 640);
    EXPECT_EQ(c.depth.height, 480);
    EXPECT_EQ(c.depth_scale, 5000.0);
    EXPECT_EQ(c.depth.fx, e.fx) << e.name;
    EXPECT_EQ(c.depth.fy, e.fy) << e.name;
    EXPECT_EQ(c.depth.cx, e.cx) << e.name;
    EXPECT_EQ(c.depth.cy, e.cy) << e.name;
    EXPECT_EQ(c.color_distortion.k1, e.k1) << e.name;
    EXPECT_EQ(c.depth_distortion.k3, e.k3) << e.name;
    EXPECT_EQ(c.color.fx, c.depth.fx);
  }
  EXPECT_EQ(TumPresetCalibration(TumIntrinsicsPreset::kFreiburg2).depth_distortion.p2, -0.0001);
  EXPECT_TRUE(TumPresetCalibration(TumIntrinsicsPreset::kFreiburg3).depth_distortion.IsZero());
  // A preset overrides camera.yaml; a name that is no preset is a file.
  const std::string folder = WriteTum("preset");
  TumReaderOptions options;
  options.SetIntrinsics("kinect");
  EXPECT_EQ(TumReader(folder, options).calibration().depth.fx, 525.0);
  EXPECT_NE(TumReader(folder, options).intrinsics_source().find("kinect"), std::string::npos);
  options.SetIntrinsics(folder + "/camera.yaml");
  EXPECT_EQ(options.intrinsics_preset, TumIntrinsicsPreset::kNone);
  EXPECT_EQ(TumReader(folder, options).calibration().depth.fx, 517.3);
  options.SetIntrinsics(folder + "/nothing.yaml");
  const std::string msg = ErrorOf([&] { TumReader reader(folder, options); });
  EXPECT_NE(msg.find("nothing.yaml"), std::string::npos) << msg;
  EXPECT_NE(msg.find("fr1"), std::string::npos) << msg;
  // Both at once is invalid.
  options.intrinsics_preset = TumIntrinsicsPreset::kFreiburg1;
  std::string why;
  EXPECT_FALSE(options.IsValid(&why));
  EXPECT_NE(why.find("input.intrinsics"), std::string::npos) << why;
}

TEST(TumReaderTest, AccelerometerGivesUpInTheCameraFrame) {
  const std::string folder = WriteTum("accelerometer");
  EXPECT_FALSE(TumReader(folder).gravity().has_value());  // no file
  // An upright Kinect tilted forward a little: the specific force points up, -y of the camera,
  // with some +z as the camera pitches down; noisy samples around the mean.
  std::ofstream(folder + "/accelerometer.txt") << "# accelerometer data\n# timestamp ax ay az\n"
                                               << Stamp(kStart) << " 0.10 -9.60 1.90\n"
                                               << Stamp(kStart + 0.01) << " -0.10 -9.70 1.70\n"
                                               << Stamp(kStart + 0.02) << " 0.00 -9.65 1.80\n";
  TumReader reader(folder);
  ASSERT_TRUE(reader.gravity().has_value());
  EXPECT_EQ(reader.num_accelerometer_samples(), 3);
  const Eigen::Vector3d up = *reader.gravity();
  const Eigen::Vector3d expected = Eigen::Vector3d(0.0, -9.65, 1.8).normalized();
  EXPECT_NEAR((up - expected).norm(), 0.0, 1e-12);
  EXPECT_NEAR(up.norm(), 1.0, 1e-12);
  EXPECT_LT(up.y(), -0.95);  // upright: up is -y of the OpenCV camera (y points down)
  EXPECT_NE(reader.Description().find("accelerometer.txt"), std::string::npos);
  // Switched off, or too short a mean (a file of zeros): none.
  TumReaderOptions off;
  off.read_accelerometer = false;
  EXPECT_FALSE(TumReader(folder, off).gravity().has_value());
  std::ofstream(folder + "/accelerometer.txt", std::ios::trunc) << "1.0 0 0 0\n2.0 0 0 0\n";
  EXPECT_FALSE(TumReader(folder).gravity().has_value());
  // Malformed lines: file, line, expected, found.
  std::ofstream(folder + "/accelerometer.txt", std::ios::trunc)
      << "# timestamp ax ay az\n1.0 0 -9.8 0\n2.0 0 -9.8\n";
  std::string msg = ErrorOf([&] { TumReader r(folder); });
  EXPECT_NE(msg.find("accelerometer.txt: line 3"), std::string::npos) << msg;
  EXPECT_NE(msg.find("timestamp ax ay az"), std::string::npos) << msg;
  EXPECT_NE(msg.find("'2.0 0 -9.8'"), std::string::npos) << msg;
  std::ofstream(folder + "/accelerometer.txt", std::ios::trunc) << "1.0 0 up 0\n";
  msg = ErrorOf([&] { TumReader r(folder); });
  EXPECT_NE(msg.find("line 1"), std::string::npos) << msg;
  EXPECT_NE(msg.find("'1.0 0 up 0'"), std::string::npos) << msg;
}

TEST(TumReaderTest, CountsUnpairedAndMissingAndReportsThem) {
  const std::string folder = WriteTum("counts");
  fs::remove(folder + "/rgb/" + Stamp(kStart + 2 / 30.0 + 0.012) + ".png");
  TumReader reader(folder);
  EXPECT_EQ(reader.num_frames(), kFrames);
  EXPECT_EQ(reader.num_missing_files(), 1);
  const std::string d = reader.Description();
  EXPECT_NE(d.find("6 depth/colour pairs of 7 depth and 7 colour entries"), std::string::npos) << d;
  EXPECT_NE(d.find("1 depth and 1 colour unpaired"), std::string::npos) << d;
  EXPECT_NE(d.find("missing files in 1 pairs"), std::string::npos) << d;
  EXPECT_NE(d.find("camera.yaml"), std::string::npos) << d;
  Frame f;
  std::string warning;
  EXPECT_FALSE(reader.ReadFrame(2, &f, &warning));
  EXPECT_NE(warning.find("rgb.txt line 6"), std::string::npos) << warning;
  EXPECT_NE(warning.find("skipped"), std::string::npos) << warning;
  // No pair at all: the counts of entries.
  TumReaderOptions tight;
  tight.max_time_difference = 0.001;
  const std::string msg = ErrorOf([&] { TumReader r(folder, tight); });
  EXPECT_NE(msg.find("all 7 depth and 7 colour entries are unpaired"), std::string::npos) << msg;
  // Empty lists.
  const std::string empty = TempFolder("empty");
  std::ofstream(empty + "/depth.txt") << "# nothing\n";
  std::ofstream(empty + "/rgb.txt") << "1.0 rgb/a.png\n";
  std::ofstream(empty + "/camera.yaml") << "{width: 4, height: 3, fx: 5, fy: 5, cx: 1.5, cy: 1}";
  const std::string e = ErrorOf([&] { TumReader r(empty); });
  EXPECT_NE(e.find("depth.txt: expected at least one entry, found none"), std::string::npos) << e;
}

}  // namespace
}  // namespace artex
