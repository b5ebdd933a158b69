#include "sensors/mkv_reader.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>
#include <tuple>

#include "models/error.h"

#ifdef ARTEX_HAVE_LIBAV
extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/imgutils.h>
#include <libswscale/swscale.h>
}
#endif

namespace artex {
namespace fs = std::filesystem;

bool MkvReaderOptions::IsValid(std::string* error) const {
  if (!(max_time_difference >= 0) || !std::isfinite(max_time_difference)) {
    if (error) *error = "input.max_time_difference: expected a finite number >= 0";
    return false;
  }
  return true;
}

#ifndef ARTEX_HAVE_LIBAV

bool MkvSupportAvailable() { return false; }

struct MkvReader::Impl {};

MkvReader::MkvReader(const std::string& path, const MkvReaderOptions&) {
  throw Error(path + ": reading .mkv needs artex built with libavformat (libavformat-dev)");
}
MkvReader::~MkvReader() = default;
const Calibration& MkvReader::calibration() const { throw Error("MkvReader: unavailable"); }
int MkvReader::num_frames() const { return 0; }
bool MkvReader::ReadFrame(int, Frame*, std::string*) { return false; }
std::vector<cv::Mat> MkvReader::ReadBackgroundFrames() { return {}; }
std::string MkvReader::Description() const { return ""; }

#else

bool MkvSupportAvailable() { return true; }

namespace {

std::string AvError(int code) {
  char buf[AV_ERROR_MAX_STRING_SIZE] = {0};
  av_strerror(code, buf, sizeof(buf));
  return buf;
}

std::string StreamTitle(const AVStream* s) {
  const AVDictionaryEntry* e = av_dict_get(s->metadata, "title", nullptr, 0);
  return e ? e->value : "";
}

bool IsGray16(int format) { return format == AV_PIX_FMT_GRAY16LE || format == AV_PIX_FMT_GRAY16BE; }

struct Track {
  int stream = -1;
  AVCodecContext* codec = nullptr;
  std::vector<int64_t> pts;  // in stream time base, sorted
  double time_base = 0;      // s per pts unit
};

}  // namespace

struct MkvReader::Impl {
  std::string path;
  std::string calibration_path;
  Calibration calibration;
  AVFormatContext* format = nullptr;
  Track depth, color;
  std::vector<std::pair<int, int> > pairs;  // (depth index, colour index)
  int unmatched_depth = 0, unmatched_color = 0;
  AVPacket* packet = nullptr;
  AVFrame* decoded = nullptr;
  SwsContext* sws = nullptr;

  ~Impl() {
    for (Track* t : {&depth, &color}) avcodec_free_context(&t->codec);
    av_packet_free(&packet);
    av_frame_free(&decoded);
    sws_freeContext(sws);
    if (format) avformat_close_input(&format);
  }

  void OpenDecoder(Track* t) {
    const AVCodecParameters* par = format->streams[t->stream]->codecpar;
    const AVCodec* codec = avcodec_find_decoder(par->codec_id);
    if (!codec) {
      throw Error(path + ": track " + std::to_string(t->stream) + ": no decoder for codec '" +
                  avcodec_get_name(par->codec_id) + "'");
    }
    t->codec = avcodec_alloc_context3(codec);
    avcodec_parameters_to_context(t->codec, par);
    t->codec->thread_count = 1;  // one packet in, one frame out
    const int r = avcodec_open2(t->codec, codec, nullptr);
    if (r < 0) throw Error(path + ": cannot open the " + codec->name + " decoder: " + AvError(r));
    t->time_base = av_q2d(format->streams[t->stream]->time_base);
  }

