#include "stream/video_codec.h"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavutil/imgutils.h>
#include <libavutil/opt.h>
}

#include <cmath>
#include <cstring>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "models/error.h"

namespace artex {
namespace {

std::string AvError(int code) {
  char buffer[AV_ERROR_MAX_STRING_SIZE] = {0};
  av_strerror(code, buffer, sizeof(buffer));
  return buffer;
}

const char* EncoderName(VideoCodec c) {
  switch (c) {
    case VideoCodec::kVp9:
      return "libvpx-vp9";
    case VideoCodec::kH264:
      return "libx264";
    case VideoCodec::kAv1:
      return "libaom-av1";
  }
  return "";
}

AVCodecID CodecId(VideoCodec c) {
  switch (c) {
    case VideoCodec::kVp9:
      return AV_CODEC_ID_VP9;
    case VideoCodec::kH264:
      return AV_CODEC_ID_H264;
    case VideoCodec::kAv1:
      return AV_CODEC_ID_AV1;
  }
  return AV_CODEC_ID_NONE;
}

// Copies an I420 picture (OpenCV layout: Y rows, then U, then V, contiguous) into `frame`.
void I420ToFrame(const cv::Mat& i420, int width, int height, AVFrame* frame) {
  const uint8_t* y = i420.data;
  const uint8_t* u = y + width * height;
  const uint8_t* v = u + (width / 2) * (height / 2);
  for (int r = 0; r < height; ++r)
    std::memcpy(frame->data[0] + r * frame->linesize[0], y + r * width, width);
  for (int r = 0; r < height / 2; ++r) {
    std::memcpy(frame->data[1] + r * frame->linesize[1], u + r * (width / 2), width / 2);
    std::memcpy(frame->data[2] + r * frame->linesize[2], v + r * (width / 2), width / 2);
  }
}

// Sets an encoder option; a value the encoder rejects (out of its range in this FFmpeg) is an
// error rather than a silent fallback to the encoder's default.
void SetEncoderOption(AVCodecContext* c, VideoCodec codec, const char* key,
                      const std::string& value) {
  const int rc = av_opt_set(c->priv_data, key, value.c_str(), 0);
  if (rc < 0)
    throw Error(std::string("atlas video: ") + EncoderName(codec) + " rejects " + key + "=" +
                value + ": " + AvError(rc));
}

}  // namespace

const char* VideoCodecName(VideoCodec c) {
  switch (c) {
    case VideoCodec::kVp9:
      return "vp9";
    case VideoCodec::kH264:
      return "h264";
    case VideoCodec::kAv1:
      return "av1";
  }
  return "?";
}

VideoCodec ParseVideoCodec(const std::string& name) {
  if (name == "vp9") return VideoCodec::kVp9;
  if (name == "h264") return VideoCodec::kH264;
  if (name == "av1") return VideoCodec::kAv1;
  throw Error("stream.codec: expected vp9, h264 or av1, found " + name);
}

bool VideoEncoderOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (bitrate_kbps < 10)
    msg << "stream.texture_kbps: expected >= 10, found " << bitrate_kbps;
  else if (buffer_ms < 1)
    msg << "stream.buffer_ms: expected >= 1, found " << buffer_ms;
  else if (speed < 0 || speed > (codec == VideoCodec::kH264 ? 9 : 8))
    msg << "stream.speed: expected 0.." << (codec == VideoCodec::kH264 ? 9 : 8) << " for "
        << VideoCodecName(codec) << ", found " << speed;
  else if (threads < 1)
    msg << "stream.threads: expected >= 1, found " << threads;
  else if (!(min_quantizer >= 0 && min_quantizer <= 63))
    msg << "stream.min_quantizer: expected 0..63, found " << min_quantizer;
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

struct AtlasVideoEncoder::Impl {
  AVCodecContext* ctx = nullptr;
  AVFrame* frame = nullptr;
  AVPacket* packet = nullptr;
  int width = 0, height = 0;
  int64_t pts = 0;
  ~Impl() {
    av_packet_free(&packet);
    av_frame_free(&frame);
    avcodec_free_context(&ctx);
  }
};

AtlasVideoEncoder::AtlasVideoEncoder(int width, int height, double frame_rate,
                                     const VideoEncoderOptions& options)
    : impl_(std::make_unique<Impl>()) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(why);
  if (width < 16 || height < 16 || width % 2 || height % 2 || !(frame_rate > 0))
    throw Error("atlas video: expected even sizes >= 16 and a frame rate > 0, found " +
                std::to_string(width) + "x" + std::to_string(height));
  av_log_set_level(AV_LOG_ERROR);  // libav's banner and notices are no library output
  const AVCodec* codec = avcodec_find_encoder_by_name(EncoderName(options.codec));
  if (!codec)
    throw Error(std::string("atlas video: this FFmpeg has no ") + EncoderName(options.codec) +
                " encoder");
  Impl& m = *impl_;
  m.width = width;
  m.height = height;
  m.ctx = avcodec_alloc_context3(codec);
  AVCodecContext* c = m.ctx;
  c->width = width;
  c->height = height;
  c->pix_fmt = AV_PIX_FMT_YUV420P;
  const int fps = std::max(1, static_cast<int>(std::lround(frame_rate)));
  c->time_base = AVRational{1, fps};
  c->framerate = AVRational{fps, 1};
  c->bit_rate = 1000LL * options.bitrate_kbps;
  c->rc_max_rate = c->bit_rate;
  c->rc_min_rate = c->bit_rate;  // constant bitrate (libvpx CBR mode)
  c->rc_buffer_size = static_cast<int>(c->bit_rate * options.buffer_ms / 1000);
  c->gop_size = std::numeric_limits<int>::max() / 2;  // keyframes only on request
  c->max_b_frames = 0;
  c->thread_count = options.threads;
  c->color_range = AVCOL_RANGE_MPEG;
  c->colorspace = AVCOL_SPC_SMPTE170M;
  c->color_primaries = AVCOL_PRI_SMPTE170M;
  c->color_trc = AVCOL_TRC_SMPTE170M;
  const std::string speed = std::to_string(options.speed);
  const VideoCodec id = options.codec;
  switch (id) {
    case VideoCodec::kVp9:
      SetEncoderOption(c, id, "deadline", "realtime");
      SetEncoderOption(c, id, "cpu-used", speed);
      SetEncoderOption(c, id, "lag-in-frames", "0");
      SetEncoderOption(c, id, "row-mt", "1");
      SetEncoderOption(c, id, "tile-columns", "1");
      c->qmin = static_cast<int>(options.min_quantizer);
      c->qmax = 63;
      break;
    case VideoCodec::kAv1:
      SetEncoderOption(c, id, "usage", "realtime");
      SetEncoderOption(c, id, "cpu-used", speed);
      SetEncoderOption(c, id, "lag-in-frames", "0");
      SetEncoderOption(c, id, "row-mt", "1");
      c->qmin = static_cast<int>(options.min_quantizer);
      c->qmax = 63;
      break;
    case VideoCodec::kH264: {
      static const char* kPresets[] = {"ultrafast", "superfast", "veryfast", "faster",  "fast",
                                       "medium",    "slow",      "slower",   "veryslow"};
      SetEncoderOption(c, id, "preset", kPresets[std::max(0, std::min(8, 9 - options.speed))]);
      SetEncoderOption(c, id, "tune", "zerolatency");
      SetEncoderOption(c, id, "forced-idr", "1");
      break;
    }
  }
  const int rc = avcodec_open2(c, codec, nullptr);
  if (rc < 0)
    throw Error(std::string("atlas video: cannot open ") + EncoderName(options.codec) + ": " +
                AvError(rc));
  m.frame = av_frame_alloc();
  m.frame->format = c->pix_fmt;
  m.frame->width = width;
  m.frame->height = height;
  if (av_frame_get_buffer(m.frame, 0) < 0) throw Error("atlas video: cannot allocate a frame");
  m.packet = av_packet_alloc();
}

