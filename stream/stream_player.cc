#include "stream/stream_player.h"

#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>

#include "models/error.h"
#include "models/template_io.h"
#include "stream/rest_shape.h"
#include "stream/stream_sender.h"

namespace artex {
namespace {

Template TemplateFromGlb(const std::string& glb, const std::string& name) {
  namespace fs = std::filesystem;
  const fs::path tmp =
      fs::temp_directory_path() / ("artex_stream_template_" + std::to_string(::getpid()) + ".glb");
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out.write(glb.data(), static_cast<std::streamsize>(glb.size()));
    if (!out) throw Error(name + ": cannot write the header's template to " + tmp.string());
  }
  Template tmpl;
  try {
    tmpl = ReadTemplateGlb(tmp.string());
  } catch (const Error& e) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw Error(name + ": the header's template: " + e.what());
  }
  std::error_code ec;
  fs::remove(tmp, ec);
  return tmpl;
}

}  // namespace

StreamPlayer::StreamPlayer(const std::string& path, int from_frame)
    : reader_(std::make_unique<StreamReader>(path)) {
  Init(from_frame);
}

StreamPlayer::StreamPlayer(std::unique_ptr<StreamReader> reader, int from_frame)
    : reader_(std::move(reader)) {
  Init(from_frame);
}

StreamPlayer::~StreamPlayer() = default;

void StreamPlayer::Init(int from_frame) {
  const StreamHeader& h = reader_->header();
  header_model_ = TemplateFromGlb(h.glb, "stream");
  model_ = header_model_;
  if (model_.num_joints() != h.num_joints ||
      model_.num_triangles() != static_cast<int>(h.num_triangles))
    throw Error("stream header: joints/triangles disagree with its template");
  PoseCodecOptions po;
  po.scale_step = h.scale_step;
  po.translation_step = h.translation_step;
  po.rotation_step = h.rotation_step;
  po.prediction = h.pose_prediction == 0 ? PosePrediction::kPrevious : PosePrediction::kVelocity;
  pose_ = std::make_unique<PoseDecoder>(h.num_joints, po);
  if (h.codec != 0) {
    video_ = std::make_unique<AtlasVideoDecoder>(static_cast<VideoCodec>(h.codec), h.atlas_width,
                                                 h.atlas_height);
    atlas_ = cv::Mat(h.atlas_height, h.atlas_width, CV_8UC3, cv::Scalar(0, 0, 0));
  }
  coverage_.assign((model_.num_triangles() + 7) / 8, 0);
  from_frame_ = from_frame;
}

bool StreamPlayer::Next(PlayedFrame* out) {
  StreamRecord r;
  while (true) {
    const std::size_t before = issues_.size();
    if (!reader_->Next(&r, &issues_)) return false;
    if (issues_.size() != before) need_keyframe_ = true;
    if (!r.shape.empty()) {
      // The shape is state like the header's template: taken from skipped records too.
      std::string why;
      if (!DecodeRestShape(r.shape, header_model_, &model_, &why)) {
        issues_.push_back({r.offset, static_cast<int>(r.frame),
                           "frame " + std::to_string(r.frame) + ": " + why +
                               "; waiting for a keyframe"});
        need_keyframe_ = true;
        ++skipped_;
        continue;
      }
      shape_changed_ = true;
    }
    if (static_cast<int>(r.frame) < from_frame_ || (need_keyframe_ && !r.keyframe)) {
      ++skipped_;
      continue;
    }
    const auto t = std::chrono::steady_clock::now();
    const auto damage = [&](const std::string& what) {
      issues_.push_back({r.offset, static_cast<int>(r.frame), what + "; waiting for a keyframe"});
      need_keyframe_ = true;
      pose_->Reset();
      if (video_) video_->Reset();
    };
    if (r.keyframe && need_keyframe_ && started_) {
      pose_->Reset();
      if (video_) video_->Reset();
    }
    std::string why;
    Pose pose;
    if (!pose_->Decode(r.pose.data(), r.pose.size(), r.keyframe, &pose, &why)) {
      damage("frame " + std::to_string(r.frame) + ": " + why);
      continue;
    }
    if (r.has_mask) {
      std::vector<uint8_t> coverage = coverage_;
      if (!DecodeCoverage(r.mask, model_.num_triangles(), r.keyframe, &coverage)) {
        damage("frame " + std::to_string(r.frame) + ": damaged coverage payload");
        continue;
      }
      coverage_ = std::move(coverage);
    } else if (r.keyframe && video_) {
      damage("frame " + std::to_string(r.frame) + ": keyframe without coverage");
      continue;
    }
    if (video_ && !r.video.empty()) {
      cv::Mat atlas;
      if (!video_->Decode(r.video.data(), r.video.size(), &atlas, &why)) {
        damage("frame " + std::to_string(r.frame) + ": " + why);
        continue;
      }
      atlas_ = atlas;
    }
    need_keyframe_ = false;
    started_ = true;
    out->frame = static_cast<int>(r.frame);
    out->keyframe = r.keyframe;
    out->offset = r.offset;
    out->pose_bytes = r.pose.size();
    out->mask_bytes = r.mask.size();
    out->video_bytes = r.video.size();
    out->record_bytes = r.size;
    out->pose = pose;
    out->shape_changed = shape_changed_;
    shape_changed_ = false;
    out->atlas = atlas_;
    out->textured = UnpackCoverage(coverage_, model_.num_triangles());
    out->decode_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
    return true;
  }
}

}  // namespace artex
