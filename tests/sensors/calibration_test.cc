#include "sensors/calibration.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "models/error.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

std::string TempFolder(const std::string& name) {
  return testing_util::FreshTempDir("calibration_test_" + name).string();
}

Calibration MakeRig() {
  Calibration c;
  // Kinect depth camera tilted vertically (portrait 480x640), separate 1600x2032 colour camera.
  c.depth.width = 480;
  c.depth.height = 640;
  c.depth.fx = 580.25;
  c.depth.fy = 579.5;
  c.depth.cx = 239.3;
  c.depth.cy = 321.7;
  c.depth.world_to_camera = PinholeCamera::LookAt(
      Eigen::Vector3d(0.1, 1.2, 2.5), Eigen::Vector3d(0, 0.9, 0), Eigen::Vector3d::UnitY());
  c.depth_distortion.k1 = -0.12;
  c.depth_distortion.p2 = 0.001;
  c.color.width = 1600;
  c.color.height = 2032;
  c.color.fx = 1812.125;
  c.color.fy = 1811.0;
  c.color.cx = 801.5;
  c.color.cy = 1015.25;
  c.color.world_to_camera = PinholeCamera::LookAt(
      Eigen::Vector3d(-0.05, 1.25, 2.45), Eigen::Vector3d(0, 0.9, 0), Eigen::Vector3d::UnitY());
  c.color_distortion = {0.05, -0.2, 0.0007, -0.0003, 0.11};
  c.depth_scale = 1000.0;
  c.frame_rate = 30.0;
  return c;
}

