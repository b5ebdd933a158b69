// Exact z-buffer rasterisation of a triangle mesh through a pinhole camera: per pixel the
// camera depth (m), the triangle id and the perspective-correct barycentrics of the visible
// surface. Serves the virtual Kinect, visibility tests and novel-view renders.
// Pixel centres are sampled at integer (u, v); top-left fill rule; no anti-aliasing.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "render/camera.h"

namespace artex {

struct RasterOptions {
  double near_plane = 0.05;  // m; triangles with any vertex nearer are clipped away
  bool cull_backfaces = false;  // drop triangles facing away (counter-clockwise = front)
};

struct RasterBuffers {
  int width = 0;
  int height = 0;
  std::vector<float> depth;          // width * height, row-major; +inf where nothing is hit
  std::vector<int32_t> triangle_id;  // -1 where nothing is hit
  std::vector<Eigen::Vector2f> barycentric;  // (b1, b2); b0 = 1 - b1 - b2

  int index(int u, int v) const { return v * width + u; }
};

// vertices: V x 3 world (m); triangles: F x 3. Resizes and fills `out`.
void Rasterize(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
               const PinholeCamera& camera, const RasterOptions& options, RasterBuffers* out);
// Rasterize's depth buffer alone (bitwise identical to RasterBuffers::depth, width * height
// row-major, +inf where nothing is hit), without triangle ids and barycentrics: z-buffer tests.
void RasterizeDepth(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                    const PinholeCamera& camera, const RasterOptions& options,
                    std::vector<float>* depth);

}  // namespace artex
