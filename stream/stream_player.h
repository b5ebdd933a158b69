// The receiver of the tele-presence stream (docs/streaming.md): reads an .artx stream, decodes
// pose, coverage and atlas per frame and reconstructs the receiver's model (the template from
// the header, posed, with the decoded atlas). Playback starts (or, with from_frame, joins) at
// a keyframe; a damaged or truncated record is reported with its byte offset and frame and
// playback resumes at the next keyframe. Never throws after construction.
#pragma once

#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "models/pose.h"
#include "models/template.h"
#include "stream/container.h"
#include "stream/pose_codec.h"
#include "stream/video_codec.h"

namespace artex {

struct PlayedFrame {
  int frame = 0;
  bool keyframe = false;
  std::size_t offset = 0;
  std::size_t pose_bytes = 0, mask_bytes = 0, video_bytes = 0, record_bytes = 0;
  Pose pose;
  cv::Mat atlas;              // CV_8UC3, the receiver's current atlas (empty without texture)
  std::vector<int> textured;  // F: 1 textured, 0 not (the current coverage)
  double decode_ms = 0.0;     // pose + coverage + video decoding of this record
  // StreamPlayer::model() changed since the previous frame (a rest shape, docs/streaming.md):
  // this frame's pose is of the new shape.
  bool shape_changed = false;
};

class StreamPlayer {
 public:
  // Throws artex::Error for an unreadable stream, a damaged header or an unusable template.
  StreamPlayer(const std::string& path, int from_frame = 0);
  explicit StreamPlayer(std::unique_ptr<StreamReader> reader, int from_frame = 0);
  ~StreamPlayer();
  const StreamHeader& header() const { return reader_->header(); }
  // The receiver's model: the header's template with the latest rest shape read (also from
  // records skipped before from_frame or while waiting for a keyframe).
  const Template& model() const { return model_; }
  std::size_t stream_bytes() const { return reader_->size(); }
  // The next decoded frame; false at the end of the stream.
  bool Next(PlayedFrame* frame);
  // Damage found so far (offset, frame, what), and records skipped while waiting for a keyframe.
  const std::vector<StreamIssue>& issues() const { return issues_; }
  int skipped_records() const { return skipped_; }

 private:
  void Init(int from_frame);

  std::unique_ptr<StreamReader> reader_;
  Template header_model_, model_;
  std::unique_ptr<PoseDecoder> pose_;
  std::unique_ptr<AtlasVideoDecoder> video_;
  std::vector<StreamIssue> issues_;
  cv::Mat atlas_;
  std::vector<uint8_t> coverage_;  // packed textured flags
  int from_frame_ = 0;
  bool need_keyframe_ = true;
  bool started_ = false;
  bool shape_changed_ = false;
  int skipped_ = 0;
};

}  // namespace artex
