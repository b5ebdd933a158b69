#include "stream/container.h"

#include <zlib.h>

#include <cstring>
#include <fstream>
#include <iterator>
#include <sstream>

#include "models/error.h"

namespace artex {
namespace {

const char kMagic[4] = {'A', 'R', 'T', 'X'};
const char kSync[4] = {'A', 'R', 'X', 'F'};
constexpr std::size_t kMaxPayload = 64u << 20;  // a record larger than this is damage

class Writer {
 public:
  template <class T>
  void Put(T v) {
    uint8_t b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));  // little-endian hosts (x86-64, arm64)
    bytes.insert(bytes.end(), b, b + sizeof(T));
  }
  void PutBytes(const void* p, std::size_t n) {
    const auto* c = static_cast<const uint8_t*>(p);
    bytes.insert(bytes.end(), c, c + n);
  }
  void PutCrc(std::size_t from) {
    Put<uint32_t>(static_cast<uint32_t>(
        crc32(0L, bytes.data() + from, static_cast<uInt>(bytes.size() - from))));
  }
  std::vector<uint8_t> bytes;
};

class Cursor {
 public:
  Cursor(const std::vector<uint8_t>& b, std::size_t at) : bytes_(b), at_(at) {}
  template <class T>
  bool Get(T* v) {
    if (at_ + sizeof(T) > bytes_.size()) return false;
    std::memcpy(v, bytes_.data() + at_, sizeof(T));
    at_ += sizeof(T);
    return true;
  }
  std::size_t at() const { return at_; }

 private:
  const std::vector<uint8_t>& bytes_;
  std::size_t at_;
};

uint32_t Crc(const std::vector<uint8_t>& b, std::size_t from, std::size_t to) {
  return static_cast<uint32_t>(crc32(0L, b.data() + from, static_cast<uInt>(to - from)));
}

}  // namespace

std::vector<uint8_t> EncodeStreamHeader(const StreamHeader& h) {
  Writer w;
  w.PutBytes(kMagic, 4);
  w.Put<uint16_t>(h.version);
  w.Put<uint16_t>(0);  // flags
  w.Put<uint32_t>(0);  // header size, patched below
  w.Put<uint32_t>(h.frame_rate_num);
  w.Put<uint32_t>(h.frame_rate_den);
  w.Put<uint8_t>(h.codec);
  w.Put<uint8_t>(h.pose_prediction);
  w.Put<uint16_t>(h.num_joints);
  w.Put<uint16_t>(h.atlas_width);
  w.Put<uint16_t>(h.atlas_height);
  w.Put<uint32_t>(h.num_triangles);
  w.Put<double>(h.scale_step);
  w.Put<double>(h.translation_step);
  w.Put<double>(h.rotation_step);
  w.Put<uint32_t>(h.keyframe_interval);
  w.Put<uint32_t>(h.target_kbps);
  w.Put<uint16_t>(static_cast<uint16_t>(h.camera.width));
  w.Put<uint16_t>(static_cast<uint16_t>(h.camera.height));
  w.Put<double>(h.camera.fx);
  w.Put<double>(h.camera.fy);
  w.Put<double>(h.camera.cx);
  w.Put<double>(h.camera.cy);
  const Eigen::Matrix4d m = h.camera.world_to_camera.matrix();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) w.Put<double>(m(r, c));
  w.Put<uint32_t>(static_cast<uint32_t>(h.glb.size()));
  w.PutBytes(h.glb.data(), h.glb.size());
  const uint32_t size = static_cast<uint32_t>(w.bytes.size() + 4);
  std::memcpy(w.bytes.data() + 8, &size, 4);
  w.PutCrc(0);
  return w.bytes;
}

