// The sender of the tele-presence stream (docs/streaming.md): per frame the pose (pose_codec.h)
// and the texture atlas as one picture of a video (video_codec.h), with the set of textured
// triangles when it changes, framed into an .artx stream (container.h). Keyframes every
// keyframe_interval frames (intra video picture, absolute pose, full coverage set) let a
// receiver join there. The file is written through a temporary and renamed by Finish().
#pragma once

#include <cstdint>
#include <fstream>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "models/skinning.h"
#include "models/template.h"
#include "render/camera.h"
#include "stream/container.h"
#include "stream/pose_codec.h"
#include "stream/video_codec.h"

namespace artex {

struct StreamOptions {
  PoseCodecOptions pose;
  VideoEncoderOptions video;
  int keyframe_interval = 60;  // frames between keyframes (2 s at 30 Hz); >= 1
  // Side of the atlas video (texels, even); 0: the atlas as it is (downscaled otherwise).
  int video_size = 0;
  // Measure the pose quantisation error at the hands every frame (one extra skinning each).
  bool measure_pose_error = true;

  bool IsValid(std::string* error) const;
};

struct StreamFrameStats {
  int frame = 0;
  bool keyframe = false;
  std::size_t pose_bytes = 0, mask_bytes = 0, video_bytes = 0, record_bytes = 0;
  std::size_t shape_bytes = 0;           // the rest shape (SetRestShape), 0 on most frames
  double pose_ms = 0.0, video_ms = 0.0;  // encoding time (wall)
  // CPU time of the calling thread while encoding the picture: the whole encoder's with
  // threads = 1 (wall above it means the thread waited for a core).
  double video_cpu_ms = 0.0;
  double compose_ms = 0.0;     // composing the atlas picture (by the caller; 0 when given one)
  double hand_error_mm = 0.0;  // largest hand-vertex displacement by the quantisation
};

struct StreamSummary {
  int frames = 0, keyframes = 0;
  std::size_t header_bytes = 0, glb_bytes = 0;
  std::size_t pose_bytes = 0, mask_bytes = 0, video_bytes = 0, framing_bytes = 0;
  int shapes = 0;                // records carrying a rest shape (SetRestShape)
  std::size_t shape_bytes = 0;   // their rest-shape payloads
  double frame_rate = 30.0;
  double pose_kbps = 0.0;     // pose payloads at the frame rate
  double texture_kbps = 0.0;  // video + coverage payloads
  double total_kbps = 0.0;    // every record byte (framing included), header excluded
  double max_hand_error_mm = 0.0, mean_hand_error_mm = 0.0;
  double mean_encode_ms = 0.0, max_encode_ms = 0.0;    // pose + picture encoding, wall
  double mean_encode_cpu_ms = 0.0;                     // picture encoding, calling thread's CPU
  double mean_compose_ms = 0.0, max_compose_ms = 0.0;  // atlas composition (caller's, wall)
  std::vector<StreamFrameStats> per_frame;
};

class StreamSender {
 public:
  // texture: false sends poses only (codec 0). camera: the colour camera (a default viewpoint
  // for receivers). Throws artex::Error for invalid options or an unavailable codec.
  StreamSender(const std::string& path, const Template& tmpl, const PinholeCamera& camera,
               double frame_rate, int atlas_size, bool texture, const StreamOptions& options);
  ~StreamSender();
  // atlas: CV_8UC3 atlas_size^2 (ignored without texture); triangle_frames: F, < 0 untextured
  // (may be null: everything textured). compose_ms: the caller's time to compose `atlas`
  // (reported in the statistics only).
  StreamFrameStats AddFrame(int frame, const Pose& pose, const cv::Mat& atlas,
                            const std::vector<int>* triangle_frames, double compose_ms = 0.0);
  // The subject's rest shape from the next AddFrame on (shape estimation swapped the tracking
  // template; `shaped` has the header template's rig and mesh): that frame's record carries it
  // (stream/rest_shape.h) and is a keyframe, so a receiver that starts there has it. Throws
  // artex::Error for a template of another size.
  void SetRestShape(const Template& shaped);
  // Closes the stream (renames it into place) and returns the totals.
  StreamSummary Finish();
  // The bytes written so far: the header, and the record of the last AddFrame (live taps).
  const std::vector<uint8_t>& header_bytes() const { return header_bytes_; }
  const std::vector<uint8_t>& last_record() const { return last_record_; }

 private:
  std::string path_, temp_path_;
  std::ofstream out_;
  Template template_;  // the header's
  StreamOptions options_;
  std::vector<uint8_t> pending_shape_;  // the next record's rest shape (SetRestShape)
  StreamHeader header_;
  std::unique_ptr<Skinning> skinning_;
  std::vector<int> hand_vertices_;
  PoseEncoder pose_encoder_;
  std::unique_ptr<AtlasVideoEncoder> video_;
  std::vector<uint8_t> last_bits_;
  std::vector<uint8_t> header_bytes_, last_record_;
  StreamSummary summary_;
  bool finished_ = false;
};

// Per-triangle textured flags (frames[f] >= 0) packed into bits (triangle f: bit f % 8 of
// byte f / 8).
std::vector<uint8_t> PackCoverage(const std::vector<int>& triangle_frames);
// The coverage payload: the packed bits deflated (zlib) on keyframes, else their XOR with the
// previous frame's bits deflated (a few bytes when few triangles change).
std::vector<uint8_t> EncodeCoverage(const std::vector<uint8_t>& bits,
                                    const std::vector<uint8_t>* previous_bits);
// The inverse: *bits updated in place (XOR for a delta); false for a damaged payload.
bool DecodeCoverage(const std::vector<uint8_t>& payload, int num_triangles, bool keyframe,
                    std::vector<uint8_t>* bits);
// F flags (1 textured) from packed bits.
std::vector<int> UnpackCoverage(const std::vector<uint8_t>& bits, int num_triangles);

// Vertices of the template's hands: of joints whose name contains "wrist" or "hand" (every
// vertex when there are none).
std::vector<int> HandVertices(const Template& tmpl);

}  // namespace artex
