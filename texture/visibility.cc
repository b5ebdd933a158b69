#include "texture/visibility.h"

#include <cmath>
#include <sstream>

#include "energies/texture_terms.h"
#include "models/normals.h"
#include "render/rasterizer.h"

namespace artex {

bool VisibilityOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (!(depth_tolerance >= 0.0)) msg << "visibility.depth_tolerance: expected >= 0, found " << depth_tolerance;
  else if (!(corner_shrink >= 0.0 && corner_shrink < 1.0))
    msg << "visibility.corner_shrink: expected [0, 1), found " << corner_shrink;
  else if (!(min_visible_fraction > 0.0 && min_visible_fraction <= 1.0))
    msg << "visibility.min_visible_fraction: expected (0, 1], found " << min_visible_fraction;
  else if (!(border_pixels >= 0.0)) msg << "visibility.border_pixels: expected >= 0, found " << border_pixels;
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

TriangleVisibility ComputeVisibility(const Eigen::MatrixX3d& vertices,
                                     const Eigen::MatrixX3i& triangles,
                                     const PinholeCamera& camera,
                                     const VisibilityOptions& options) {
  RasterBuffers buffers;
  Rasterize(vertices, triangles, camera, RasterOptions(), &buffers);
  Eigen::MatrixX3d normals;
  ComputeTriangleNormals(vertices, triangles, &normals);
  const int num_triangles = static_cast<int>(triangles.rows());
  TriangleVisibility out;
  out.visible.assign(num_triangles, 0);
  out.quality.assign(num_triangles, 0.0f);
  const Eigen::Vector3d center = camera.Center();
  const double max_u = camera.width - 1 - options.border_pixels;
  const double max_v = camera.height - 1 - options.border_pixels;
  for (int f = 0; f < num_triangles; ++f) {
    const Eigen::Vector3d a = vertices.row(triangles(f, 0));
    const Eigen::Vector3d b = vertices.row(triangles(f, 1));
    const Eigen::Vector3d c = vertices.row(triangles(f, 2));
    const Eigen::Vector3d centroid = (a + b + c) / 3.0;
    const double w = TriangleQuality(normals.row(f).transpose(), (centroid - center).normalized());
    if (w <= 0.0) continue;
    const Eigen::Vector3d samples[4] = {centroid, a + options.corner_shrink * (centroid - a),
                                        b + options.corner_shrink * (centroid - b),
                                        c + options.corner_shrink * (centroid - c)};
    int good = 0;
    for (const auto& s : samples) {
      double z = 0.0;
      const Eigen::Vector2d p = camera.Project(s, &z);
      if (!(z > 0.0) || p.x() < options.border_pixels || p.y() < options.border_pixels ||
          p.x() > max_u || p.y() > max_v)
        continue;
      const int u = static_cast<int>(std::lround(p.x()));
      const int v = static_cast<int>(std::lround(p.y()));
      const float zbuf = buffers.depth[buffers.index(u, v)];
      if (z <= zbuf + options.depth_tolerance) ++good;
    }
    if (good >= options.min_visible_fraction * 4.0 - 1e-9) {
      out.visible[f] = 1;
      out.quality[f] = static_cast<float>(w);
    }
  }
  return out;
}

}  // namespace artex