std::vector<uint8_t> EncodeStreamRecord(const StreamRecord& r) {
  if (r.pose.size() > 0xffff || r.mask.size() > kMaxPayload || r.video.size() > kMaxPayload ||
      r.shape.size() > kMaxPayload)
    throw Error("stream record of frame " + std::to_string(r.frame) + ": payload too large");
  Writer w;
  w.PutBytes(kSync, 4);
  w.Put<uint32_t>(r.frame);
  const bool shape = !r.shape.empty();
  w.Put<uint8_t>(
      static_cast<uint8_t>((r.keyframe ? 1 : 0) | (r.has_mask ? 2 : 0) | (shape ? 4 : 0)));
  w.Put<uint8_t>(0);
  w.Put<uint16_t>(static_cast<uint16_t>(r.pose.size()));
  w.Put<uint32_t>(static_cast<uint32_t>(r.mask.size()));
  w.Put<uint32_t>(static_cast<uint32_t>(r.video.size()));
  if (shape) w.Put<uint32_t>(static_cast<uint32_t>(r.shape.size()));
  w.PutBytes(r.pose.data(), r.pose.size());
  w.PutBytes(r.mask.data(), r.mask.size());
  w.PutBytes(r.video.data(), r.video.size());
  w.PutBytes(r.shape.data(), r.shape.size());
  w.PutCrc(0);
  return w.bytes;
}

StreamReader::StreamReader(const std::string& path) : name_(path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path + ": cannot open the stream");
  bytes_.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  ParseHeader();
}

StreamReader::StreamReader(std::vector<uint8_t> bytes, const std::string& name)
    : name_(name), bytes_(std::move(bytes)) {
  ParseHeader();
}

void StreamReader::ParseHeader() {
  const auto fail = [&](const std::string& what) {
    throw Error(name_ + ": stream header (byte 0): " + what);
  };
  if (bytes_.size() < 12 || std::memcmp(bytes_.data(), kMagic, 4) != 0)
    fail("expected the magic ARTX, found another file or fewer than 12 bytes");
  Cursor c(bytes_, 4);
  StreamHeader& h = header_;
  uint16_t flags = 0;
  uint32_t size = 0;
  c.Get(&h.version);
  c.Get(&flags);
  c.Get(&size);
  if (h.version < kOldestStreamVersion || h.version > kStreamVersion)
    fail("expected version " + std::to_string(kOldestStreamVersion) + " to " +
         std::to_string(kStreamVersion) + ", found " + std::to_string(h.version));
  if (size < 24 || size > bytes_.size())
    fail("header size " + std::to_string(size) + " beyond the " + std::to_string(bytes_.size()) +
         " bytes of the stream (truncated)");
  uint32_t crc = 0;
  std::memcpy(&crc, bytes_.data() + size - 4, 4);
  if (crc != Crc(bytes_, 0, size - 4)) fail("CRC mismatch (damaged header)");
  uint16_t w = 0, hh = 0;
  bool ok = c.Get(&h.frame_rate_num) && c.Get(&h.frame_rate_den) && c.Get(&h.codec) &&
            c.Get(&h.pose_prediction) && c.Get(&h.num_joints) && c.Get(&h.atlas_width) &&
            c.Get(&h.atlas_height) && c.Get(&h.num_triangles) && c.Get(&h.scale_step) &&
            c.Get(&h.translation_step) && c.Get(&h.rotation_step) && c.Get(&h.keyframe_interval) &&
            c.Get(&h.target_kbps) && c.Get(&w) && c.Get(&hh) && c.Get(&h.camera.fx) &&
            c.Get(&h.camera.fy) && c.Get(&h.camera.cx) && c.Get(&h.camera.cy);
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  for (int r = 0; r < 3 && ok; ++r)
    for (int col = 0; col < 4 && ok; ++col) ok = c.Get(&m(r, col));
  uint32_t glb_size = 0;
  ok = ok && c.Get(&glb_size) && c.at() + glb_size + 4 == size;
  if (!ok) fail("fields do not fit the header size (malformed)");
  h.camera.width = w;
  h.camera.height = hh;
  h.camera.world_to_camera.matrix() = m;
  h.glb.assign(reinterpret_cast<const char*>(bytes_.data() + c.at()), glb_size);
  if (h.frame_rate_den == 0 || h.frame_rate_num == 0) fail("frame rate 0");
  if (h.codec > 3) fail("unknown codec " + std::to_string(h.codec));
  header_size_ = size;
  position_ = size;
}

