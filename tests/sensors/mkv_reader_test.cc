// MkvReader (sensors/mkv_reader.h): a small Matroska file written here with libavformat itself
// (FFV1 gray16le depth track "DEPTH", FFV1 bgr0 colour track "COLOR", colour 5 ms after depth)
// reads back with the same depth and colour pixels, through OpenFrameSource too; missing
// calibration and a file without a depth track give clear errors.
#include "sensors/mkv_reader.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>

#include "models/error.h"
#include "sensors/frame_source.h"
#include "sensors/sequence.h"
#include "tests/error_of.h"
#include "tests/testing_util.h"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/log.h>
}

namespace artex {
namespace {

namespace fs = std::filesystem;

constexpr int kWidth = 32;
constexpr int kHeight = 24;
constexpr int kFrames = 4;

uint16_t DepthValue(int k, int x, int y) {
  return static_cast<uint16_t>(1000 + 300 * k + 37 * x + 11 * y);
}
cv::Vec3b ColorValue(int k, int x, int y) {
  return cv::Vec3b(static_cast<uint8_t>(5 * x), static_cast<uint8_t>(7 * y),
                   static_cast<uint8_t>(40 * k + 3));
}

struct Encoder {
  AVStream* stream = nullptr;
  AVCodecContext* codec = nullptr;
};

void Drain(AVFormatContext* oc, Encoder* e, AVPacket* packet) {
  while (avcodec_receive_packet(e->codec, packet) >= 0) {
    av_packet_rescale_ts(packet, e->codec->time_base, e->stream->time_base);
    packet->stream_index = e->stream->index;
    ASSERT_GE(av_interleaved_write_frame(oc, packet), 0);
  }
}

// Writes the recording; with_depth false leaves out the depth track.
void WriteMkv(const std::string& path, bool with_depth) {
  AVFormatContext* oc = nullptr;
  ASSERT_GE(avformat_alloc_output_context2(&oc, nullptr, "matroska", path.c_str()), 0);
  const AVCodec* ffv1 = avcodec_find_encoder(AV_CODEC_ID_FFV1);
  ASSERT_NE(ffv1, nullptr);
  Encoder depth, color;
  for (Encoder* e : {&depth, &color}) {
    if (e == &depth && !with_depth) continue;
    e->stream = avformat_new_stream(oc, nullptr);
    e->codec = avcodec_alloc_context3(ffv1);
    e->codec->width = kWidth;
    e->codec->height = kHeight;
    e->codec->pix_fmt = e == &depth ? AV_PIX_FMT_GRAY16LE : AV_PIX_FMT_BGR0;
    e->codec->time_base = AVRational{1, 1000};
    if (oc->oformat->flags & AVFMT_GLOBALHEADER) e->codec->flags |= AV_CODEC_FLAG_GLOBAL_HEADER;
    ASSERT_GE(avcodec_open2(e->codec, ffv1, nullptr), 0);
    ASSERT_GE(avcodec_parameters_from_context(e->stream->codecpar, e->codec), 0);
    e->stream->time_base = e->codec->time_base;
    av_dict_set(&e->stream->metadata, "title", e == &depth ? "DEPTH" : "COLOR", 0);
  }
  ASSERT_GE(avio_open(&oc->pb, path.c_str(), AVIO_FLAG_WRITE), 0);
  ASSERT_GE(avformat_write_header(oc, nullptr), 0);
  AVPacket* packet = av_packet_alloc();
  AVFrame* frame = av_frame_alloc();
  for (int k = 0; k < kFrames; ++k) {
    for (Encoder* e : {&depth, &color}) {
      if (!e->codec) continue;
      av_frame_unref(frame);
      frame->format = e->codec->pix_fmt;
      frame->width = kWidth;
      frame->height = kHeight;
      ASSERT_GE(av_frame_get_buffer(frame, 0), 0);
      for (int y = 0; y < kHeight; ++y) {
        uint8_t* row = frame->data[0] + y * frame->linesize[0];
        for (int x = 0; x < kWidth; ++x) {
          if (e == &depth) {
            const uint16_t v = DepthValue(k, x, y);
            row[2 * x] = static_cast<uint8_t>(v & 0xff);
            row[2 * x + 1] = static_cast<uint8_t>(v >> 8);
          } else {
            const cv::Vec3b c = ColorValue(k, x, y);
            row[4 * x] = c[0];
            row[4 * x + 1] = c[1];
            row[4 * x + 2] = c[2];
            row[4 * x + 3] = 0;
          }
        }
      }
      frame->pts = 33 * k + (e == &color ? 5 : 0);
      ASSERT_GE(avcodec_send_frame(e->codec, frame), 0);
      Drain(oc, e, packet);
    }
  }
  for (Encoder* e : {&depth, &color}) {
    if (!e->codec) continue;
    avcodec_send_frame(e->codec, nullptr);
    Drain(oc, e, packet);
    avcodec_free_context(&e->codec);
  }
  ASSERT_GE(av_write_trailer(oc), 0);
  avio_closep(&oc->pb);
  avformat_free_context(oc);
  av_frame_free(&frame);
  av_packet_free(&packet);
}

std::string Folder(const std::string& name) {
  return testing_util::FreshTempDir("mkv_test_" + name).string();
}

Calibration SmallCalibration() {
  Calibration c;
  c.depth.width = c.color.width = kWidth;
  c.depth.height = c.color.height = kHeight;
  c.depth.fx = c.depth.fy = c.color.fx = c.color.fy = 30;
  c.depth.cx = c.color.cx = 15.5;
  c.depth.cy = c.color.cy = 11.5;
  c.color.world_to_camera.translation().x() = -0.032;  // a separate colour camera
  return c;
}

TEST(MkvReaderTest, ReadsBackTheDepthAndColourPixels) {
  ASSERT_TRUE(MkvSupportAvailable());
  av_log_set_level(AV_LOG_ERROR);  // the FFV1 encoder's notes
  const std::string folder = Folder("basic");
  const std::string path = folder + "/capture.mkv";
  WriteMkv(path, true);
  WriteCalibration(SmallCalibration(), folder + "/capture.yaml");
  MkvReader reader(path);
  ASSERT_EQ(reader.num_frames(), kFrames);
  EXPECT_EQ(reader.calibration().depth.fx, 30);
  EXPECT_NEAR(reader.calibration().DepthToColor().translation().x(), -0.032, 1e-12);
  EXPECT_NE(reader.Description().find("capture.yaml"), std::string::npos) << reader.Description();
  // Out of order on purpose: frames are found by seeking.
  for (int k : {2, 0, 3, 1}) {
    Frame f;
    std::string warning;
    ASSERT_TRUE(reader.ReadFrame(k, &f, &warning)) << warning;
    EXPECT_EQ(f.index, k);
    EXPECT_NEAR(f.depth_timestamp, 0.033 * k, 1e-9);
    EXPECT_NEAR(f.color_timestamp - f.depth_timestamp, 0.005, 1e-9);
    ASSERT_EQ(f.depth.type(), CV_16UC1);
    ASSERT_EQ(f.color.type(), CV_8UC3);
    int depth_errors = 0, color_errors = 0;
    for (int y = 0; y < kHeight; ++y) {
      for (int x = 0; x < kWidth; ++x) {
        depth_errors += f.depth.at<uint16_t>(y, x) != DepthValue(k, x, y);
        color_errors += f.color.at<cv::Vec3b>(y, x) != ColorValue(k, x, y);
      }
    }
    EXPECT_EQ(depth_errors, 0) << "frame " << k;
    EXPECT_EQ(color_errors, 0) << "frame " << k;
  }
  // Through OpenFrameSource: detected by the extension; the calibration may be given.
  EXPECT_EQ(DetectFrameSource(path), FrameSourceKind::kMatroska);
  fs::rename(folder + "/capture.yaml", folder + "/rig.yaml");
  const std::string msg = ErrorOf([&] { OpenFrameSource(path); });
  EXPECT_NE(msg.find("capture.yaml"), std::string::npos) << msg;
  EXPECT_NE(msg.find("calibration.yaml"), std::string::npos) << msg;
  FrameSourceOptions options;
  options.mkv.calibration_path = folder + "/rig.yaml";
  const std::unique_ptr<FrameSource> source = OpenFrameSource(path, options);
  EXPECT_EQ(source->num_frames(), kFrames);
  // A window narrower than the 5 ms lag pairs nothing.
  options.mkv.max_time_difference = 0.001;
  EXPECT_NE(ErrorOf([&] { OpenFrameSource(path, options); }).find("unpaired"), std::string::npos);
}

TEST(MkvReaderTest, ImportWritesTheSamePixelsAsAnArtexSequence) {
  ASSERT_TRUE(fs::exists(ARTEX_BINARY)) << ARTEX_BINARY;
  av_log_set_level(AV_LOG_ERROR);
  const std::string folder = Folder("import");
  WriteMkv(folder + "/capture.mkv", true);
  WriteCalibration(SmallCalibration(), folder + "/calibration.yaml");
  const std::string command = "'" + std::string(ARTEX_BINARY) + "' import -q '" + folder +
                              "/capture.mkv' -o '" + folder +
                              "/seq' --world-frame calibration > '" + folder + "/log.txt' 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0);
  MkvReader mkv(folder + "/capture.mkv");
  SequenceReader seq(folder + "/seq");
  ASSERT_EQ(seq.num_frames(), kFrames);
  for (int k = 0; k < kFrames; ++k) {
    Frame a, b;
    std::string warning;
    ASSERT_TRUE(mkv.ReadFrame(k, &a, &warning)) << warning;
    ASSERT_TRUE(seq.ReadFrame(k, &b, &warning)) << warning;
    EXPECT_EQ(cv::norm(a.depth, b.depth, cv::NORM_INF), 0.0) << k;
    EXPECT_EQ(cv::norm(a.color, b.color, cv::NORM_INF), 0.0) << k;
  }
  EXPECT_TRUE(seq.calibration().DepthToColor().isApprox(SmallCalibration().DepthToColor()));
}

TEST(MkvReaderTest, NoDepthTrackNamesTheTracks) {
  av_log_set_level(AV_LOG_ERROR);
  const std::string folder = Folder("no_depth");
  const std::string path = folder + "/colour_only.mkv";
  WriteMkv(path, false);
  WriteCalibration(SmallCalibration(), folder + "/calibration.yaml");
  const std::string msg = ErrorOf([&] { MkvReader reader(path); });
  EXPECT_NE(msg.find("16-bit depth track"), std::string::npos) << msg;
  EXPECT_NE(msg.find("COLOR"), std::string::npos) << msg;
  EXPECT_NE(ErrorOf([&] { MkvReader reader(folder + "/missing.mkv"); }).find("missing.mkv"),
            std::string::npos);
}

}  // namespace
}  // namespace artex
