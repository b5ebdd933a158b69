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

// Bands of image rows rasterised in parallel: every band owns its pixels and visits the
// triangles overlapping it in index order, so no synchronisation is needed and the result does
// not depend on the thread schedule. The height only affects speed.
constexpr int kBandRows = 32;
// The depth computed at a pixel inside a triangle is at least its nearest corner's depth times
// (1 - 8 u) (u = 2^-53: the roundings of 1/z, of the three products and sums and of the
// quotient); this factor is far below that.
constexpr double kDepthBoundFactor = 1.0 - 1e-12;

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

// std::max(0, static_cast<int>(std::ceil(x))) and std::min(hi, static_cast<int>(std::floor(x)))
// for finite x with x <= hi (ceil) or x >= 0 (floor), hi >= 0, without library calls (and well
// defined beyond the int range).
inline int CeilAtLeastZero(double x, int hi) {
  if (!(x > 0.0)) return 0;
  if (x >= hi) return hi;
  const int t = static_cast<int>(x);  // floor for positive x
  return t + (t < x);
}
inline int FloorAtMost(double x, int hi) { return x >= hi ? hi : static_cast<int>(x); }

// What binning needs of a triangle (computed once): drawn or not, orientation, pixel box.
struct TriangleBox {
  bool drawn = false;
  bool flipped = false;  // corners 1 and 2 swapped for the positive orientation
  int x0, x1, y0, y1;    // inclusive pixel bounding box, clipped to the image
};

// What rasterisation needs of a triangle (set up per band from the screen points: cheaper
// than keeping it in memory for every triangle).
struct TriangleSetup {
  int corner[3];  // original corner index (0..2) of the positively oriented vertex order
  double inv_z[3];
  Edge edge[3];  // edge i: vertex i -> vertex i+1 (positively oriented order)

  void Set(const ScreenPoint* const p[3], bool flipped) {
    corner[0] = 0;
    corner[1] = flipped ? 2 : 1;
    corner[2] = flipped ? 1 : 2;
    const ScreenPoint* q[3] = {p[corner[0]], p[corner[1]], p[corner[2]]};
    for (int k = 0; k < 3; ++k) {
      inv_z[k] = 1.0 / q[k]->z;
      edge[k].Set(*q[k], *q[(k + 1) % 3]);
    }
  }
};

