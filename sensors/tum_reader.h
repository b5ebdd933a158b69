// Reader for the TUM RGB-D benchmark layout (Sturm et al. 2012): a folder with rgb.txt and
// depth.txt ("timestamp filename" per line, '#' comments), rgb/*.png (8-bit colour) and
// depth/*.png (16-bit, 5000 units per metre, registered to the colour camera), optionally
// accelerometer.txt ("timestamp ax ay az", m/s^2). Depth and colour frames are associated
// one-to-one by nearest timestamp (greedy in order of time difference, as the benchmark's
// associate.py). Intrinsics come from a small YAML file or a named preset (docs/formats.md).
#pragma once

#include <Eigen/Core>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "sensors/sequence.h"

namespace artex {

// The TUM benchmark's published intrinsics (all 640x480, 5000 units/m): Freiburg 1, 2 and 3
// colour cameras (fr3: no distortion) and the ROS/OpenNI Kinect default (525, 525, 319.5, 239.5).
enum class TumIntrinsicsPreset { kNone, kFreiburg1, kFreiburg2, kFreiburg3, kKinect };
// "none", "fr1", "fr2", "fr3", "kinect".
const std::map<std::string, TumIntrinsicsPreset>& TumIntrinsicsPresetNames();
std::string TumIntrinsicsPresetName(TumIntrinsicsPreset preset);
// Depth and colour cameras with the preset's intrinsics, identity poses, depth_scale 5000,
// 30 Hz. Throws artex::Error for kNone.
Calibration TumPresetCalibration(TumIntrinsicsPreset preset);

struct TumReaderOptions {
  // Largest |t_depth - (t_rgb + time_offset)| (s) for an associated pair.
  double max_time_difference = 0.02;
  // Added to every colour timestamp before association (s).
  double time_offset = 0.0;
  // Intrinsics YAML; "" means <folder>/camera.yaml (unless intrinsics_preset is set). Keys:
  // width, height, fx, fy, cx, cy (pixels), optional k1, k2, p1, p2, k3 and depth_scale (units
  // per metre, default 5000). A given file must exist.
  std::string intrinsics_path;
  // A published preset instead of a file; overrides <folder>/camera.yaml. At most one of
  // intrinsics_path and intrinsics_preset may be set.
  TumIntrinsicsPreset intrinsics_preset = TumIntrinsicsPreset::kNone;
  // Read accelerometer.txt (when present) for gravity().
  bool read_accelerometer = true;
  // m/s^2: a mean accelerometer vector shorter than this gives no gravity (a moving device or
  // a file of zeros); 9.81 at rest.
  double min_gravity_norm = 4.9;

  // A preset name (TumIntrinsicsPresetNames) sets intrinsics_preset and clears the path; any
  // other text is taken as a file path; "" resets both.
  void SetIntrinsics(const std::string& name_or_file);
  bool IsValid(std::string* error) const;
};

// Depth and colour are treated as the same camera (the benchmark's depth is registered to the
// colour image): both PinholeCameras get the same intrinsics and the identity world pose, i.e.
// the world frame is the camera frame (x right, y down, z forward).
// No background frames: ReadBackgroundFrames() returns an empty vector.
class TumReader : public FrameSource {
 public:
  // Throws artex::Error for a missing folder or list file, a malformed line (file, line,
  // expected, found), timestamps out of order, missing or bad intrinsics (naming the file,
  // the keys and the presets), a malformed accelerometer.txt or no associated pair (with the
  // numbers of entries). Listed files that do not exist are counted (num_missing_files) and
  // their frames fail in ReadFrame with a warning.
  TumReader(const std::string& folder, const TumReaderOptions& options = TumReaderOptions());
  ~TumReader() override;

  const Calibration& calibration() const override;
  int num_frames() const override;
  bool ReadFrame(int i, Frame* frame, std::string* warning) override;
  std::vector<cv::Mat> ReadBackgroundFrames() override;
  // Mean specific force of accelerometer.txt, normalised: "up" in the depth camera frame. The
  // accelerometer's axes are taken as the camera's (OpenCV: x right, y down, z forward); at
  // rest it measures the reaction to gravity, which points up, so an upright Kinect reads about
  // (0, -9.8, 0) and gives up = (0, -1, 0). None without the file, with read_accelerometer
  // off, or when the mean is shorter than min_gravity_norm.
  std::optional<Eigen::Vector3d> gravity() const override;
  std::string Description() const override;

  // The associated pair i: depth and colour file names relative to the folder.
  const std::string& depth_file(int i) const;
  const std::string& color_file(int i) const;
  // Entries of depth.txt / rgb.txt left without a partner.
  int num_unmatched_depth() const;
  int num_unmatched_color() const;
  // Associated pairs whose depth or colour file does not exist.
  int num_missing_files() const;
  // Samples read from accelerometer.txt (0 without the file).
  int num_accelerometer_samples() const;
  // Where the intrinsics came from: a file path or "preset fr1" etc.
  const std::string& intrinsics_source() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace artex