std::size_t StreamReader::RecordAt(std::size_t offset, StreamRecord* r, std::string* why) const {
  if (offset + kRecordFraming > bytes_.size()) {
    *why = "truncated record (" + std::to_string(bytes_.size() - offset) + " bytes left)";
    return 0;
  }
  if (std::memcmp(bytes_.data() + offset, kSync, 4) != 0) {
    *why = "no record sync word";
    return 0;
  }
  Cursor c(bytes_, offset + 4);
  uint8_t flags = 0, reserved = 0;
  uint16_t pose = 0;
  uint32_t mask = 0, video = 0;
  c.Get(&r->frame);
  c.Get(&flags);
  c.Get(&reserved);
  c.Get(&pose);
  c.Get(&mask);
  c.Get(&video);
  // Flag bit 2: a rest-shape payload, its size after the video's (version 2).
  const bool has_shape = (flags & 4) && header_.version >= 2;
  uint32_t shape = 0;
  if (has_shape && !c.Get(&shape)) {
    *why = "truncated record (no room for the rest shape's size)";
    return 0;
  }
  if (mask > kMaxPayload || video > kMaxPayload || shape > kMaxPayload) {
    *why = "implausible payload sizes";
    return 0;
  }
  const std::size_t shape_field = has_shape ? kShapeSizeField : 0;
  const std::size_t head = 20 + shape_field;  // the payloads start here
  const std::size_t size = kRecordFraming + shape_field + pose + mask + video + shape;
  if (offset + size > bytes_.size()) {
    *why = "truncated record (needs " + std::to_string(size) + " bytes, " +
           std::to_string(bytes_.size() - offset) + " left)";
    return 0;
  }
  uint32_t crc = 0;
  std::memcpy(&crc, bytes_.data() + offset + size - 4, 4);
  if (crc != Crc(bytes_, offset, offset + size - 4)) {
    *why = "CRC mismatch (damaged record)";
    return 0;
  }
  const uint8_t* p = bytes_.data() + offset + head;
  r->offset = offset;
  r->size = size;
  r->keyframe = flags & 1;
  r->has_mask = flags & 2;
  r->pose.assign(p, p + pose);
  r->mask.assign(p + pose, p + pose + mask);
  r->video.assign(p + pose + mask, p + pose + mask + video);
  r->shape.assign(p + pose + mask + video, p + pose + mask + video + shape);
  return size;
}

bool StreamReader::Next(StreamRecord* record, std::vector<StreamIssue>* issues) {
  if (position_ >= bytes_.size()) return false;
  std::string why;
  std::size_t size = RecordAt(position_, record, &why);
  if (size == 0) {
    StreamIssue issue;
    issue.offset = position_;
    issue.frame = last_frame_ + 1;
    issue.what = why;
    // Resynchronise: the next sync word that starts an intact record.
    std::size_t at = position_ + 1;
    for (; at + 4 <= bytes_.size(); ++at) {
      if (std::memcmp(bytes_.data() + at, kSync, 4) != 0) continue;
      std::string ignored;
      size = RecordAt(at, record, &ignored);
      if (size > 0) break;
    }
    if (size == 0) {
      issue.what += "; no intact record after it";
      if (issues) issues->push_back(issue);
      position_ = bytes_.size();
      return false;
    }
    issue.what += "; resynchronised at byte " + std::to_string(at) + " (frame " +
                  std::to_string(record->frame) + ")";
    if (issues) issues->push_back(issue);
    position_ = at;
  }
  position_ += size;
  last_frame_ = static_cast<int>(record->frame);
  return true;
}

}  // namespace artex
