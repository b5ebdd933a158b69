// OpenFrameSource / DetectFrameSource (sensors/frame_source.h): the layout decides the reader,
// options reach the TUM reader, and a folder that is neither layout fails naming what was
// looked for.
#include "sensors/frame_source.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <string>

#include "models/error.h"
#include "tests/error_of.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

std::string Folder(const std::string& name) {
  return testing_util::FreshTempDir("frame_source_test_" + name).string();
}

Calibration SmallCalibration() {
  Calibration c;
  c.depth.width = c.color.width = 8;
  c.depth.height = c.color.height = 6;
  c.depth.fx = c.depth.fy = c.color.fx = c.color.fy = 10;
  c.depth.cx = c.color.cx = 3.5;
  c.depth.cy = c.color.cy = 2.5;
  return c;
}

// Two frames of an artex sequence: depth k + 1 m.
std::string WriteArtex(const std::string& name) {
  const std::string folder = Folder(name);
  SequenceWriter writer(folder, SmallCalibration());
  for (int k = 0; k < 2; ++k) {
    Frame f;
    f.index = k;
    f.depth_timestamp = f.color_timestamp = k / 30.0;
    f.depth = cv::Mat(6, 8, CV_16UC1, cv::Scalar(1000 * (k + 1)));
    f.color = cv::Mat(6, 8, CV_8UC3, cv::Scalar(1, 2, 3));
    writer.AddFrame(f);
  }
  writer.Finish();
  return folder;
}

// Three TUM pairs, 8 x 6, without camera.yaml.
std::string WriteTum(const std::string& name) {
  const std::string folder = Folder(name);
  fs::create_directories(folder + "/rgb");
  fs::create_directories(folder + "/depth");
  std::ofstream rgb(folder + "/rgb.txt"), depth(folder + "/depth.txt");
  for (int k = 0; k < 3; ++k) {
    const std::string n = std::to_string(100 + k) + ".png";
    cv::imwrite(folder + "/depth/" + n, cv::Mat(6, 8, CV_16UC1, cv::Scalar(5000)));
    cv::imwrite(folder + "/rgb/" + n, cv::Mat(6, 8, CV_8UC3, cv::Scalar(0, 0, 0)));
    depth << 100 + k / 30.0 << " depth/" << n << "\n";
    rgb << 100 + k / 30.0 + 0.005 << " rgb/" << n << "\n";
  }
  return folder;
}

TEST(FrameSourceTest, DetectsTheLayout) {
  const std::string artex = WriteArtex("artex");
  EXPECT_EQ(DetectFrameSource(artex), FrameSourceKind::kArtexSequence);
  const std::string tum = WriteTum("tum");
  EXPECT_EQ(DetectFrameSource(tum), FrameSourceKind::kTumRgbd);
  EXPECT_EQ(FrameSourceKindName(FrameSourceKind::kTumRgbd), "TUM RGB-D folder");
}

TEST(FrameSourceTest, OpensTheRightReader) {
  const std::unique_ptr<FrameSource> artex = OpenFrameSource(WriteArtex("open_artex"));
  ASSERT_NE(dynamic_cast<SequenceReader*>(artex.get()), nullptr);
  EXPECT_EQ(artex->num_frames(), 2);
  EXPECT_FALSE(artex->gravity().has_value());
  EXPECT_NE(artex->Description().find("artex sequence"), std::string::npos);
  Frame f;
  std::string warning;
  ASSERT_TRUE(artex->ReadFrame(1, &f, &warning)) << warning;
  EXPECT_EQ(f.depth.at<uint16_t>(2, 3), 2000);

  const std::string tum = WriteTum("open_tum");
  // Without camera.yaml the TUM reader needs intrinsics; the options carry a preset.
  const std::string msg = ErrorOf([&] { OpenFrameSource(tum); });
  EXPECT_NE(msg.find("camera.yaml"), std::string::npos) << msg;
  std::ofstream(tum + "/camera.yaml") << "{width: 8, height: 6, fx: 10, fy: 10, cx: 3.5, cy: 2.5}";
  FrameSourceOptions options;
  options.tum.max_time_difference = 0.001;  // the 5 ms lag no longer pairs
  EXPECT_NE(ErrorOf([&] { OpenFrameSource(tum, options); }).find("unpaired"), std::string::npos);
  options.tum.max_time_difference = 0.01;
  const std::unique_ptr<FrameSource> source = OpenFrameSource(tum, options);
  ASSERT_NE(dynamic_cast<TumReader*>(source.get()), nullptr);
  EXPECT_EQ(source->num_frames(), 3);
  EXPECT_EQ(source->calibration().depth_scale, 5000.0);
  ASSERT_TRUE(source->ReadFrame(2, &f, &warning)) << warning;
  EXPECT_EQ(f.depth.at<uint16_t>(0, 0), 5000);
  options.tum.SetIntrinsics("fr3");
  EXPECT_EQ(OpenFrameSource(tum, options)->calibration().depth.fx, 535.4);
  // Invalid options fail before anything is read.
  options.tum.max_time_difference = -1;
  EXPECT_NE(ErrorOf([&] { OpenFrameSource(tum, options); }).find("max_time_difference"),
            std::string::npos);
}

TEST(FrameSourceTest, NeitherLayoutNamesTheFolderAndTheFiles) {
  const std::string empty = Folder("neither");
  std::ofstream(empty + "/notes.txt") << "hello\n";
  const std::string msg = ErrorOf([&] { OpenFrameSource(empty); });
  for (const std::string& part : {empty, std::string("calibration.yaml"), std::string("frames.csv"),
                                  std::string("rgb.txt"), std::string("depth.txt")}) {
    EXPECT_NE(msg.find(part), std::string::npos) << part << " in: " << msg;
  }
  EXPECT_NE(ErrorOf([&] { OpenFrameSource(empty + "/missing"); }).find("found nothing"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] {
              OpenFrameSource(empty + "/notes.txt");
            }).find("found a file with extension '.txt'"),
            std::string::npos);
  // An incomplete artex sequence is an artex sequence that fails on its missing file.
  std::ofstream(empty + "/calibration.yaml") << "x: 1\n";
  EXPECT_EQ(DetectFrameSource(empty), FrameSourceKind::kArtexSequence);
  EXPECT_THROW(OpenFrameSource(empty), Error);
}

}  // namespace
}  // namespace artex
