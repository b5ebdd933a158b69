// Reader for Matroska (.mkv) RGB-D recordings through FFmpeg's libavformat/libavcodec: a
// 16-bit grey depth track (Azure Kinect's "DEPTH" track, b16g raw 16-bit big-endian, or FFV1
// gray16le) and a colour track (Azure Kinect's "COLOR", MJPEG, FFV1, raw ...). The calibration
// (depth and colour cameras, extrinsics, depth_scale; the artex calibration.yaml format) comes
// from a YAML file: the recording's own calibration.json is not read (docs/formats.md).
// Built only with libavformat (MkvSupportAvailable()).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "sensors/sequence.h"

namespace artex {

// True when artex was built with libavformat (otherwise MkvReader throws).
bool MkvSupportAvailable();

struct MkvReaderOptions {
  // calibration.yaml of the recording; "" means <file without .mkv>.yaml, else calibration.yaml
  // in the file's folder.
  std::string calibration_path;
  // Largest |t_depth - t_colour| (s) for an associated pair (nearest, one-to-one).
  double max_time_difference = 0.02;

  bool IsValid(std::string* error) const;
};

// Tracks: the video track titled DEPTH (else the first track decoding to 16-bit grey) and the
// one titled COLOR (else the first other video track). Frames are decoded on demand (seek to
// the frame's timestamp); no background frames.
class MkvReader : public FrameSource {
 public:
  // Throws artex::Error for a missing or undecodable file, no 16-bit depth track, no colour
  // track, a missing calibration file (naming the paths tried) or no associated pair.
  MkvReader(const std::string& path, const MkvReaderOptions& options = MkvReaderOptions());
  ~MkvReader() override;

  const Calibration& calibration() const override;
  int num_frames() const override;
  bool ReadFrame(int i, Frame* frame, std::string* warning) override;
  std::vector<cv::Mat> ReadBackgroundFrames() override;
  std::string Description() const override;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace artex
