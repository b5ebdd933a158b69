// Depth image -> world-frame triangle mesh (paper sec. 2: "we compute a set of triangles by
// connecting adjacent depth pixels, if their depth value does not exceed a pre-defined
// threshold"). Pixels are back-projected through the depth camera's intrinsics (undistorted
// when the distortion is non-zero) and its world pose; each 2x2 block of (sub-sampled) pixels
// gives up to two triangles, counter-clockwise as seen from the camera, kept only when every
// pair of its vertices satisfies |z_a - z_b| <= max_relative_jump * step * min(z_a, z_b).
// Vertex normals: normalised mean of incident unit triangle normals, oriented towards the
// camera (the paper's n(v_s), eq. 4).
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "models/default_init_allocator.h"
#include "render/camera.h"
#include "sensors/calibration.h"
#include "sensors/scan.h"

namespace artex {

struct DepthMeshOptions {
  // Use every step-th pixel in u and v (1 = full resolution).
  int step = 1;
  // Largest depth difference between two connected pixels, relative to the nearer depth and per
  // pixel of spacing (0.03 at 2.5 m and step 1: 7.5 cm).
  double max_relative_jump = 0.03;
  // Drop vertices that belong to no triangle (their normal would be undefined).
  bool drop_isolated_points = true;

  bool IsValid(std::string* error) const;
};

// Per-pixel ray table of a depth camera: pixel (u, v) with depth z (m, along the optical axis)
// maps to the camera point (rx z, ry z, z), (rx, ry) the undistorted normalised coordinates.
class DepthBackProjector {
 public:
  DepthBackProjector(const PinholeCamera& camera, const Distortion& distortion);
  Eigen::Vector3d CameraPoint(int u, int v, double z) const;
  Eigen::Vector3d WorldPoint(int u, int v, double z) const;
  // Every pixel with depth != 0 and mask != 0 (empty mask: all pixels), in row-major pixel
  // order -> N x 3 world points (m). depth: CV_16UC1 in units of 1/depth_scale m.
  void BackProject(const cv::Mat& depth, double depth_scale, const cv::Mat& mask,
                   Eigen::MatrixX3d* points) const;
  const PinholeCamera& camera() const { return camera_; }
  const float* rays() const { return rays_.data(); }  // 2 floats per pixel, row-major

 private:
  PinholeCamera camera_;
  std::vector<float> rays_;
  Eigen::Matrix3d rotation_;     // camera -> world
  Eigen::Vector3d translation_;  // camera -> world
};

struct DepthMeshStats {
  int candidate_pixels = 0;  // masked pixels with valid depth on the sampling grid
  int vertices = 0;
  int triangles = 0;
  int isolated_dropped = 0;
};

// Builds depth meshes frame after frame, reusing its buffers.
class DepthMesher {
 public:
  // Throws artex::Error for invalid options.
  DepthMesher(const PinholeCamera& camera, const Distortion& distortion,
              const DepthMeshOptions& options = DepthMeshOptions());

  // depth: CV_16UC1 of the camera's size; mask: CV_8UC1 of the same size, non-zero = use
  // (empty: all pixels). Fills scan->points, normals (N x 3, world) and triangles (M x 3);
  // leaves colours untouched. Throws artex::Error for a wrong image size or type.
  void Build(const cv::Mat& depth, double depth_scale, const cv::Mat& mask, Scan* scan,
             DepthMeshStats* stats = nullptr);
  // Pixel (v * width + u) of each vertex of the last Build.
  const std::vector<int>& vertex_pixels() const { return vertex_pixels_; }
  const DepthBackProjector& projector() const { return projector_; }

 private:
  DepthBackProjector projector_;
  DepthMeshOptions options_;
  std::vector<int> grid_index_;  // per grid node: provisional vertex id or -1
  std::vector<int> row_range_;   // per grid row: first and one-past-last valid column
  // Sized for the worst case (every node, 4 triangles a node) and not zero-filled: a frame
  // writes and reads only its first entries (models/default_init_allocator.h).
  std::vector<int, DefaultInitAllocator<int>> grid_pixel_;  // per provisional vertex: pixel
  std::vector<int, DefaultInitAllocator<int>> triangles_;   // 3 provisional vertex ids each
  std::vector<int> remap_;       // provisional -> final vertex id (-1: dropped)
  std::vector<int> vertex_pixels_;
  // 4 floats (x, y, z, 0) per provisional vertex, camera frame, 16-byte aligned for SIMD.
  std::vector<float, DefaultInitAllocator<float, Eigen::aligned_allocator<float>>>
      camera_points_;  // m
  std::vector<float, Eigen::aligned_allocator<float>> normal_sums_;
};

// models/normals.h ComputeVertexNormals (normalised mean of incident unit triangle normals;
// zero where no triangle), flipped where needed to face `viewpoint`. DepthMesher computes the
// same normals with its own buffers. vertices: V x 3, triangles: F x 3.
void ComputeOrientedVertexNormals(const Eigen::MatrixX3d& vertices,
                                  const Eigen::MatrixX3i& triangles,
                                  const Eigen::Vector3d& viewpoint, Eigen::MatrixX3d* normals);

}  // namespace artex
