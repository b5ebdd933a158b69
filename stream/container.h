// The .artx stream container, version 2 (spec: docs/streaming.md): a header (codec, frame
// rate, pose quantisation, atlas size, viewpoint, the template as GLB bytes) and one framed
// record per frame (sync word, frame index, keyframe flag, pose / coverage / video payloads,
// from version 2 an optional rest-shape payload, CRC-32). Version 1 streams (no rest shapes)
// are read as well. Little-endian throughout. The reader checks every length and CRC; a damaged or
// truncated record is reported with its byte offset and the reader resynchronises on the next
// sync word that starts an intact record.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "render/camera.h"

namespace artex {

constexpr uint16_t kStreamVersion = 2;
constexpr uint16_t kOldestStreamVersion = 1;  // the oldest version the reader accepts

struct StreamHeader {
  uint16_t version = kStreamVersion;
  uint32_t frame_rate_num = 30, frame_rate_den = 1;
  uint8_t codec = 1;            // 0 none (no texture), 1 VP9, 2 H.264, 3 AV1 (VideoCodec)
  uint8_t pose_prediction = 1;  // 0 previous, 1 velocity (PosePrediction)
  uint16_t num_joints = 0;
  uint16_t atlas_width = 0, atlas_height = 0;
  uint32_t num_triangles = 0;
  double scale_step = 0.0, translation_step = 0.0, rotation_step = 0.0;
  uint32_t keyframe_interval = 0;
  uint32_t target_kbps = 0;  // texture video target
  PinholeCamera camera;      // the sender's colour camera (a default viewpoint)
  std::string glb;           // the template (EncodeTemplateGlb), sent once

  double frame_rate() const { return static_cast<double>(frame_rate_num) / frame_rate_den; }
};

struct StreamRecord {
  std::size_t offset = 0;  // byte offset of the record in the stream
  std::size_t size = 0;    // whole record, framing included
  uint32_t frame = 0;
  bool keyframe = false;
  bool has_mask = false;
  std::vector<uint8_t> pose, mask, video;
  // The subject's rest shape from this frame on (EncodeRestShape; empty: unchanged). Version 2.
  std::vector<uint8_t> shape;
};

struct StreamIssue {
  std::size_t offset = 0;  // byte offset where the damage was found
  int frame = -1;          // the frame expected there (the last intact one + 1; -1 unknown)
  std::string what;
};

constexpr std::size_t kRecordFraming = 24;  // 20-byte record header + CRC-32
// A record with a rest shape has 4 more header bytes (the shape payload's size).
constexpr std::size_t kShapeSizeField = 4;

std::vector<uint8_t> EncodeStreamHeader(const StreamHeader& header);
// True when an encoded record's flags say it carries a rest shape (flag bit 2).
inline bool RecordCarriesRestShape(const std::vector<uint8_t>& record) {
  return record.size() > 8 && (record[8] & 4) != 0;
}
std::vector<uint8_t> EncodeStreamRecord(const StreamRecord& record);

class StreamReader {
 public:
  // Reads the whole stream file; throws artex::Error naming the file for an unreadable file or
  // a damaged header (nothing can be decoded without it).
  explicit StreamReader(const std::string& path);
  // In-memory stream (tests); `name` names it in messages.
  StreamReader(std::vector<uint8_t> bytes, const std::string& name);
  const StreamHeader& header() const { return header_; }
  std::size_t header_size() const { return header_size_; }
  std::size_t size() const { return bytes_.size(); }
  // The next intact record; damaged bytes before it are appended to *issues. False at the end.
  bool Next(StreamRecord* record, std::vector<StreamIssue>* issues);

 private:
  void ParseHeader();
  // An intact record at `offset`: 0 when none, else its size (*why tells what is wrong).
  std::size_t RecordAt(std::size_t offset, StreamRecord* record, std::string* why) const;

  std::string name_;
  std::vector<uint8_t> bytes_;
  StreamHeader header_;
  std::size_t header_size_ = 0;
  std::size_t position_ = 0;
  int last_frame_ = -1;
};

}  // namespace artex
