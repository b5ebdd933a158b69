#include "stream/stream_sender.h"

#include <time.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "models/error.h"
#include "models/template_io.h"
#include "stream/rest_shape.h"

namespace artex {
namespace {

double MsSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

double ThreadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

}  // namespace

bool StreamOptions::IsValid(std::string* error) const {
  if (!pose.IsValid(error) || !video.IsValid(error)) return false;
  std::ostringstream msg;
  if (keyframe_interval < 1)
    msg << "stream.keyframe_interval: expected >= 1, found " << keyframe_interval;
  else if (video_size < 0 || video_size % 2 || (video_size > 0 && video_size < 16))
    msg << "stream.video_size: expected 0 or an even value >= 16, found " << video_size;
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

std::vector<uint8_t> PackCoverage(const std::vector<int>& frames) {
  std::vector<uint8_t> bits((frames.size() + 7) / 8, 0);
  for (std::size_t f = 0; f < frames.size(); ++f)
    if (frames[f] >= 0) bits[f / 8] |= static_cast<uint8_t>(1u << (f % 8));
  return bits;
}

std::vector<int> UnpackCoverage(const std::vector<uint8_t>& bits, int num_triangles) {
  std::vector<int> out(num_triangles, 0);
  for (int f = 0; f < num_triangles && f / 8 < static_cast<int>(bits.size()); ++f)
    out[f] = (bits[f / 8] >> (f % 8)) & 1;
  return out;
}

std::vector<uint8_t> EncodeCoverage(const std::vector<uint8_t>& packed,
                                    const std::vector<uint8_t>* previous) {
  std::vector<uint8_t> bits = packed;
  if (previous && previous->size() == bits.size())
    for (std::size_t i = 0; i < bits.size(); ++i) bits[i] ^= (*previous)[i];
  uLongf size = compressBound(static_cast<uLong>(bits.size()));
  std::vector<uint8_t> out(size);
  if (compress2(out.data(), &size, bits.data(), static_cast<uLong>(bits.size()), 9) != Z_OK)
    throw Error("stream: coverage compression failed");
  out.resize(size);
  return out;
}

bool DecodeCoverage(const std::vector<uint8_t>& payload, int num_triangles, bool keyframe,
                    std::vector<uint8_t>* out) {
  std::vector<uint8_t> bits((num_triangles + 7) / 8);
  uLongf size = static_cast<uLongf>(bits.size());
  if (uncompress(bits.data(), &size, payload.data(), static_cast<uLong>(payload.size())) != Z_OK ||
      size != bits.size())
    return false;
  if (!keyframe) {
    if (out->size() != bits.size()) return false;
    for (std::size_t i = 0; i < bits.size(); ++i) bits[i] ^= (*out)[i];
  }
  *out = std::move(bits);
  return true;
}

std::vector<int> HandVertices(const Template& tmpl) {
  std::vector<uint8_t> hand_joint(tmpl.num_joints(), 0);
  for (int j = 0; j < tmpl.num_joints(); ++j) {
    std::string name = tmpl.joints[j].name;
    std::transform(name.begin(), name.end(), name.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    hand_joint[j] =
        name.find("wrist") != std::string::npos || name.find("hand") != std::string::npos;
  }
  std::vector<int> out;
  for (int v = 0; v < tmpl.num_vertices(); ++v)
    if (hand_joint[tmpl.vertex_joint[v]]) out.push_back(v);
  if (out.empty())
    for (int v = 0; v < tmpl.num_vertices(); ++v) out.push_back(v);
  return out;
}

StreamSender::StreamSender(const std::string& path, const Template& tmpl,
                           const PinholeCamera& camera, double frame_rate, int atlas_size,
                           bool texture, const StreamOptions& options)
    : path_(path),
      template_(tmpl),
      options_(options),
      pose_encoder_(tmpl.num_joints(), options.pose) {
  std::string why;
  if (!options_.IsValid(&why)) throw Error(why);
  if (!(frame_rate > 0)) throw Error(path + ": stream frame rate must be > 0");
  const int side = options_.video_size > 0 ? options_.video_size : atlas_size;
  if (texture) {
    video_ = std::make_unique<AtlasVideoEncoder>(side, side, frame_rate, options_.video);
  }
  StreamHeader& h = header_;
  h.frame_rate_num = static_cast<uint32_t>(std::lround(frame_rate * 1000));
  h.frame_rate_den = 1000;
  h.codec = texture ? static_cast<uint8_t>(options_.video.codec) : 0;
  h.pose_prediction = static_cast<uint8_t>(options_.pose.prediction);
  h.num_joints = static_cast<uint16_t>(tmpl.num_joints());
  h.atlas_width = h.atlas_height = static_cast<uint16_t>(texture ? side : 0);
  h.num_triangles = static_cast<uint32_t>(tmpl.num_triangles());
  h.scale_step = options_.pose.scale_step;
  h.translation_step = options_.pose.translation_step;
  h.rotation_step = options_.pose.rotation_step;
  h.keyframe_interval = static_cast<uint32_t>(options_.keyframe_interval);
  h.target_kbps = static_cast<uint32_t>(options_.video.bitrate_kbps);
  h.camera = camera;
  h.glb = EncodeTemplateGlb(tmpl);
  if (options_.measure_pose_error) {
    skinning_ = std::make_unique<Skinning>(template_);
    hand_vertices_ = HandVertices(template_);
  }
  temp_path_ = path + ".tmp" + std::to_string(::getpid());
  out_.open(temp_path_, std::ios::binary | std::ios::trunc);
  if (!out_) throw Error(path + ": cannot write the stream");
  const std::vector<uint8_t> bytes = EncodeStreamHeader(h);
  out_.write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
  summary_.header_bytes = bytes.size();
  header_bytes_ = bytes;
  summary_.glb_bytes = h.glb.size();
  summary_.frame_rate = frame_rate;
}

StreamSender::~StreamSender() {
  if (!finished_) {
    out_.close();
    std::error_code ec;
    std::filesystem::remove(temp_path_, ec);
  }
}

StreamFrameStats StreamSender::AddFrame(int frame, const Pose& pose, const cv::Mat& atlas,
                                        const std::vector<int>* triangle_frames,
                                        double compose_ms) {
  if (finished_) throw Error(path_ + ": frame added after Finish");
  StreamFrameStats s;
  s.frame = frame;
  s.compose_ms = compose_ms;
  StreamRecord record;
  record.frame = static_cast<uint32_t>(frame);
  record.shape = std::move(pending_shape_);
  pending_shape_.clear();
  bool keyframe = summary_.frames % options_.keyframe_interval == 0 || !record.shape.empty();
  if (video_) {
    const auto t = std::chrono::steady_clock::now();
    const double cpu = ThreadCpuMs();
    cv::Mat picture = atlas;
    const int side = header_.atlas_width;
    if (atlas.cols != side || atlas.rows != side)
      cv::resize(atlas, picture, cv::Size(side, side), 0, 0, cv::INTER_AREA);
    bool intra = false;
    record.video = video_->Encode(picture, keyframe, &intra);
    keyframe = keyframe || intra;
    s.video_ms = MsSince(t);
    s.video_cpu_ms = ThreadCpuMs() - cpu;
    std::vector<int> all;
    if (!triangle_frames) all.assign(template_.num_triangles(), 0);
    std::vector<uint8_t> bits = PackCoverage(triangle_frames ? *triangle_frames : all);
    if (keyframe || bits != last_bits_) {
      record.mask = EncodeCoverage(bits, keyframe ? nullptr : &last_bits_);
      record.has_mask = true;
      last_bits_ = std::move(bits);
    }
  }
  const auto t_pose = std::chrono::steady_clock::now();
  Pose decoded;
  record.pose = pose_encoder_.Encode(pose, keyframe, &decoded);
  s.pose_ms = MsSince(t_pose);
  record.keyframe = keyframe;
  if (skinning_) {
    Eigen::MatrixX3d a, b;
    skinning_->Apply(pose, &a);
    skinning_->Apply(decoded, &b);
    double worst = 0.0;
    for (int v : hand_vertices_) worst = std::max(worst, (a.row(v) - b.row(v)).norm());
    s.hand_error_mm = 1000.0 * worst;
  }
  const std::vector<uint8_t> bytes = EncodeStreamRecord(record);
  out_.write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
  if (!out_) throw Error(path_ + ": writing the stream failed");
  out_.flush();  // readers of the growing file (the viewer's server) see whole records
  last_record_ = bytes;
  s.keyframe = keyframe;
  s.pose_bytes = record.pose.size();
  s.mask_bytes = record.mask.size();
  s.video_bytes = record.video.size();
  s.shape_bytes = record.shape.size();
  s.record_bytes = bytes.size();
  StreamSummary& m = summary_;
  ++m.frames;
  m.keyframes += keyframe;
  m.pose_bytes += s.pose_bytes;
  m.mask_bytes += s.mask_bytes;
  m.video_bytes += s.video_bytes;
  m.shapes += s.shape_bytes > 0;
  m.shape_bytes += s.shape_bytes;
  m.framing_bytes +=
      s.record_bytes - s.pose_bytes - s.mask_bytes - s.video_bytes - s.shape_bytes;
  m.per_frame.push_back(s);
  return s;
}

void StreamSender::SetRestShape(const Template& shaped) {
  if (finished_) throw Error(path_ + ": rest shape set after Finish");
  pending_shape_ = EncodeRestShape(template_, shaped);
  if (skinning_) skinning_ = std::make_unique<Skinning>(shaped);
}

StreamSummary StreamSender::Finish() {
  if (finished_) return summary_;
  out_.close();
  if (!out_) throw Error(path_ + ": writing the stream failed");
  std::error_code ec;
  std::filesystem::rename(temp_path_, path_, ec);
  if (ec) throw Error(path_ + ": cannot move the stream into place: " + ec.message());
  finished_ = true;
  StreamSummary& m = summary_;
  if (m.frames > 0) {
    const double per_frame_to_kbps = 8.0 * m.frame_rate / 1000.0 / m.frames;
    m.pose_kbps = m.pose_bytes * per_frame_to_kbps;
    m.texture_kbps = (m.video_bytes + m.mask_bytes) * per_frame_to_kbps;
    m.total_kbps = (m.pose_bytes + m.video_bytes + m.mask_bytes + m.shape_bytes +
                    m.framing_bytes) *
                   per_frame_to_kbps;
    double sum = 0.0;
    for (const StreamFrameStats& s : m.per_frame) {
      m.max_hand_error_mm = std::max(m.max_hand_error_mm, s.hand_error_mm);
      sum += s.hand_error_mm;
      m.mean_encode_ms += s.pose_ms + s.video_ms;
      m.max_encode_ms = std::max(m.max_encode_ms, s.pose_ms + s.video_ms);
      m.mean_encode_cpu_ms += s.video_cpu_ms;
      m.mean_compose_ms += s.compose_ms;
      m.max_compose_ms = std::max(m.max_compose_ms, s.compose_ms);
    }
    m.mean_hand_error_mm = sum / m.frames;
    m.mean_encode_ms /= m.frames;
    m.mean_encode_cpu_ms /= m.frames;
    m.mean_compose_ms /= m.frames;
  }
  return m;
}

}  // namespace artex
