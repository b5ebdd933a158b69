// RGB-D rig calibration: a depth camera and a separate colour camera, each a pinhole with
// optional radial-tangential distortion (k1, k2, p1, p2, k3; OpenCV order), their world poses,
// and the depth scale. Stored as calibration.yaml in an artex sequence (docs/formats.md).
#pragma once

#include <Eigen/Core>
#include <string>

#include "render/camera.h"

namespace artex {

struct Distortion {
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0;
  bool IsZero() const { return k1 == 0 && k2 == 0 && p1 == 0 && p2 == 0 && k3 == 0; }
};

struct Calibration {
  PinholeCamera depth;          // depth camera intrinsics and world -> depth camera pose
  Distortion depth_distortion;
  PinholeCamera color;          // colour camera intrinsics and world -> colour camera pose
  Distortion color_distortion;
  double depth_scale = 1000.0;  // 16-bit depth units per metre (TUM: 5000)
  double frame_rate = 30.0;     // Hz (nominal)

  // depth -> colour camera extrinsic transform (x_color = T x_depth).
  Eigen::Isometry3d DepthToColor() const {
    return color.world_to_camera * depth.world_to_camera.inverse();
  }
};

// Plausible calibration values (docs/reliability.md); a value outside is an input error, not a
// rig: image sizes in [1, kMaxImageSide] pixels; focal lengths in [kMinFocal, kMaxFocal] pixels;
// the principal point within one image size of the image (cx in [-width, 2 width]);
// |distortion coefficients| <= kMaxDistortion; depth_scale in [kMinDepthScale, kMaxDepthScale]
// units per metre; frame_rate in [kMinFrameRate, kMaxFrameRate] Hz; |translation| <=
// kMaxTranslation m.
struct CalibrationLimits {
  static constexpr int kMaxImageSide = 16384;
  static constexpr double kMinFocal = 1.0, kMaxFocal = 1e5;
  static constexpr double kMaxDistortion = 1e3;
  static constexpr double kMinDepthScale = 1.0, kMaxDepthScale = 1e6;
  static constexpr double kMinFrameRate = 0.1, kMaxFrameRate = 1000.0;
  static constexpr double kMaxTranslation = 1e4;
};
// False with the field, range and value in *why when a value is outside CalibrationLimits.
bool CalibrationIsPlausible(const Calibration& calibration, std::string* why);

// Reads/writes calibration.yaml. Read throws artex::Error naming the file and field
// (missing key, wrong type, duplicate key, non-positive focal length or size, non-rigid
// rotation, a value outside CalibrationLimits...).
Calibration ReadCalibration(const std::string& path);
void WriteCalibration(const Calibration& calibration, const std::string& path);  // atomic

// Maps a distorted pixel to its undistorted pinhole position (iterative inversion).
Eigen::Vector2d UndistortPixel(const PinholeCamera& camera, const Distortion& d,
                               const Eigen::Vector2d& pixel);
Eigen::Vector2d DistortPixel(const PinholeCamera& camera, const Distortion& d,
                             const Eigen::Vector2d& pixel);

}  // namespace artex
