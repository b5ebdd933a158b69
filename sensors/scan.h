// One preprocessed frame (paper sec. 2): the foreground depth mesh in world coordinates with
// per-vertex normals (mean of incident triangle normals) and colours from the colour camera.
// This is the v_s, n(v_s), rgb(v_s) of the fitting energy (eq. 4).
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

namespace artex {

struct SilhouetteMap;  // sensors/silhouette.h

struct Scan {
  Eigen::MatrixX3d points;          // N x 3, world frame (m)
  Eigen::MatrixX3d normals;         // N x 3 unit, oriented towards the depth camera
  Eigen::MatrixX3d colors;          // N x 3 linear RGB in [0, 1]
  std::vector<uint8_t> color_valid; // N: 0 where the point projects outside the colour image
  Eigen::MatrixX3i triangles;       // M x 3 depth-mesh triangles (indices into points)
  // The frame's free space for the silhouette term (null: none, e.g. a scan made without a
  // depth image); shared, never modified, by the copies of the scan.
  std::shared_ptr<const SilhouetteMap> silhouette;

  int size() const { return static_cast<int>(points.rows()); }
};

}  // namespace artex