// Fills `depth` and, when kSurface, `ids` and `bary` (all width * height, pre-filled with "no
// hit").
template <bool kSurface>
void RasterizeInto(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                   const PinholeCamera& camera, const RasterOptions& options, float* depth,
                   int32_t* ids, Eigen::Vector2f* bary) {
  const int width = camera.width;
  const int height = camera.height;
  const int num_vertices = static_cast<int>(vertices.rows());
  const int num_triangles = static_cast<int>(triangles.rows());

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
  const auto corners = [&](int f, const ScreenPoint* p[3]) {
    for (int k = 0; k < 3; ++k) p[k] = &screen[triangles(f, k)];
  };

  // Which triangles are drawn and where (parallel).
  std::vector<TriangleBox> boxes(num_triangles);
  tbb::parallel_for(tbb::blocked_range<int>(0, num_triangles, 1024),
                    [&](const tbb::blocked_range<int>& range) {
                      for (int f = range.begin(); f < range.end(); ++f) {
                        const ScreenPoint* p[3];
                        corners(f, p);
                        bool ok = true;
                        for (int k = 0; k < 3; ++k) {
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
                        const double min_x = std::min({p[0]->x, p[1]->x, p[2]->x});
                        const double max_x = std::max({p[0]->x, p[1]->x, p[2]->x});
                        const double min_y = std::min({p[0]->y, p[1]->y, p[2]->y});
                        const double max_y = std::max({p[0]->y, p[1]->y, p[2]->y});
                        if (max_x < 0 || max_y < 0 || min_x > width - 1 || min_y > height - 1)
                          continue;
                        TriangleBox& b = boxes[f];
                        b.x0 = CeilAtLeastZero(min_x, width - 1);
                        b.x1 = FloorAtMost(max_x, width - 1);
                        b.y0 = CeilAtLeastZero(min_y, height - 1);
                        b.y1 = FloorAtMost(max_y, height - 1);
                        b.flipped = !(area > 0);
                        b.drawn = b.x0 <= b.x1 && b.y0 <= b.y1;
                      }
                    });

  // Binning into bands (serial). A pixel's depth is the minimum over the triangles, and its
  // triangle the first in index order of those at that depth (the order of (depth, index)),
  // whatever order they are drawn in: triangles facing the camera (negative area for
  // counter-clockwise meshes) go first, so that the occlusion test below skips most of the others.
  const int num_bands = (height + kBandRows - 1) / kBandRows;
  std::vector<std::vector<int>> bins(num_bands), later_bins(num_bands);
  for (int f = 0; f < num_triangles; ++f) {
    const TriangleBox& box = boxes[f];
    if (!box.drawn) continue;
    std::vector<std::vector<int>>& to = box.flipped ? bins : later_bins;
    for (int band = box.y0 / kBandRows; band <= box.y1 / kBandRows; ++band) to[band].push_back(f);
  }
  for (int band = 0; band < num_bands; ++band)
    bins[band].insert(bins[band].end(), later_bins[band].begin(), later_bins[band].end());

  tbb::parallel_for(
      tbb::blocked_range<int>(0, num_bands, 1), [&](const tbb::blocked_range<int>& range) {
        for (int band = range.begin(); band < range.end(); ++band) {
          const int band_y0 = band * kBandRows;
          const int band_y1 = std::min(height - 1, band_y0 + kBandRows - 1);
          for (int f : bins[band]) {
            const TriangleBox& box = boxes[f];
            const ScreenPoint* p[3];
            corners(f, p);
            const int y0 = std::max(box.y0, band_y0), y1 = std::min(box.y1, band_y1);
            // Occlusion test: every depth computed inside the triangle is at least its nearest
            // corner's depth up to a few rounding errors (z_bound, rounded to float, is at most
            // any of them), so where the buffer is already below z_bound across the box (at most
            // z_bound for the depth alone, where a tie changes nothing), no pixel can change.
            const float z_bound =
                static_cast<float>(std::min({p[0]->z, p[1]->z, p[2]->z}) * kDepthBoundFactor);
            bool occluded = true;
            for (int y = y0; y <= y1 && occluded; ++y) {
              const float* row = depth + static_cast<size_t>(y) * width;
              for (int x = box.x0; x <= box.x1 && occluded; ++x)
                occluded = kSurface ? row[x] < z_bound : row[x] <= z_bound;
            }
            if (occluded) continue;
            TriangleSetup t;
            t.Set(p, box.flipped);
            for (int y = y0; y <= y1; ++y) {
              const double py = y;
              const double r0 = t.edge[0].Row(py);
              const double r1 = t.edge[1].Row(py);
              const double r2 = t.edge[2].Row(py);
              // Each edge value is monotone along the row (every rounding step is), so the
              // covered pixels of a row are contiguous: stop at the first pixel after them.
              bool entered = false;
              for (int x = box.x0; x <= box.x1; ++x) {
                const double px = x;
                const double e0 = t.edge[0].Value(r0, px);
                const double e1 = t.edge[1].Value(r1, px);
                const double e2 = t.edge[2].Value(r2, px);
                if (!(t.edge[0].Inside(e0) && t.edge[1].Inside(e1) && t.edge[2].Inside(e2))) {
                  if (entered) break;
                  continue;
                }
                entered = true;
                // Screen-space barycentrics of vertices 0, 1, 2 are e1, e2, e0 (the edge
                // opposite each vertex), then perspective correction with 1/z.
                const double w0 = e1 * t.inv_z[0];
                const double w1 = e2 * t.inv_z[1];
                const double w2 = e0 * t.inv_z[2];
                const double w = w0 + w1 + w2;
                const double z = (e0 + e1 + e2) / w;
                const size_t index = static_cast<size_t>(y) * width + x;
                const float zf = static_cast<float>(z);
                // With ids, an equal depth goes to the smaller index (+inf, where ids is -1, is
                // never equal: zf is finite or NaN).
                if (!(zf < depth[index] || (kSurface && zf == depth[index] && f < ids[index])))
                  continue;
                depth[index] = zf;
                if constexpr (kSurface) {
                  ids[index] = f;
                  double b[3];
                  b[t.corner[0]] = w0 / w;
                  b[t.corner[1]] = w1 / w;
                  b[t.corner[2]] = w2 / w;
                  bary[index] = Eigen::Vector2f(static_cast<float>(b[1]), static_cast<float>(b[2]));
                }
              }
            }
          }
        }
      });
}

// Throws unless the camera has pixels and every triangle index names a vertex.
void CheckInput(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                const PinholeCamera& camera, const char* function) {
  if (camera.width <= 0 || camera.height <= 0) {
    std::ostringstream msg;
    msg << function << ": camera size must be positive, found " << camera.width << " x "
        << camera.height;
    throw Error(msg.str());
  }
  const int num_vertices = static_cast<int>(vertices.rows());
  if (triangles.rows() > 0 && (triangles.minCoeff() < 0 || triangles.maxCoeff() >= num_vertices)) {
    std::ostringstream msg;
    msg << function << ": triangle indices must lie in [0, " << num_vertices << "), found range ["
        << triangles.minCoeff() << ", " << triangles.maxCoeff() << "]";
    throw Error(msg.str());
  }
}

}  // namespace

void Rasterize(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
               const PinholeCamera& camera, const RasterOptions& options, RasterBuffers* out) {
  CheckInput(vertices, triangles, camera, "Rasterize");
  out->width = camera.width;
  out->height = camera.height;
  const size_t num_pixels = static_cast<size_t>(camera.width) * camera.height;
  out->depth.assign(num_pixels, std::numeric_limits<float>::infinity());
  out->triangle_id.assign(num_pixels, -1);
  out->barycentric.assign(num_pixels, Eigen::Vector2f::Zero());
  RasterizeInto<true>(vertices, triangles, camera, options, out->depth.data(),
                      out->triangle_id.data(), out->barycentric.data());
}

void RasterizeDepth(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                    const PinholeCamera& camera, const RasterOptions& options,
                    std::vector<float>* depth) {
  CheckInput(vertices, triangles, camera, "RasterizeDepth");
  depth->assign(static_cast<size_t>(camera.width) * camera.height,
                std::numeric_limits<float>::infinity());
  RasterizeInto<false>(vertices, triangles, camera, options, depth->data(), nullptr, nullptr);
}

}  // namespace artex
