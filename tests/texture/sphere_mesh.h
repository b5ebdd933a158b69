// Test meshes shared by the texture tests.
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <vector>

namespace artex {
namespace testing {

// Appends a UV sphere (outward-facing counter-clockwise triangles) whose latitude-longitude
// atlas fills the UV rectangle [u0, u1] x [v0, v1] (split UV corners at the seam and poles).
inline void AddUvSphere(int rings, int segments, double r, const Eigen::Vector3d& c, double u0,
                        double u1, double v0, double v1, std::vector<Eigen::Vector3d>* vertices,
                        std::vector<Eigen::Vector3i>* triangles, std::vector<Eigen::Vector2d>* uvs,
                        std::vector<Eigen::Vector3i>* uv_triangles) {
  const int first = static_cast<int>(vertices->size());
  vertices->push_back(c + Eigen::Vector3d(0, r, 0));
  vertices->push_back(c - Eigen::Vector3d(0, r, 0));
  for (int i = 1; i < rings; ++i) {
    const double phi = M_PI * i / rings;
    for (int j = 0; j < segments; ++j) {
      const double theta = 2.0 * M_PI * j / segments;
      vertices->push_back(c + r * Eigen::Vector3d(std::sin(phi) * std::sin(theta), std::cos(phi),
                                                  std::sin(phi) * std::cos(theta)));
    }
  }
  const auto ring = [&](int i, int j) { return first + 2 + (i - 1) * segments + j % segments; };
  const auto uv = [&](int i, int j) {
    uvs->emplace_back(u0 + (u1 - u0) * j / segments, v0 + (v1 - v0) * i / rings);
    return static_cast<int>(uvs->size()) - 1;
  };
  for (int j = 0; j < segments; ++j) {
    triangles->emplace_back(first, ring(1, j), ring(1, j + 1));
    uv_triangles->emplace_back(uv(0, j), uv(1, j), uv(1, j + 1));
    for (int i = 1; i < rings - 1; ++i) {
      triangles->emplace_back(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1));
      uv_triangles->emplace_back(uv(i, j), uv(i + 1, j), uv(i + 1, j + 1));
      triangles->emplace_back(ring(i, j), ring(i + 1, j + 1), ring(i, j + 1));
      uv_triangles->emplace_back(uv(i, j), uv(i + 1, j + 1), uv(i, j + 1));
    }
    triangles->emplace_back(first + 1, ring(rings - 1, j + 1), ring(rings - 1, j));
    uv_triangles->emplace_back(uv(rings, j), uv(rings - 1, j + 1), uv(rings - 1, j));
  }
}

}  // namespace testing
}  // namespace artex
