#include "texture/visibility.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "energies/texture_terms.h"
#include "models/normals.h"
#include "render/rasterizer.h"

namespace artex {

bool VisibilityOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (!(depth_tolerance >= 0.0))
    msg << "visibility.depth_tolerance: expected >= 0, found " << depth_tolerance;
  else if (!(corner_shrink >= 0.0 && corner_shrink < 1.0))
    msg << "visibility.corner_shrink: expected [0, 1), found " << corner_shrink;
  else if (!(min_visible_fraction > 0.0 && min_visible_fraction <= 1.0))
    msg << "visibility.min_visible_fraction: expected (0, 1], found " << min_visible_fraction;
  else if (!(border_pixels >= 0.0))
    msg << "visibility.border_pixels: expected >= 0, found " << border_pixels;
  else if (!(raster_scale > 0.0 && raster_scale <= 1.0))
    msg << "visibility.raster_scale: expected (0, 1], found " << raster_scale;
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

TriangleVisibility ComputeVisibility(const Eigen::MatrixX3d& vertices,
                                     const Eigen::MatrixX3i& triangles, const PinholeCamera& camera,
                                     const VisibilityOptions& options, SurfaceDepth* surface) {
  const int num_vertices = static_cast<int>(vertices.rows());
  const int num_triangles = static_cast<int>(triangles.rows());
  const RasterOptions raster_options;
  // Camera coordinates of every vertex once.
  const Eigen::Matrix3d rotation = camera.world_to_camera.linear();
  const Eigen::Vector3d translation = camera.world_to_camera.translation();
  Eigen::Matrix3Xd cam(3, num_vertices);
  for (int v = 0; v < num_vertices; ++v)
    cam.col(v) = rotation * vertices.row(v).transpose() + translation;

  // The z-buffer camera: the colour camera scaled by raster_scale (pixel centres map as
  // (u + 0.5) s - 0.5), cut to the bounding box of the projected vertices in front of the near
  // plane (every rasterised triangle lies inside it, so the crop changes nothing).
  const double s = options.raster_scale;
  PinholeCamera zcam = camera;
  zcam.fx = camera.fx * s;
  zcam.fy = camera.fy * s;
  zcam.cx = (camera.cx + 0.5) * s - 0.5;
  zcam.cy = (camera.cy + 0.5) * s - 0.5;
  const int full_w = std::max(1, static_cast<int>(std::ceil(camera.width * s)));
  const int full_h = std::max(1, static_cast<int>(std::ceil(camera.height * s)));
  double min_x = std::numeric_limits<double>::infinity(), min_y = min_x;
  double max_x = -min_x, max_y = -min_x;
  for (int v = 0; v < num_vertices; ++v) {
    const Eigen::Vector3d c = cam.col(v);
    if (!(c.z() >= raster_options.near_plane)) continue;
    const double x = zcam.fx * c.x() / c.z() + zcam.cx;
    const double y = zcam.fy * c.y() / c.z() + zcam.cy;
    if (!std::isfinite(x) || !std::isfinite(y)) continue;
    min_x = std::min(min_x, x);
    max_x = std::max(max_x, x);
    min_y = std::min(min_y, y);
    max_y = std::max(max_y, y);
  }
  int x0 = 0, y0 = 0, x1 = -1, y1 = -1;  // inclusive crop, empty when nothing projects
  if (min_x <= max_x) {
    x0 = std::max(0, static_cast<int>(std::floor(min_x)) - 1);
    y0 = std::max(0, static_cast<int>(std::floor(min_y)) - 1);
    x1 = std::min(full_w - 1, static_cast<int>(std::ceil(max_x)) + 1);
    y1 = std::min(full_h - 1, static_cast<int>(std::ceil(max_y)) + 1);
  }
  RasterBuffers buffers;
  const bool any_pixels = x1 >= x0 && y1 >= y0;
  if (any_pixels) {
    zcam.width = x1 - x0 + 1;
    zcam.height = y1 - y0 + 1;
    zcam.cx -= x0;
    zcam.cy -= y0;
    Rasterize(vertices, triangles, zcam, raster_options, &buffers);
  }
  const float kNoSurface = std::numeric_limits<float>::infinity();
  const float* depth = buffers.depth.data();  // stays valid when moved into *surface
  const auto zbuffer = [&](double u, double v) {
    if (!any_pixels) return kNoSurface;
    const double su = s == 1.0 ? u : (u + 0.5) * s - 0.5;
    const double sv = s == 1.0 ? v : (v + 0.5) * s - 0.5;
    const int x = static_cast<int>(std::lround(su)) - x0;
    const int y = static_cast<int>(std::lround(sv)) - y0;
    if (x < 0 || y < 0 || x >= buffers.width || y >= buffers.height) return kNoSurface;
    return depth[static_cast<std::size_t>(y) * buffers.width + x];
  };
  if (surface != nullptr) {
    surface->scale = s;
    surface->x0 = x0;
    surface->y0 = y0;
    surface->width = any_pixels ? buffers.width : 0;
    surface->height = any_pixels ? buffers.height : 0;
    surface->depth = any_pixels ? std::move(buffers.depth) : std::vector<float>();
  }

  Eigen::MatrixX3d normals;
  ComputeTriangleNormals(vertices, triangles, &normals);
  TriangleVisibility out;
  out.visible.assign(num_triangles, 0);
  out.quality.assign(num_triangles, 0.0f);
  const Eigen::Vector3d center = camera.Center();
  const double max_u = camera.width - 1 - options.border_pixels;
  const double max_v = camera.height - 1 - options.border_pixels;
  tbb::parallel_for(
      tbb::blocked_range<int>(0, num_triangles, 2048), [&](const tbb::blocked_range<int>& range) {
        for (int f = range.begin(); f < range.end(); ++f) {
          const Eigen::Vector3d a = vertices.row(triangles(f, 0));
          const Eigen::Vector3d b = vertices.row(triangles(f, 1));
          const Eigen::Vector3d c = vertices.row(triangles(f, 2));
          const Eigen::Vector3d centroid = (a + b + c) / 3.0;
          const double w =
              TriangleQuality(normals.row(f).transpose(), (centroid - center).normalized());
          if (w <= 0.0) continue;
          // Samples in camera coordinates (linear in the world points).
          const Eigen::Vector3d ca = cam.col(triangles(f, 0)), cb = cam.col(triangles(f, 1)),
                                cc = cam.col(triangles(f, 2));
          const Eigen::Vector3d cm = (ca + cb + cc) / 3.0;
          const Eigen::Vector3d samples[4] = {cm, ca + options.corner_shrink * (cm - ca),
                                              cb + options.corner_shrink * (cm - cb),
                                              cc + options.corner_shrink * (cm - cc)};
          int good = 0;
          for (const auto& p : samples) {
            const double z = p.z();
            const double u = camera.fx * p.x() / z + camera.cx;
            const double v = camera.fy * p.y() / z + camera.cy;
            if (!(z > 0.0) || u < options.border_pixels || v < options.border_pixels || u > max_u ||
                v > max_v)
              continue;
            if (z <= zbuffer(u, v) + options.depth_tolerance) ++good;
          }
          if (good >= options.min_visible_fraction * 4.0 - 1e-9) {
            out.visible[f] = 1;
            out.quality[f] = static_cast<float>(w);
          }
        }
      });
  return out;
}

}  // namespace artex
