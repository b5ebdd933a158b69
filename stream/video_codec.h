// Atlas video through FFmpeg's libavcodec (docs/streaming.md): the texture atlas of every frame
// is one picture of a video (VP9 through libvpx by default; H.264 through libx264 and AV1
// through libaom for comparison), real-time settings without frame lag so each frame gives
// one packet, a target bitrate with the encoder's rate control, and keyframes on request.
// Pictures are 8-bit 4:2:0 (OpenCV's BT.601 studio-range BGR <-> I420 conversion on both ends,
// signalled in the bitstream).
#pragma once

#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace artex {

enum class VideoCodec { kVp9 = 1, kH264 = 2, kAv1 = 3 };

const char* VideoCodecName(VideoCodec c);             // vp9 | h264 | av1
VideoCodec ParseVideoCodec(const std::string& name);  // throws artex::Error

struct VideoEncoderOptions {
  VideoCodec codec = VideoCodec::kVp9;
  int bitrate_kbps = 600;  // target bitrate of the atlas video (kbit/s); >= 10
  // Rate-control buffer (ms of the target rate): shorter follows the target more tightly.
  int buffer_ms = 1000;
  // Encoder speed: libvpx / libaom cpu-used (0..8, the range FFmpeg passes on), libx264 preset
  // by 9 - speed (9 ultrafast, 8 superfast, 7 veryfast, ..., 1 and 0 veryslow).
  int speed = 8;
  int threads = 1;           // encoder threads; >= 1 (a second one gains nothing next to tracking)
  double min_quantizer = 4;  // libvpx / libaom qmin (0..63); keeps static texture sharp

  bool IsValid(std::string* error) const;
};

class AtlasVideoEncoder {
 public:
  // width, height: even, >= 16; frame_rate > 0. Throws artex::Error when the codec is not
  // available in this FFmpeg or rejects the settings.
  AtlasVideoEncoder(int width, int height, double frame_rate, const VideoEncoderOptions& options);
  ~AtlasVideoEncoder();
  // bgr: CV_8UC3 width x height. Returns one packet (lag-free); *keyframe is true when it is
  // an intra frame (always when force_keyframe).
  std::vector<uint8_t> Encode(const cv::Mat& bgr, bool force_keyframe, bool* keyframe);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

class AtlasVideoDecoder {
 public:
  AtlasVideoDecoder(VideoCodec codec, int width, int height);  // throws artex::Error
  ~AtlasVideoDecoder();
  // Decodes one packet into *bgr (CV_8UC3 width x height); false with a reason for a packet the
  // decoder rejects or that yields no picture.
  bool Decode(const uint8_t* data, std::size_t size, cv::Mat* bgr, std::string* error);
  void Reset();  // drops the reference pictures (before resuming at a keyframe)

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// PSNR (dB) of two equal-size CV_8UC3 images over all pixels (+inf when identical).
double ImagePsnr(const cv::Mat& a, const cv::Mat& b);

}  // namespace artex
