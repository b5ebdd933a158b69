#include "texture/visibility.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "energies/texture_terms.h"
#include "models/error.h"
#include "render/rasterizer.h"

namespace artex {
namespace {

// std::lround for |x| < 2^31 without the library call (halfway cases away from zero).
inline int RoundHalfAwayFromZero(double x) {
  const int t = static_cast<int>(x);  // towards zero
  const double fraction = x - t;      // exact
  return t + (fraction >= 0.5) - (fraction <= -0.5);
}

// The unit normal of ComputeTriangleNormals (models/normals.h) from the area vector
// n = (b - a) x (c - a): zero when degenerate.
inline Eigen::Vector3d UnitNormal(const Eigen::Vector3d& n) {
  const double norm = n.norm();
  if (!(norm > 0.0) || !std::isfinite(norm)) return Eigen::Vector3d::Zero();
  return n / norm;
}

// A triangle whose area vector n and view vector d (centroid - camera centre) have
// n . d > kFacingAwayMargin |n|_1 |d|_1 faces away by far more than the rounding errors of the
// unit vectors and of their dot product (~1e-15): its quality W is 0.
constexpr double kFacingAwayMargin = 1e-9;

}  // namespace

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
  if (num_triangles > 0 && (triangles.minCoeff() < 0 || triangles.maxCoeff() >= num_vertices)) {
    std::ostringstream msg;
    msg << "ComputeVisibility: triangles: expected vertex indices in [0, " << num_vertices
        << "), found " << triangles.minCoeff() << ".." << triangles.maxCoeff();
    throw Error(msg.str());
  }
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
  std::vector<float> depth;  // zcam.width * zcam.height when any_pixels
  const bool any_pixels = x1 >= x0 && y1 >= y0;
  if (any_pixels) {
    zcam.width = x1 - x0 + 1;
    zcam.height = y1 - y0 + 1;
    zcam.cx -= x0;
    zcam.cy -= y0;
    RasterizeDepth(vertices, triangles, zcam, raster_options, &depth);
  }
  const float kNoSurface = std::numeric_limits<float>::infinity();
  const int depth_width = any_pixels ? zcam.width : 0;
  const int depth_height = any_pixels ? zcam.height : 0;
  const float* depth_data = depth.data();  // stays valid when moved into *surface
  // The z-buffer at full-image position (u, v), |u|, |v| < 2^31 (nearest raster pixel).
  const auto zbuffer = [&](double u, double v) {
    const double su = s == 1.0 ? u : (u + 0.5) * s - 0.5;
    const double sv = s == 1.0 ? v : (v + 0.5) * s - 0.5;
    const int x = RoundHalfAwayFromZero(su) - x0;
    const int y = RoundHalfAwayFromZero(sv) - y0;
    if (x < 0 || y < 0 || x >= depth_width || y >= depth_height) return kNoSurface;
    return depth_data[static_cast<std::size_t>(y) * depth_width + x];
  };
  if (surface != nullptr) {
    surface->scale = s;
    surface->x0 = x0;
    surface->y0 = y0;
    surface->width = depth_width;
    surface->height = depth_height;
    surface->depth = std::move(depth);
  }

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
          const Eigen::Vector3d n = (b - a).cross(c - a);
          const Eigen::Vector3d view = centroid - center;
          if (n.dot(view) > kFacingAwayMargin * n.cwiseAbs().sum() * view.cwiseAbs().sum())
            continue;
          const double w = TriangleQuality(UnitNormal(n), view.normalized());
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
