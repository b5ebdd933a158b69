// Reader for the TUM RGB-D benchmark layout (Sturm et al. 2012): a folder with rgb.txt and
// depth.txt ("timestamp filename" per line, '#' comments), rgb/*.png (8-bit colour) and
// depth/*.png (16-bit, 5000 units per metre, registered to the colour camera). Depth and colour
// frames are associated one-to-one by nearest timestamp (greedy in order of time difference, as
// the benchmark's associate.py). Intrinsics come from a small YAML file (docs/formats.md).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "sensors/sequence.h"

namespace artex {

struct TumReaderOptions {
  // Largest |t_depth - (t_rgb + time_offset)| (s) for an associated pair.
  double max_time_difference = 0.02;
  // Added to every colour timestamp before association (s).
  double time_offset = 0.0;
  // Intrinsics YAML; "" means <folder>/camera.yaml. Keys: width, height, fx, fy, cx, cy
  // (pixels), optional k1, k2, p1, p2, k3 and depth_scale (units per metre, default 5000).
  std::string intrinsics_path;
  // When the intrinsics file does not exist: false -> artex::Error; true -> the published
  // Freiburg-1 colour intrinsics (fx 517.3, fy 516.5, cx 318.6, cy 255.3, k1..k3 0.2624,
  // -0.9531, -0.0054, 0.0026, 1.1633; 640x480, 5000 units/m).
  bool freiburg1_defaults = false;

  bool IsValid(std::string* error) const;
};

// Depth and colour are treated as the same camera (the benchmark's depth is registered to the
// colour image): both PinholeCameras get the same intrinsics and the identity world pose.
// No background frames: ReadBackgroundFrames() returns an empty vector.
class TumReader : public FrameSource {
 public:
  // Throws artex::Error for a missing folder or list file, a malformed line (file, line,
  // expected, found), timestamps out of order, bad intrinsics or no associated pair.
  TumReader(const std::string& folder, const TumReaderOptions& options = TumReaderOptions());
  ~TumReader() override;

  const Calibration& calibration() const override;
  int num_frames() const override;
  bool ReadFrame(int i, Frame* frame, std::string* warning) override;
  std::vector<cv::Mat> ReadBackgroundFrames() override;

  // The associated pair i: depth and colour file names relative to the folder.
  const std::string& depth_file(int i) const;
  const std::string& color_file(int i) const;
  // Entries of depth.txt / rgb.txt left without a partner.
  int num_unmatched_depth() const;
  int num_unmatched_color() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace artex
