// The atlas video (stream/video_codec.h) with each codec a stream can carry (VP9, H.264): the
// encoder's rate control follows the target bitrate (a higher target spends more bytes, the
// achieved rate is near the target), keyframes come exactly when requested, and a decoder that
// starts at a requested keyframe gives the same pictures as one that decoded from the start.
#include "stream/video_codec.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "models/error.h"

namespace artex {
namespace {

constexpr int kSide = 256;
constexpr int kFrames = 60;
constexpr int kKeyframeInterval = 20;
constexpr double kFrameRate = 30.0;

// Stripes and a chart-like grid; every frame one band of rows is redrawn with fresh noise (an
// atlas region resampled from a new image), so every frame costs bits.
cv::Mat Picture(int frame) {
  cv::Mat a(kSide, kSide, CV_8UC3);
  for (int y = 0; y < kSide; ++y)
    for (int x = 0; x < kSide; ++x)
      a.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<uchar>(128 + 90 * std::sin(x / 7.0)),
                                        static_cast<uchar>(128 + 90 * std::cos(y / 11.0)),
                                        static_cast<uchar>(((x / 16 + y / 16) % 2) ? 200 : 40));
  const int band = kSide / 8;
  cv::Mat rows = a.rowRange((frame * band) % kSide, (frame * band) % kSide + band);
  cv::Mat noise(rows.size(), CV_8UC3);
  cv::RNG rng(static_cast<uint64_t>(frame) + 1);
  rng.fill(noise, cv::RNG::NORMAL, 0, 25);
  cv::add(rows, noise, rows);
  return a;
}

struct Encoded {
  std::vector<std::vector<uint8_t>> packets;
  std::vector<bool> keyframes;
  double delta_kbps = 0.0;  // non-keyframe packets at the frame rate
};

Encoded Encode(VideoCodec codec, int kbps) {
  VideoEncoderOptions o;
  o.codec = codec;
  o.bitrate_kbps = kbps;
  o.threads = 1;
  AtlasVideoEncoder encoder(kSide, kSide, kFrameRate, o);
  Encoded out;
  double delta_bytes = 0.0;
  int deltas = 0;
  for (int f = 0; f < kFrames; ++f) {
    bool key = false;
    out.packets.push_back(encoder.Encode(Picture(f), f % kKeyframeInterval == 0, &key));
    out.keyframes.push_back(key);
    if (!key) {
      delta_bytes += out.packets.back().size();
      ++deltas;
    }
  }
  out.delta_kbps = deltas ? 8.0 * delta_bytes / deltas * kFrameRate / 1000.0 : 0.0;
  return out;
}

std::vector<cv::Mat> Decode(VideoCodec codec, const Encoded& e, int from) {
  AtlasVideoDecoder decoder(codec, kSide, kSide);
  std::vector<cv::Mat> out;
  for (int f = from; f < kFrames; ++f) {
    cv::Mat picture;
    std::string why;
    EXPECT_TRUE(decoder.Decode(e.packets[f].data(), e.packets[f].size(), &picture, &why))
        << "frame " << f << ": " << why;
    out.push_back(picture);
  }
  return out;
}

class VideoCodecTest : public ::testing::TestWithParam<VideoCodec> {};

TEST_P(VideoCodecTest, RateControlFollowsTheTarget) {
  const Encoded low = Encode(GetParam(), 300);
  const Encoded high = Encode(GetParam(), 1200);
  std::printf("%s: target 300 -> %.0f kbit/s, target 1200 -> %.0f kbit/s (delta frames)\n",
              VideoCodecName(GetParam()), low.delta_kbps, high.delta_kbps);
  EXPECT_GT(high.delta_kbps, 2.0 * low.delta_kbps);
  EXPECT_GT(low.delta_kbps, 0.5 * 300);
  EXPECT_LT(low.delta_kbps, 1.5 * 300);
  EXPECT_GT(high.delta_kbps, 0.5 * 1200);
  EXPECT_LT(high.delta_kbps, 1.5 * 1200);
  // More rate, better pictures.
  const std::vector<cv::Mat> a = Decode(GetParam(), low, 0), b = Decode(GetParam(), high, 0);
  double psnr_low = 0.0, psnr_high = 0.0;
  for (int f = 0; f < kFrames; ++f) {
    psnr_low += ImagePsnr(a[f], Picture(f)) / kFrames;
    psnr_high += ImagePsnr(b[f], Picture(f)) / kFrames;
  }
  EXPECT_GT(psnr_high, psnr_low + 1.0);
}

TEST_P(VideoCodecTest, KeyframesExactlyWhenRequestedAndDecodableAlone) {
  const Encoded e = Encode(GetParam(), 600);
  for (int f = 0; f < kFrames; ++f)
    EXPECT_EQ(e.keyframes[f], f % kKeyframeInterval == 0) << "frame " << f;
  const std::vector<cv::Mat> all = Decode(GetParam(), e, 0);
  const std::vector<cv::Mat> joined = Decode(GetParam(), e, kKeyframeInterval);
  ASSERT_EQ(static_cast<int>(joined.size()), kFrames - kKeyframeInterval);
  for (std::size_t k = 0; k < joined.size(); ++k)
    EXPECT_EQ(cv::norm(joined[k], all[kKeyframeInterval + k], cv::NORM_INF), 0.0) << "frame " << k;
}

// A speed the encoder does not take is an error, not a silent fallback to its default (this
// FFmpeg passes libvpx cpu-used 0..8 only; 9 is x264's ultrafast).
TEST(VideoEncoderOptionsTest, SpeedOutsideTheEncodersRangeIsAnError) {
  VideoEncoderOptions o;
  o.codec = VideoCodec::kVp9;
  o.speed = 9;
  std::string why;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("stream.speed"), std::string::npos) << why;
  EXPECT_THROW(AtlasVideoEncoder(kSide, kSide, kFrameRate, o), Error);
  o.codec = VideoCodec::kH264;
  EXPECT_TRUE(o.IsValid(&why)) << why;
  AtlasVideoEncoder ultrafast(kSide, kSide, kFrameRate, o);
  bool key = false;
  EXPECT_FALSE(ultrafast.Encode(Picture(0), true, &key).empty());
  EXPECT_TRUE(key);
}

INSTANTIATE_TEST_SUITE_P(Codecs, VideoCodecTest,
                         ::testing::Values(VideoCodec::kVp9, VideoCodec::kH264),
                         [](const ::testing::TestParamInfo<VideoCodec>& info) {
                           return std::string(VideoCodecName(info.param));
                         });

}  // namespace
}  // namespace artex