  // Decodes the frame of track t with timestamp pts into `decoded`; false (with *warning)
  // when it cannot be found or decoded.
  bool Decode(Track* t, int64_t pts, std::string* warning) {
    const std::string what = path + ": " + (t == &depth ? "depth" : "colour") + " frame at " +
                             std::to_string(pts * t->time_base) + " s";
    int r = av_seek_frame(format, t->stream, pts, AVSEEK_FLAG_BACKWARD);
    if (r < 0) {
      if (warning) *warning = what + ": seek failed: " + AvError(r);
      return false;
    }
    avcodec_flush_buffers(t->codec);
    while ((r = av_read_frame(format, packet)) >= 0) {
      const bool mine = packet->stream_index == t->stream;
      const int64_t packet_pts = packet->pts;
      if (mine) r = avcodec_send_packet(t->codec, packet);
      av_packet_unref(packet);
      if (!mine) continue;
      if (r < 0) break;
      while ((r = avcodec_receive_frame(t->codec, decoded)) >= 0) {
        const int64_t frame_pts = decoded->best_effort_timestamp != AV_NOPTS_VALUE
                                      ? decoded->best_effort_timestamp
                                      : packet_pts;
        if (frame_pts == pts) return true;
        if (frame_pts > pts) break;
      }
      if (packet_pts > pts) break;
    }
    if (warning) *warning = what + ": not decodable" + (r < 0 ? ": " + AvError(r) : "");
    return false;
  }
};

MkvReader::MkvReader(const std::string& path, const MkvReaderOptions& options)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.path = path;
  std::string why;
  if (!options.IsValid(&why)) throw Error(why);
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw Error(path + ": expected an .mkv file, found none");
  int r = avformat_open_input(&m.format, path.c_str(), nullptr, nullptr);
  if (r < 0) throw Error(path + ": cannot open as Matroska: " + AvError(r));
  r = avformat_find_stream_info(m.format, nullptr);
  if (r < 0) throw Error(path + ": cannot read the tracks: " + AvError(r));

  // Tracks by title, else by pixel format.
  std::string tracks;
  for (unsigned s = 0; s < m.format->nb_streams; ++s) {
    const AVStream* st = m.format->streams[s];
    if (st->codecpar->codec_type != AVMEDIA_TYPE_VIDEO) continue;
    const std::string title = StreamTitle(st);
    tracks += (tracks.empty() ? "" : ", ") + std::to_string(s) + " '" + title + "' " +
              avcodec_get_name(st->codecpar->codec_id);
    if (title == "DEPTH") m.depth.stream = static_cast<int>(s);
    if (title == "COLOR") m.color.stream = static_cast<int>(s);
  }
  for (unsigned s = 0; s < m.format->nb_streams && m.depth.stream < 0; ++s) {
    const AVStream* st = m.format->streams[s];
    if (st->codecpar->codec_type == AVMEDIA_TYPE_VIDEO && IsGray16(st->codecpar->format) &&
        static_cast<int>(s) != m.color.stream) {
      m.depth.stream = static_cast<int>(s);
    }
  }
  for (unsigned s = 0; s < m.format->nb_streams && m.color.stream < 0; ++s) {
    const AVStream* st = m.format->streams[s];
    if (st->codecpar->codec_type == AVMEDIA_TYPE_VIDEO && static_cast<int>(s) != m.depth.stream &&
        StreamTitle(st) != "IR") {
      m.color.stream = static_cast<int>(s);
    }
  }
  if (m.depth.stream < 0 || m.color.stream < 0) {
    throw Error(path +
                ": expected a 16-bit depth track (title DEPTH or 16-bit grey) and a colour "
                "track (title COLOR or another video track), found video tracks: " +
                (tracks.empty() ? std::string("none") : tracks));
  }
  if (!IsGray16(m.format->streams[m.depth.stream]->codecpar->format)) {
    throw Error(path + ": track " + std::to_string(m.depth.stream) +
                " (DEPTH): expected 16-bit grey pixels (b16g, gray16), found " +
                std::string(av_get_pix_fmt_name(static_cast<AVPixelFormat>(
                                m.format->streams[m.depth.stream]->codecpar->format))
                                ? av_get_pix_fmt_name(static_cast<AVPixelFormat>(
                                      m.format->streams[m.depth.stream]->codecpar->format))
                                : "unknown"));
  }
  m.OpenDecoder(&m.depth);
  m.OpenDecoder(&m.color);
  m.packet = av_packet_alloc();
  m.decoded = av_frame_alloc();

