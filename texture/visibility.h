// Visibility and viewing quality of every template triangle in one colour image (paper sec. 4):
// a triangle is visible when it faces the camera and its sample points (corners pulled towards
// the centroid, and the centroid) are inside the image and not occluded by the rest of the body
// (z-buffer of the posed mesh from render/).
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

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

// The z-buffer of the posed mesh as seen by the colour camera (at VisibilityOptions::raster_scale,
// cut to the mesh's bounding box): camera depth (m) of the visible surface per raster pixel.
struct SurfaceDepth {
  std::vector<float> depth;  // width * height, row-major; +inf where no surface
  int width = 0, height = 0;
  int x0 = 0, y0 = 0;  // raster pixel of depth[0] in the scaled full image
  double scale = 1.0;  // raster_scale

  // Depth of the surface seen at full-image pixel (u, v) (integer pixel centres; nearest raster
  // pixel); +inf outside the buffer.
  float At(int u, int v) const {
    const int x = (scale == 1.0 ? u : static_cast<int>(std::lround((u + 0.5) * scale - 0.5))) - x0;
    const int y = (scale == 1.0 ? v : static_cast<int>(std::lround((v + 0.5) * scale - 0.5))) - y0;
    if (x < 0 || y < 0 || x >= width || y >= height) return std::numeric_limits<float>::infinity();
    return depth[static_cast<std::size_t>(y) * width + x];
  }
  std::size_t MemoryBytes() const { return depth.size() * sizeof(float); }
};

struct TriangleVisibility {
  std::vector<uint8_t> visible;  // F: 1 when visible
  std::vector<float> quality;    // F: W = max(0, -n . v) (paper eq. 12), 0 when not visible
};

// vertices: V x 3 posed mesh (world, m); triangles: F x 3; camera: the colour camera (pixels of
// the full image).
// surface (optional): receives the z-buffer used for the occlusion test.
TriangleVisibility ComputeVisibility(const Eigen::MatrixX3d& vertices,
                                     const Eigen::MatrixX3i& triangles, const PinholeCamera& camera,
                                     const VisibilityOptions& options,
                                     SurfaceDepth* surface = nullptr);

}  // namespace artex