AtlasVideoEncoder::~AtlasVideoEncoder() = default;

std::vector<uint8_t> AtlasVideoEncoder::Encode(const cv::Mat& bgr, bool force_keyframe,
                                               bool* keyframe) {
  Impl& m = *impl_;
  if (bgr.type() != CV_8UC3 || bgr.cols != m.width || bgr.rows != m.height)
    throw Error("atlas video: expected a " + std::to_string(m.width) + "x" +
                std::to_string(m.height) + " BGR image, found " + std::to_string(bgr.cols) + "x" +
                std::to_string(bgr.rows));
  if (av_frame_make_writable(m.frame) < 0) throw Error("atlas video: frame not writable");
  cv::Mat i420;
  cv::cvtColor(bgr, i420, cv::COLOR_BGR2YUV_I420);
  I420ToFrame(i420, m.width, m.height, m.frame);
  m.frame->pts = m.pts++;
  m.frame->pict_type = force_keyframe ? AV_PICTURE_TYPE_I : AV_PICTURE_TYPE_NONE;
  m.frame->key_frame = force_keyframe ? 1 : 0;
  int rc = avcodec_send_frame(m.ctx, m.frame);
  if (rc < 0) throw Error("atlas video: encoding failed: " + AvError(rc));
  std::vector<uint8_t> out;
  *keyframe = false;
  while ((rc = avcodec_receive_packet(m.ctx, m.packet)) >= 0) {
    out.insert(out.end(), m.packet->data, m.packet->data + m.packet->size);
    *keyframe = *keyframe || (m.packet->flags & AV_PKT_FLAG_KEY);
    av_packet_unref(m.packet);
  }
  if (rc != AVERROR(EAGAIN) && rc != AVERROR_EOF)
    throw Error("atlas video: encoding failed: " + AvError(rc));
  return out;
}