  // Calibration.
  const fs::path file(path);
  std::vector<std::string> tried;
  if (!options.calibration_path.empty()) {
    tried.push_back(options.calibration_path);
  } else {
    tried.push_back((file.parent_path() / (file.stem().string() + ".yaml")).string());
    tried.push_back((file.parent_path() / "calibration.yaml").string());
  }
  for (const std::string& t : tried) {
    if (fs::is_regular_file(t, ec)) {
      m.calibration_path = t;
      break;
    }
  }
  if (m.calibration_path.empty()) {
    std::string list;
    for (const std::string& t : tried) list += (list.empty() ? "" : " or ") + t;
    throw Error(path + ": missing calibration: expected " + list +
                " (the artex calibration.yaml format: depth and colour cameras, their poses and "
                "depth_scale, docs/formats.md; set input.calibration to give another file)");
  }
  m.calibration = ReadCalibration(m.calibration_path);
  for (const Track* t : {&m.depth, &m.color}) {
    const AVCodecParameters* par = m.format->streams[t->stream]->codecpar;
    const PinholeCamera& cam = t == &m.depth ? m.calibration.depth : m.calibration.color;
    if (par->width != cam.width || par->height != cam.height) {
      throw Error(m.calibration_path + ": the " + (t == &m.depth ? "depth" : "colour") +
                  " camera is " + std::to_string(cam.width) + "x" + std::to_string(cam.height) +
                  ", expected the size of track " + std::to_string(t->stream) + " of " + path +
                  ": " + std::to_string(par->width) + "x" + std::to_string(par->height));
    }
  }

  // Index: the timestamps of both tracks.
  while ((r = av_read_frame(m.format, m.packet)) >= 0) {
    Track* t = m.packet->stream_index == m.depth.stream   ? &m.depth
               : m.packet->stream_index == m.color.stream ? &m.color
                                                          : nullptr;
    if (t && m.packet->pts != AV_NOPTS_VALUE) t->pts.push_back(m.packet->pts);
    av_packet_unref(m.packet);
  }
  for (Track* t : {&m.depth, &m.color}) std::sort(t->pts.begin(), t->pts.end());
  if (m.depth.pts.empty() || m.color.pts.empty()) {
    throw Error(path + ": expected depth and colour frames, found " +
                std::to_string(m.depth.pts.size()) + " depth and " +
                std::to_string(m.color.pts.size()) + " colour frames");
  }
  // Nearest pairs within the window, greedy one-to-one by increasing difference.
  std::vector<std::tuple<double, int, int> > candidates;
  for (int di = 0; di < static_cast<int>(m.depth.pts.size()); ++di) {
    const double td = m.depth.pts[di] * m.depth.time_base;
    for (int ci = 0; ci < static_cast<int>(m.color.pts.size()); ++ci) {
      const double diff = std::abs(td - m.color.pts[ci] * m.color.time_base);
      if (diff <= options.max_time_difference) candidates.emplace_back(diff, di, ci);
    }
  }
  std::sort(candidates.begin(), candidates.end());
  std::vector<char> du(m.depth.pts.size(), 0), cu(m.color.pts.size(), 0);
  for (const auto& [diff, di, ci] : candidates) {
    if (du[di] || cu[ci]) continue;
    du[di] = cu[ci] = 1;
    m.pairs.emplace_back(di, ci);
  }
  std::sort(m.pairs.begin(), m.pairs.end());
  m.unmatched_depth = static_cast<int>(m.depth.pts.size() - m.pairs.size());
  m.unmatched_color = static_cast<int>(m.color.pts.size() - m.pairs.size());
  if (m.pairs.empty()) {
    throw Error(path + ": expected depth/colour frames within " +
                std::to_string(options.max_time_difference) +
                " s (input.max_time_difference), found none: all " +
                std::to_string(m.depth.pts.size()) + " depth and " +
                std::to_string(m.color.pts.size()) + " colour frames are unpaired");
  }
}

