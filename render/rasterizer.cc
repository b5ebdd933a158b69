#include "render/rasterizer.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "models/error.h"

namespace artex {
namespace {

// Screen tiles processed in parallel: every tile owns its pixels, so no synchronisation is
// needed and the result does not depend on the thread schedule (triangles are visited in
// index order inside a tile). The size only affects speed.
constexpr int kTileSize = 32;

struct ScreenPoint {
  double x = 0, y = 0;  // pixel coordinates
  double z = 0;         // camera depth (m)
};

// Lexicographic order on (x, y): every edge is evaluated from its smaller to its larger
// endpoint, so the two triangles sharing an edge compute bitwise-identical edge values (up
// to the sign), which makes the top-left rule exact: no cracks and no double coverage.
inline bool Before(const ScreenPoint& a, const ScreenPoint& b) {
  return a.x < b.x || (a.x == b.x && a.y < b.y);
}

struct Edge {
  double ax, ay;   // canonical start point
  double dx, dy;   // canonical direction (b - a)
  double sign;     // +1 if the triangle traverses the edge canonically, -1 otherwise
  bool owns_zero;  // top-left rule: pixels exactly on the edge belong to this triangle

  void Set(const ScreenPoint& from, const ScreenPoint& to) {
    const bool canonical = Before(from, to);
    const ScreenPoint& a = canonical ? from : to;
    const ScreenPoint& b = canonical ? to : from;
    ax = a.x;
    ay = a.y;
    dx = b.x - a.x;
    dy = b.y - a.y;
    sign = canonical ? 1.0 : -1.0;
    // Direction as traversed by the (positively oriented) triangle. IEEE subtraction is
    // sign-symmetric, so the neighbour sees exactly the opposite signs.
    const double tdx = to.x - from.x;
    const double tdy = to.y - from.y;
    // Image y points down; with interior on the positive side, a "left" edge goes up
    // (dy < 0) and a "top" edge is horizontal going right.
    owns_zero = tdy < 0 || (tdy == 0 && tdx > 0);
  }
  // Row part of the edge function, shared by all pixels of row py.
  double Row(double py) const { return dx * (py - ay); }
  double Value(double row, double px) const { return sign * (row - dy * (px - ax)); }
  bool Inside(double value) const { return value > 0 || (value == 0 && owns_zero); }
};

struct TriangleSetup {
  int id = -1;
  int corner[3];  // original corner index (0..2) of the positively oriented vertex order
  double inv_z[3];
  Edge edge[3];        // edge i: vertex i -> vertex i+1 (positively oriented order)
  int x0, x1, y0, y1;  // inclusive pixel bounding box, clipped to the image
};

}  // namespace

void Rasterize(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
               const PinholeCamera& camera, const RasterOptions& options, RasterBuffers* out) {
  const int width = camera.width;
  const int height = camera.height;
  if (width <= 0 || height <= 0) {
    std::ostringstream msg;
    msg << "Rasterize: camera size must be positive, found " << width << " x " << height;
    throw Error(msg.str());
  }
  const int num_vertices = static_cast<int>(vertices.rows());
  const int num_triangles = static_cast<int>(triangles.rows());
  if (num_triangles > 0 && (triangles.minCoeff() < 0 || triangles.maxCoeff() >= num_vertices)) {
    std::ostringstream msg;
    msg << "Rasterize: triangle indices must lie in [0, " << num_vertices << "), found range ["
        << triangles.minCoeff() << ", " << triangles.maxCoeff() << "]";
    throw Error(msg.str());
  }

  out->width = width;
  out->height = height;
  const size_t num_pixels = static_cast<size_t>(width) * height;
  out->depth.assign(num_pixels, std::numeric_limits<float>::infinity());
  out->triangle_id.assign(num_pixels, -1);
  out->barycentric.assign(num_pixels, Eigen::Vector2f::Zero());

  // Project every vertex once (shared vertices get bitwise-identical screen positions).
  std::vector<ScreenPoint> screen(num_vertices);
  const Eigen::Matrix3d rotation = camera.world_to_camera.linear();
  const Eigen::Vector3d translation = camera.world_to_camera.translation();
  tbb::parallel_for(
      tbb::blocked_range<int>(0, num_vertices, 4096), [&](const tbb::blocked_range<int>& range) {
        for (int i = range.begin(); i < range.end(); ++i) {
          const Eigen::Vector3d c = rotation * vertices.row(i).transpose() + translation;
          ScreenPoint& s = screen[i];
          s.z = c.z();
          s.x = camera.fx * c.x() / c.z() + camera.cx;
          s.y = camera.fy * c.y() / c.z() + camera.cy;
        }
      });

  // Triangle setup (parallel), then binning into tiles (serial, in triangle order).
  std::vector<TriangleSetup> setups(num_triangles);
  std::vector<uint8_t> keep(num_triangles, 0);
  tbb::parallel_for(tbb::blocked_range<int>(0, num_triangles, 1024),
                    [&](const tbb::blocked_range<int>& range) {
                      for (int f = range.begin(); f < range.end(); ++f) {
                        const ScreenPoint* p[3];
                        bool ok = true;
                        for (int k = 0; k < 3; ++k) {
                          p[k] = &screen[triangles(f, k)];
                          // Near-plane rejection (also removes points behind the camera) and
                          // non-finite input.
                          if (!(p[k]->z >= options.near_plane) || !std::isfinite(p[k]->x) ||
                              !std::isfinite(p[k]->y)) {
                            ok = false;
                          }
                        }
                        if (!ok) continue;
                        // Signed doubled area from the canonical edge function of edge 0 -> 1 at
                        // vertex 2.
                        Edge e01;
                        e01.Set(*p[0], *p[1]);
                        const double area = e01.Value(e01.Row(p[2]->y), p[2]->x);
                        if (area == 0) continue;
                        // With image y downwards, a triangle counter-clockwise from outside that
                        // faces the camera has a negative area in this convention.
                        if (options.cull_backfaces && area > 0) continue;
                        TriangleSetup& t = setups[f];
                        t.id = f;
                        if (area > 0) {
                          t.corner[0] = 0, t.corner[1] = 1, t.corner[2] = 2;
                        } else {
                          t.corner[0] = 0, t.corner[1] = 2, t.corner[2] = 1;
                        }
                        const ScreenPoint* q[3] = {p[t.corner[0]], p[t.corner[1]], p[t.corner[2]]};
                        for (int k = 0; k < 3; ++k) {
                          t.inv_z[k] = 1.0 / q[k]->z;
                          t.edge[k].Set(*q[k], *q[(k + 1) % 3]);
                        }
                        const double min_x = std::min({q[0]->x, q[1]->x, q[2]->x});
                        const double max_x = std::max({q[0]->x, q[1]->x, q[2]->x});
                        const double min_y = std::min({q[0]->y, q[1]->y, q[2]->y});
                        const double max_y = std::max({q[0]->y, q[1]->y, q[2]->y});
                        if (max_x < 0 || max_y < 0 || min_x > width - 1 || min_y > height - 1)
                          continue;
                        t.x0 = std::max(0, static_cast<int>(std::ceil(min_x)));
                        t.x1 = std::min(width - 1, static_cast<int>(std::floor(max_x)));
                        t.y0 = std::max(0, static_cast<int>(std::ceil(min_y)));
                        t.y1 = std::min(height - 1, static_cast<int>(std::floor(max_y)));
                        if (t.x0 > t.x1 || t.y0 > t.y1) continue;
                        keep[f] = 1;
                      }
                    });

  const int tiles_x = (width + kTileSize - 1) / kTileSize;
  const int tiles_y = (height + kTileSize - 1) / kTileSize;
  std::vector<std::vector<int>> bins(static_cast<size_t>(tiles_x) * tiles_y);
  for (int f = 0; f < num_triangles; ++f) {
    if (!keep[f]) continue;
    const TriangleSetup& t = setups[f];
    for (int ty = t.y0 / kTileSize; ty <= t.y1 / kTileSize; ++ty) {
      for (int tx = t.x0 / kTileSize; tx <= t.x1 / kTileSize; ++tx) {
        bins[ty * tiles_x + tx].push_back(f);
      }
    }
  }

  float* depth = out->depth.data();
  int32_t* ids = out->triangle_id.data();
  Eigen::Vector2f* bary = out->barycentric.data();
  tbb::parallel_for(
      tbb::blocked_range<int>(0, tiles_x * tiles_y, 1), [&](const tbb::blocked_range<int>& range) {
        for (int tile = range.begin(); tile < range.end(); ++tile) {
          const int tx = tile % tiles_x;
          const int ty = tile / tiles_x;
          const int tile_x0 = tx * kTileSize;
          const int tile_y0 = ty * kTileSize;
          const int tile_x1 = std::min(width - 1, tile_x0 + kTileSize - 1);
          const int tile_y1 = std::min(height - 1, tile_y0 + kTileSize - 1);
          for (int f : bins[tile]) {
            const TriangleSetup& t = setups[f];
            const int x0 = std::max(t.x0, tile_x0), x1 = std::min(t.x1, tile_x1);
            const int y0 = std::max(t.y0, tile_y0), y1 = std::min(t.y1, tile_y1);
            for (int y = y0; y <= y1; ++y) {
              const double py = y;
              const double r0 = t.edge[0].Row(py);
              const double r1 = t.edge[1].Row(py);
              const double r2 = t.edge[2].Row(py);
              for (int x = x0; x <= x1; ++x) {
                const double px = x;
                const double e0 = t.edge[0].Value(r0, px);
                if (!t.edge[0].Inside(e0)) continue;
                const double e1 = t.edge[1].Value(r1, px);
                if (!t.edge[1].Inside(e1)) continue;
                const double e2 = t.edge[2].Value(r2, px);
                if (!t.edge[2].Inside(e2)) continue;
                // Screen-space barycentrics of vertices 0, 1, 2 are e1, e2, e0 (the edge
                // opposite each vertex), then perspective correction with 1/z.
                const double w0 = e1 * t.inv_z[0];
                const double w1 = e2 * t.inv_z[1];
                const double w2 = e0 * t.inv_z[2];
                const double w = w0 + w1 + w2;
                const double z = (e0 + e1 + e2) / w;
                const size_t index = static_cast<size_t>(y) * width + x;
                const float zf = static_cast<float>(z);
                if (!(zf < depth[index])) continue;
                depth[index] = zf;
                ids[index] = t.id;
                double b[3];
                b[t.corner[0]] = w0 / w;
                b[t.corner[1]] = w1 / w;
                b[t.corner[2]] = w2 / w;
                bary[index] = Eigen::Vector2f(static_cast<float>(b[1]), static_cast<float>(b[2]));
              }
            }
          }
        }
      });
}

}  // namespace artex
