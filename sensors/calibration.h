// RGB-D rig calibration: a depth camera and a separate colour camera, each a pinhole with
// optional radial-tangential distortion (k1, k2, p1, p2, k3; OpenCV order), their world poses,
// and the depth scale. Stored as calibration.yaml in an artex sequence (docs/formats.md).
#pragma once

#include <string>

#include <Eigen/Core>

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

// Reads/writes calibration.yaml. Read throws artex::Error naming the file and field
// (missing key, wrong type, non-positive focal length or size, non-rigid rotation...).
Calibration ReadCalibration(const std::string& path);
void WriteCalibration(const Calibration& calibration, const std::string& path);  // atomic

// Maps a distorted pixel to its undistorted pinhole position (iterative inversion).
Eigen::Vector2d UndistortPixel(const PinholeCamera& camera, const Distortion& d,
                               const Eigen::Vector2d& pixel);
Eigen::Vector2d DistortPixel(const PinholeCamera& camera, const Distortion& d,
                             const Eigen::Vector2d& pixel);

}  // namespace artex