MkvReader::~MkvReader() = default;

const Calibration& MkvReader::calibration() const { return impl_->calibration; }
int MkvReader::num_frames() const { return static_cast<int>(impl_->pairs.size()); }
std::vector<cv::Mat> MkvReader::ReadBackgroundFrames() { return {}; }

std::string MkvReader::Description() const {
  const Impl& m = *impl_;
  std::ostringstream s;
  s << "Matroska recording " << m.path << ": " << m.pairs.size() << " depth/colour pairs of "
    << m.depth.pts.size() << " depth (track " << m.depth.stream << ", "
    << avcodec_get_name(m.depth.codec->codec_id) << ") and " << m.color.pts.size()
    << " colour frames (track " << m.color.stream << ", "
    << avcodec_get_name(m.color.codec->codec_id) << "), " << m.unmatched_depth << " depth and "
    << m.unmatched_color << " colour unpaired; calibration from " << m.calibration_path;
  return s.str();
}

bool MkvReader::ReadFrame(int i, Frame* frame, std::string* warning) {
  Impl& m = *impl_;
  if (i < 0 || i >= num_frames()) {
    throw Error(m.path + ": frame " + std::to_string(i) + " requested, expected 0.." +
                std::to_string(num_frames() - 1));
  }
  const auto [di, ci] = m.pairs[i];
  frame->index = i;
  frame->depth_timestamp = m.depth.pts[di] * m.depth.time_base;
  frame->color_timestamp = m.color.pts[ci] * m.color.time_base;
  if (!m.Decode(&m.depth, m.depth.pts[di], warning)) return false;
  const AVFrame* d = m.decoded;
  if (!IsGray16(d->format) || d->width != m.calibration.depth.width ||
      d->height != m.calibration.depth.height) {
    if (warning) *warning = m.path + ": frame " + std::to_string(i) + ": unexpected depth image";
    return false;
  }
  frame->depth.create(d->height, d->width, CV_16UC1);
  const bool big_endian = d->format == AV_PIX_FMT_GRAY16BE;
  for (int y = 0; y < d->height; ++y) {
    const uint8_t* src = d->data[0] + static_cast<std::ptrdiff_t>(y) * d->linesize[0];
    uint16_t* dst = frame->depth.ptr<uint16_t>(y);
    for (int x = 0; x < d->width; ++x) {
      const uint8_t a = src[2 * x], b = src[2 * x + 1];
      dst[x] = big_endian ? static_cast<uint16_t>(a << 8 | b) : static_cast<uint16_t>(b << 8 | a);
    }
  }
  if (!m.Decode(&m.color, m.color.pts[ci], warning)) return false;
  const AVFrame* c = m.decoded;
  m.sws = sws_getCachedContext(m.sws, c->width, c->height, static_cast<AVPixelFormat>(c->format),
                               c->width, c->height, AV_PIX_FMT_BGR24, SWS_POINT, nullptr, nullptr,
                               nullptr);
  if (!m.sws) {
    if (warning) *warning = m.path + ": frame " + std::to_string(i) + ": colour not convertible";
    return false;
  }
  frame->color.create(c->height, c->width, CV_8UC3);
  uint8_t* dst[4] = {frame->color.data, nullptr, nullptr, nullptr};
  int dst_stride[4] = {static_cast<int>(frame->color.step), 0, 0, 0};
  sws_scale(m.sws, c->data, c->linesize, 0, c->height, dst, dst_stride);
  return true;
}

#endif  // ARTEX_HAVE_LIBAV

}  // namespace artex