struct AtlasVideoDecoder::Impl {
  AVCodecContext* ctx = nullptr;
  AVFrame* frame = nullptr;
  AVPacket* packet = nullptr;
  int width = 0, height = 0;
  ~Impl() {
    av_packet_free(&packet);
    av_frame_free(&frame);
    avcodec_free_context(&ctx);
  }
};

AtlasVideoDecoder::AtlasVideoDecoder(VideoCodec codec_type, int width, int height)
    : impl_(std::make_unique<Impl>()) {
  const AVCodec* codec = avcodec_find_decoder(CodecId(codec_type));
  if (!codec)
    throw Error(std::string("atlas video: this FFmpeg has no ") + VideoCodecName(codec_type) +
                " decoder");
  Impl& m = *impl_;
  m.width = width;
  m.height = height;
  m.ctx = avcodec_alloc_context3(codec);
  m.ctx->thread_count = 1;  // frame threading would delay pictures
  const int rc = avcodec_open2(m.ctx, codec, nullptr);
  if (rc < 0) throw Error("atlas video: cannot open the decoder: " + AvError(rc));
  m.frame = av_frame_alloc();
  m.packet = av_packet_alloc();
}

AtlasVideoDecoder::~AtlasVideoDecoder() = default;

void AtlasVideoDecoder::Reset() { avcodec_flush_buffers(impl_->ctx); }

bool AtlasVideoDecoder::Decode(const uint8_t* data, std::size_t size, cv::Mat* bgr,
                               std::string* error) {
  Impl& m = *impl_;
  if (av_new_packet(m.packet, static_cast<int>(size)) < 0) {
    if (error) *error = "cannot allocate a packet";
    return false;
  }
  std::memcpy(m.packet->data, data, size);
  int rc = avcodec_send_packet(m.ctx, m.packet);
  av_packet_unref(m.packet);
  if (rc < 0) {
    if (error) *error = "the video decoder rejects the packet: " + AvError(rc);
    return false;
  }
  bool got = false;
  while ((rc = avcodec_receive_frame(m.ctx, m.frame)) >= 0) {
    if (m.frame->width != m.width || m.frame->height != m.height ||
        m.frame->format != AV_PIX_FMT_YUV420P) {
      if (error) *error = "the video decoder gives a picture of another size or format";
      av_frame_unref(m.frame);
      return false;
    }
    cv::Mat i420(m.height * 3 / 2, m.width, CV_8UC1);
    for (int r = 0; r < m.height; ++r)
      std::memcpy(i420.ptr(r), m.frame->data[0] + r * m.frame->linesize[0], m.width);
    uint8_t* u = i420.ptr(m.height);
    uint8_t* v = u + (m.width / 2) * (m.height / 2);
    for (int r = 0; r < m.height / 2; ++r) {
      std::memcpy(u + r * (m.width / 2), m.frame->data[1] + r * m.frame->linesize[1], m.width / 2);
      std::memcpy(v + r * (m.width / 2), m.frame->data[2] + r * m.frame->linesize[2], m.width / 2);
    }
    cv::cvtColor(i420, *bgr, cv::COLOR_YUV2BGR_I420);
    av_frame_unref(m.frame);
    got = true;
  }
  if (rc != AVERROR(EAGAIN) && rc != AVERROR_EOF) {
    if (error) *error = "video decoding failed: " + AvError(rc);
    return false;
  }
  if (!got && error) *error = "the packet gives no picture";
  return got;
}

double ImagePsnr(const cv::Mat& a, const cv::Mat& b) {
  const double n = cv::norm(a, b, cv::NORM_L2SQR);
  if (n == 0.0) return std::numeric_limits<double>::infinity();
  return 10.0 * std::log10(255.0 * 255.0 * a.total() * a.channels() / n);
}

}  // namespace artex
