// `artex stream encode RUN/` and `artex stream play STREAM`: encoding a tracked run's poses and
// exported atlases (pipeline.export_atlases) into an .artx stream, and playing a stream back
// with the receiver's renders, atlas, bitrates, latency and quality against the sender's
// full-quality model (a run folder) and the ground truth (a synthetic recording).
#pragma once

#include <string>
#include <vector>

#include "stream/container.h"
#include "stream/stream_sender.h"
#include "texture/texture_quality.h"

namespace artex {

// Encodes RUN/poses.csv with RUN/atlases/ (and the template of RUN/tracked.glb or
// template_path) into stream_path, at RUN/calibration.yaml's frame rate and colour camera.
StreamSummary EncodeRunStream(const std::string& run_dir, const std::string& template_path,
                              const std::string& stream_path, const StreamOptions& options);

struct PlaybackOptions {
  int from_frame = 0;         // join at the first keyframe at or after this frame
  std::string out_dir;        // "": no files
  int render_every = 0;       // write renders/NNNNNN_vK.png every n-th frame (0: none)
  int evaluate_every = 5;     // quality against the reference / truth every n-th frame; >= 1
  std::string reference_run;  // sender's run folder (poses.csv, atlases/): quality vs sender
  std::string sequence;       // synthetic recording with ground truth: quality vs truth
  HeldOutViewOptions views;   // render and evaluation viewpoints around the model
  // Link rate (kbit/s) of the latency model (StreamLatency); 0: the stream's mean total rate.
  double link_kbps = 0.0;
};

// Per frame k (capture at k / rate): ready to send after the sender's time (atlas composition
// + encoding; RUN/stream_frames.csv of the reference run, 0 when absent), sent whole over a
// link of link_kbps that carries one record after another (a record waits while the previous
// one, e.g. a keyframe, is still being sent), then decoded. latency = sent + decode - capture.
struct FrameTiming {
  int frame = 0;
  std::size_t record_bytes = 0;
  double sender_ms = 0.0, decode_ms = 0.0;
  double queue_ms = 0.0, transmit_ms = 0.0, latency_ms = 0.0;  // outputs
};
void StreamLatency(double frame_rate, double link_kbps, std::vector<FrameTiming>* frames);

struct PlaybackReport {
  int frames = 0, keyframes = 0, skipped_records = 0;
  int first_frame = -1, last_frame = -1;
  std::vector<StreamIssue> issues;
  std::size_t stream_bytes = 0, header_bytes = 0, glb_bytes = 0;
  double pose_kbps = 0.0, texture_kbps = 0.0, total_kbps = 0.0;  // at the stream's frame rate
  double mean_decode_ms = 0.0, max_decode_ms = 0.0;
  // Stream latency per frame (StreamLatency): median, max; the link rate it assumed; whether the
  // sender's times were known (the reference run's stream_frames.csv).
  double median_latency_ms = 0.0, max_latency_ms = 0.0, link_kbps = 0.0;
  bool sender_times = false;
  // Against the sender's full-quality model (NaN without reference_run).
  double psnr_vs_sender_db = 0.0, ssim_vs_sender = 0.0, atlas_psnr_db = 0.0;
  double max_vertex_error_mm = 0.0;  // receiver's posed vertices against the sender's
  // Against the ground truth (NaN without sequence): receiver and sender (reference) models.
  double receiver_psnr_db = 0.0, receiver_ssim = 0.0;
  double sender_psnr_db = 0.0, sender_ssim = 0.0;
  int evaluated_frames = 0;
};

// Plays the stream (never throws for damaged records: they are in the report's issues); writes
// atlas.png, poses.csv, report.json and the renders into out_dir. Throws artex::Error for an
// unreadable stream or header, or unreadable reference / sequence.
PlaybackReport PlayStream(const std::string& stream_path, const PlaybackOptions& options);

}  // namespace artex
