// Visibility and viewing quality of every template triangle in one colour image (paper sec. 4):
// a triangle is visible when it faces the camera and its sample points (corners pulled towards
// the centroid, and the centroid) are inside the image and not occluded by the rest of the body
// (z-buffer of the posed mesh from render/).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "render/camera.h"

namespace artex {

struct VisibilityOptions {
  // A sample is unoccluded when its depth exceeds the z-buffer by at most this (m).
  double depth_tolerance = 0.01;
  // Corner samples are pulled this fraction of the way to the centroid (avoids edge aliasing).
  double corner_shrink = 0.2;
  // Fraction of the 4 samples (3 corners + centroid) that must be unoccluded and in the image.
  double min_visible_fraction = 0.99;
  // Samples closer than this many pixels to the image border count as outside.
  double border_pixels = 2.0;
  // Resolution of the occlusion z-buffer relative to the colour image; (0, 1]. 1 rasterises at
  // the image's pixel grid (exact); below 1 is faster but may misjudge occlusion within about
  // 1 / raster_scale pixels of a silhouette. The z-buffer always covers only the bounding box
  // of the mesh's projection (same result as the full image).
  double raster_scale = 1.0;

  bool IsValid(std::string* error) const;
};

struct TriangleVisibility {
  std::vector<uint8_t> visible;  // F: 1 when visible
  std::vector<float> quality;    // F: W = max(0, -n . v) (paper eq. 12), 0 when not visible
};

// vertices: V x 3 posed mesh (world, m); triangles: F x 3; camera: the colour camera (pixels of
// the full image).
TriangleVisibility ComputeVisibility(const Eigen::MatrixX3d& vertices,
                                     const Eigen::MatrixX3i& triangles,
                                     const PinholeCamera& camera,
                                     const VisibilityOptions& options);

}  // namespace artex