std::string ExpectError(const std::string& path) {
  try {
    ReadCalibration(path);
  } catch (const Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "no artex::Error for " << path;
  return "";
}

// Rewrites one line of a valid file: replaces the first occurrence of `from` by `to`.
std::string Mutated(const std::string& folder, const std::string& name, const std::string& from,
                    const std::string& to) {
  const std::string good = folder + "/good.yaml";
  WriteCalibration(MakeRig(), good);
  std::ifstream in(good);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  const std::string path = folder + "/" + name + ".yaml";
  std::ofstream(path) << text;
  return path;
}

TEST(CalibrationTest, RoundTripIsExact) {
  const std::string folder = TempFolder("roundtrip");
  const Calibration c = MakeRig();
  WriteCalibration(c, folder + "/calibration.yaml");
  EXPECT_FALSE(fs::exists(folder + "/calibration.yaml.partial"));
  const Calibration r = ReadCalibration(folder + "/calibration.yaml");
  for (const auto& [a, b] :
       {std::make_pair(&c.depth, &r.depth), std::make_pair(&c.color, &r.color)}) {
    EXPECT_EQ(a->width, b->width);
    EXPECT_EQ(a->height, b->height);
    EXPECT_EQ(a->fx, b->fx);
    EXPECT_EQ(a->fy, b->fy);
    EXPECT_EQ(a->cx, b->cx);
    EXPECT_EQ(a->cy, b->cy);
    EXPECT_EQ((a->world_to_camera.matrix() - b->world_to_camera.matrix()).norm(), 0.0);
  }
  EXPECT_EQ(r.depth_distortion.k1, -0.12);
  EXPECT_EQ(r.depth_distortion.p2, 0.001);
  EXPECT_EQ(r.depth_distortion.k2, 0.0);
  EXPECT_EQ(r.color_distortion.k3, 0.11);
  EXPECT_EQ(r.color_distortion.p1, 0.0007);
  EXPECT_EQ(r.depth_scale, 1000.0);
  EXPECT_EQ(r.frame_rate, 30.0);
  EXPECT_LT((r.DepthToColor().matrix() - c.DepthToColor().matrix()).norm(), 1e-15);
}

TEST(CalibrationTest, DepthToColorMapsDepthCameraPointsIntoColourCamera) {
  const Calibration c = MakeRig();
  const Eigen::Vector3d world(0.3, 1.1, 0.2);
  const Eigen::Vector3d in_depth = c.depth.world_to_camera * world;
  EXPECT_LT((c.DepthToColor() * in_depth - c.color.world_to_camera * world).norm(), 1e-12);
}

TEST(CalibrationTest, MalformedFilesNameFileFieldExpectedAndFound) {
  const std::string folder = TempFolder("malformed");
  {
    const std::string path = Mutated(folder, "fx_text", "fx: 580.25", "fx: abc");
    const std::string msg = ExpectError(path);
    EXPECT_NE(msg.find(path), std::string::npos) << msg;
    EXPECT_NE(msg.find("depth.fx"), std::string::npos) << msg;
    EXPECT_NE(msg.find("expected a number"), std::string::npos) << msg;
    EXPECT_NE(msg.find("'abc'"), std::string::npos) << msg;
    EXPECT_NE(msg.find("line"), std::string::npos) << msg;
  }
  {
    const std::string msg = ExpectError(Mutated(folder, "fy_negative", "fy: 1811", "fy: -1811"));
    EXPECT_NE(msg.find("color.fy"), std::string::npos) << msg;
    EXPECT_NE(msg.find("positive"), std::string::npos) << msg;
  }
  {
    const std::string msg = ExpectError(Mutated(folder, "missing_cx", "cx: 239.3", "cxx: 239.3"));
    EXPECT_NE(msg.find("depth.cxx"), std::string::npos) << msg;  // unknown key reported first
  }
  {
    const std::string msg = ExpectError(Mutated(folder, "width", "width: 480", "width: 0"));
    EXPECT_NE(msg.find("depth.width"), std::string::npos) << msg;
  }
  {
    const std::string msg =
        ExpectError(Mutated(folder, "scale", "depth_scale: 1000", "depth_scale: x"));
    EXPECT_NE(msg.find("depth_scale"), std::string::npos) << msg;
  }
  {
    const std::string msg =
        ExpectError(Mutated(folder, "rotation", "rotation: [", "rotation: [2, "));
    EXPECT_NE(msg.find("rotation"), std::string::npos) << msg;  // 10 entries instead of 9
    EXPECT_NE(msg.find("9 numbers"), std::string::npos) << msg;
  }
  {
    // A scaled (non-rigid) rotation matrix.
    const std::string path = folder + "/scaled.yaml";
    Calibration c = MakeRig();
    c.depth.world_to_camera.linear() *= 1.01;
    WriteCalibration(c, path);
    const std::string msg = ExpectError(path);
    EXPECT_NE(msg.find("depth.world_to_camera.rotation"), std::string::npos) << msg;
    EXPECT_NE(msg.find("proper rotation"), std::string::npos) << msg;
  }
  {
    const std::string path = folder + "/not_yaml.yaml";
    std::ofstream(path) << "depth: [1, 2\n  : :";
    const std::string msg = ExpectError(path);
    EXPECT_NE(msg.find(path), std::string::npos) << msg;
  }
  {
    const std::string path = folder + "/absent.yaml";
    const std::string msg = ExpectError(path);
    EXPECT_NE(msg.find(path), std::string::npos) << msg;
  }
  {
    const std::string msg = ExpectError(Mutated(folder, "version", "version: 1", "version: 7"));
    EXPECT_NE(msg.find("version"), std::string::npos) << msg;
  }
}

// Issue 20: finite but absurd values, duplicate keys and a folder given as the file.
TEST(CalibrationTest, ImplausibleValuesDuplicateKeysAndFoldersAreErrors) {
  const std::string folder = TempFolder("plausible");
  std::string what = ExpectError(Mutated(folder, "fx", "fx: 580.25", "fx: 1e308"));
  EXPECT_NE(what.find("depth.fx"), std::string::npos) << what;
  EXPECT_NE(what.find("[1, 100000]"), std::string::npos) << what;
  EXPECT_NE(what.find("1e+308"), std::string::npos) << what;
  what = ExpectError(Mutated(folder, "scale", "depth_scale: 1000", "depth_scale: 1e-9"));
  EXPECT_NE(what.find("depth_scale"), std::string::npos) << what;
  what = ExpectError(Mutated(folder, "rate", "frame_rate: 30", "frame_rate: 1e9"));
  EXPECT_NE(what.find("frame_rate"), std::string::npos) << what;
  what = ExpectError(Mutated(folder, "cx", "cx: 801.5", "cx: -1e7"));
  EXPECT_NE(what.find("color.cx"), std::string::npos) << what;
  what = ExpectError(
      Mutated(folder, "duplicate", "depth_scale: 1000", "frame_rate: 25\ndepth_scale: 1000"));
  EXPECT_NE(what.find("frame_rate"), std::string::npos) << what;
  EXPECT_NE(what.find("defined twice"), std::string::npos) << what;
  what = ExpectError(folder);
  EXPECT_NE(what.find(folder), std::string::npos) << what;
  EXPECT_NE(what.find("found a folder"), std::string::npos) << what;
}

TEST(CalibrationTest, DistortionMatchesRadialTangentialModel) {
  PinholeCamera cam;
  cam.fx = 500;
  cam.fy = 510;
  cam.cx = 320;
  cam.cy = 240;
  const Distortion d{0.2624, -0.9531, -0.0054, 0.0026, 1.1633};  // TUM Freiburg 1
  const Eigen::Vector2d pixel(100, 400);
  const double x = (100 - 320) / 500.0, y = (400 - 240) / 510.0;
  const double r2 = x * x + y * y;
  const double radial = 1 + d.k1 * r2 + d.k2 * r2 * r2 + d.k3 * r2 * r2 * r2;
  const double xd = x * radial + 2 * d.p1 * x * y + d.p2 * (r2 + 2 * x * x);
  const double yd = y * radial + d.p1 * (r2 + 2 * y * y) + 2 * d.p2 * x * y;
  const Eigen::Vector2d expected(500 * xd + 320, 510 * yd + 240);
  EXPECT_LT((DistortPixel(cam, d, pixel) - expected).norm(), 1e-9);
  EXPECT_EQ(DistortPixel(cam, Distortion(), pixel), pixel);
  EXPECT_EQ(UndistortPixel(cam, Distortion(), pixel), pixel);
}

TEST(CalibrationTest, UndistortInvertsDistortOverTheImage) {
  PinholeCamera cam;  // 640 x 480
  const Distortion d{0.2624, -0.9531, -0.0054, 0.0026, 1.1633};
  double worst = 0;
  for (int v = 0; v < cam.height; v += 16) {
    for (int u = 0; u < cam.width; u += 16) {
      const Eigen::Vector2d p(u, v);
      const Eigen::Vector2d undistorted = UndistortPixel(cam, d, p);
      worst = std::max(worst, (DistortPixel(cam, d, undistorted) - p).norm());
    }
  }
  EXPECT_LT(worst, 1e-8);
  // And the pixel actually moves (the test is not vacuous).
  EXPECT_GT((UndistortPixel(cam, d, Eigen::Vector2d(10, 10)) - Eigen::Vector2d(10, 10)).norm(),
            1.0);
}

}  // namespace
}  // namespace artex
