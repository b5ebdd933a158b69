// Pinhole camera without skew (the paper's model): intrinsics fx, fy, cx, cy in pixels and a
// rigid world -> camera transform. Camera frame: OpenCV convention (x right, y down, z forward),
// metres. Pixel (u, v) has its centre at integer coordinates (u = column, v = row).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace artex {

struct PinholeCamera {
  int width = 640;
  int height = 480;
  double fx = 525.0;
  double fy = 525.0;
  double cx = 319.5;
  double cy = 239.5;
  Eigen::Isometry3d world_to_camera = Eigen::Isometry3d::Identity();

  // World point -> pixel (u, v) and camera depth z (m). z <= 0 means behind the camera.
  Eigen::Vector2d Project(const Eigen::Vector3d& world, double* depth = nullptr) const;
  // Pixel (u, v) at camera depth z (m) -> world point.
  Eigen::Vector3d Unproject(double u, double v, double depth) const;
  Eigen::Vector3d Center() const;  // camera centre in world coordinates

  // Points a camera at `target` from `eye`, with `up` the world direction that appears upward
  // in the image.
  static Eigen::Isometry3d LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                                  const Eigen::Vector3d& up);
};

}  // namespace artex
