#include "sensors/depth_mesh.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "models/error.h"
#include "models/normals.h"
#include "sensors/image_io.h"

namespace artex {
namespace {

// Adds the unit normal of triangle (a, b, c) (4-float points x, y, z, 0; 16-byte aligned) to
// the three 4-float sums; degenerate triangles add nothing.
inline void AddUnitTriangleNormal(const float* a, const float* b, const float* c, float* sa,
                                  float* sb, float* sc) {
#if defined(__SSE2__)
  const __m128 pa = _mm_load_ps(a);
  const __m128 e1 = _mm_sub_ps(_mm_load_ps(b), pa);
  const __m128 e2 = _mm_sub_ps(_mm_load_ps(c), pa);
  // cross(e1, e2) = (e1 * e2.yzx - e1.yzx * e2).yzx
  const __m128 e1_yzx = _mm_shuffle_ps(e1, e1, _MM_SHUFFLE(3, 0, 2, 1));
  const __m128 e2_yzx = _mm_shuffle_ps(e2, e2, _MM_SHUFFLE(3, 0, 2, 1));
  const __m128 zxy = _mm_sub_ps(_mm_mul_ps(e1, e2_yzx), _mm_mul_ps(e1_yzx, e2));
  const __m128 n = _mm_shuffle_ps(zxy, zxy, _MM_SHUFFLE(3, 0, 2, 1));
  alignas(16) float q[4];
  _mm_store_ps(q, _mm_mul_ps(n, n));
  const float len2 = q[0] + q[1] + q[2];
  if (!(len2 > 0)) return;
  const __m128 u = _mm_mul_ps(n, _mm_set1_ps(1.0f / std::sqrt(len2)));
  _mm_store_ps(sa, _mm_add_ps(_mm_load_ps(sa), u));
  _mm_store_ps(sb, _mm_add_ps(_mm_load_ps(sb), u));
  _mm_store_ps(sc, _mm_add_ps(_mm_load_ps(sc), u));
#else
  const float e1x = b[0] - a[0], e1y = b[1] - a[1], e1z = b[2] - a[2];
  const float e2x = c[0] - a[0], e2y = c[1] - a[1], e2z = c[2] - a[2];
  const float nx = e1y * e2z - e1z * e2y, ny = e1z * e2x - e1x * e2z, nz = e1x * e2y - e1y * e2x;
  const float len2 = nx * nx + ny * ny + nz * nz;
  if (!(len2 > 0)) return;
  const float inv = 1.0f / std::sqrt(len2);
  for (float* s : {sa, sb, sc}) {
    s[0] += nx * inv;
    s[1] += ny * inv;
    s[2] += nz * inv;
  }
#endif
}

}  // namespace

bool DepthMeshOptions::IsValid(std::string* error) const {
  if (step < 1) {
    if (error) *error = "mesh.step: expected an integer >= 1, found " + std::to_string(step);
    return false;
  }
  if (!(max_relative_jump > 0) || !std::isfinite(max_relative_jump)) {
    if (error) *error = "mesh.max_relative_jump: expected a positive number";
    return false;
  }
  return true;
}

DepthBackProjector::DepthBackProjector(const PinholeCamera& camera, const Distortion& distortion)
    : camera_(camera) {
  if (camera.width <= 0 || camera.height <= 0 || !(camera.fx > 0) || !(camera.fy > 0)) {
    throw Error("depth camera: expected positive width, height, fx, fy");
  }
  rays_.resize(2 * static_cast<size_t>(camera.width) * camera.height);
  const bool distorted = !distortion.IsZero();
  for (int v = 0; v < camera.height; ++v) {
    for (int u = 0; u < camera.width; ++u) {
      Eigen::Vector2d p(u, v);
      if (distorted) p = UndistortPixel(camera, distortion, p);
      float* r = &rays_[2 * (static_cast<size_t>(v) * camera.width + u)];
      r[0] = static_cast<float>((p.x() - camera.cx) / camera.fx);
      r[1] = static_cast<float>((p.y() - camera.cy) / camera.fy);
    }
  }
  const Eigen::Isometry3d camera_to_world = camera.world_to_camera.inverse();
  rotation_ = camera_to_world.linear();
  translation_ = camera_to_world.translation();
}

Eigen::Vector3d DepthBackProjector::CameraPoint(int u, int v, double z) const {
  const float* r = &rays_[2 * (static_cast<size_t>(v) * camera_.width + u)];
  return {r[0] * z, r[1] * z, z};
}

Eigen::Vector3d DepthBackProjector::WorldPoint(int u, int v, double z) const {
  return rotation_ * CameraPoint(u, v, z) + translation_;
}

void DepthBackProjector::BackProject(const cv::Mat& depth, double depth_scale, const cv::Mat& mask,
                                     Eigen::MatrixX3d* points) const {
  if (depth.type() != CV_16UC1 || depth.cols != camera_.width || depth.rows != camera_.height) {
    throw Error("back-projection: expected a CV_16UC1 " + std::to_string(camera_.width) + "x" +
                std::to_string(camera_.height) + " depth image, found " +
                MatTypeName(depth.type()) + " " + std::to_string(depth.cols) + "x" +
                std::to_string(depth.rows));
  }
  if (!mask.empty() && (mask.type() != CV_8UC1 || mask.size() != depth.size())) {
    throw Error("back-projection: expected a CV_8UC1 mask of the depth image's size");
  }
  const double inv = 1.0 / depth_scale;
  int n = 0;
  for (int v = 0; v < depth.rows; ++v) {
    const uint16_t* d = depth.ptr<uint16_t>(v);
    const uint8_t* m = mask.empty() ? nullptr : mask.ptr<uint8_t>(v);
    for (int u = 0; u < depth.cols; ++u) n += d[u] != 0 && (!m || m[u]);
  }
  points->resize(n, 3);
  int i = 0;
  for (int v = 0; v < depth.rows; ++v) {
    const uint16_t* d = depth.ptr<uint16_t>(v);
    const uint8_t* m = mask.empty() ? nullptr : mask.ptr<uint8_t>(v);
    for (int u = 0; u < depth.cols; ++u) {
      if (d[u] == 0 || (m && !m[u])) continue;
      points->row(i++) = WorldPoint(u, v, d[u] * inv).transpose();
    }
  }
}

DepthMesher::DepthMesher(const PinholeCamera& camera, const Distortion& distortion,
                         const DepthMeshOptions& options)
    : projector_(camera, distortion), options_(options) {
  std::string error;
  if (!options_.IsValid(&error)) throw Error(error);
}

void DepthMesher::Build(const cv::Mat& depth, double depth_scale, const cv::Mat& mask, Scan* scan,
                        DepthMeshStats* stats) {
  const PinholeCamera& cam = projector_.camera();
  if (depth.type() != CV_16UC1 || depth.cols != cam.width || depth.rows != cam.height) {
    throw Error("depth mesh: expected a CV_16UC1 " + std::to_string(cam.width) + "x" +
                std::to_string(cam.height) + " depth image, found " + MatTypeName(depth.type()) +
                " " + std::to_string(depth.cols) + "x" + std::to_string(depth.rows));
  }
  if (!mask.empty() && (mask.type() != CV_8UC1 || mask.size() != depth.size())) {
    throw Error("depth mesh: expected a CV_8UC1 mask of size " + std::to_string(cam.width) + "x" +
                std::to_string(cam.height) + ", found " + MatTypeName(mask.type()) + " " +
                std::to_string(mask.cols) + "x" + std::to_string(mask.rows));
  }
  if (!(depth_scale > 0)) throw Error("depth mesh: expected a positive depth_scale");
  const int step = options_.step;
  const int gw = (cam.width - 1) / step + 1;
  const int gh = (cam.height - 1) / step + 1;
  const float inv_scale = static_cast<float>(1.0 / depth_scale);

  // 1. Grid nodes with a valid, masked depth get provisional vertex ids and camera points.
  const float* rays = projector_.rays();
  grid_index_.assign(static_cast<size_t>(gw) * gh, -1);
  row_range_.assign(2 * static_cast<size_t>(gh), 0);  // [first, last + 1) valid gx per row
  // Sized for the worst case once; only the first `candidates` entries are used.
  const size_t nodes = static_cast<size_t>(gw) * gh;
  if (grid_pixel_.size() < nodes) {
    grid_pixel_.resize(nodes);
    camera_points_.resize(4 * nodes);
  }
  int* node_pixel = grid_pixel_.data();
  float* node_point = camera_points_.data();
  int candidates = 0;
  for (int gy = 0; gy < gh; ++gy) {
    const int v = gy * step;
    const uint16_t* d = depth.ptr<uint16_t>(v);
    const uint8_t* m = mask.empty() ? nullptr : mask.ptr<uint8_t>(v);
    int* idx = &grid_index_[static_cast<size_t>(gy) * gw];
    int first = gw, last = -1;
    for (int gx = 0; gx < gw; ++gx) {
      const int u = gx * step;
      if (m && step == 1 && gx + 8 <= gw) {
        // Skip 8 background pixels at once (most of the mask is empty).
        uint64_t word;
        std::memcpy(&word, m + u, sizeof(word));
        if (word == 0) {
          gx += 7;
          continue;
        }
      }
      if (d[u] == 0 || (m && !m[u])) continue;
      const int pixel = v * cam.width + u;
      const float z = d[u] * inv_scale;
      idx[gx] = candidates;
      node_pixel[candidates] = pixel;
      float* p = node_point + 4 * static_cast<size_t>(candidates);
      p[0] = rays[2 * pixel] * z;
      p[1] = rays[2 * pixel + 1] * z;
      p[2] = z;
      p[3] = 0;
      ++candidates;
      first = std::min(first, gx);
      last = gx;
    }
    row_range_[2 * gy] = first;
    row_range_[2 * gy + 1] = last + 1;
  }

  // 2. Triangles of each 2x2 block whose depth differences stay below the threshold. A block
  // with >= 3 valid nodes has a valid top-left or bottom-right node, so there are at most
  // 2 x candidates such blocks and 4 x candidates triangles.
  const float jump = static_cast<float>(options_.max_relative_jump * step);
  triangles_.resize(12 * static_cast<size_t>(candidates));
  remap_.assign(candidates, options_.drop_isolated_points ? -1 : 0);
  int* tri = triangles_.data();
  int* used = remap_.data();
  const float* cp = camera_points_.data();
  // Pairwise |z_a - z_b| <= jump min(z_a, z_b) for all pairs <=> z_max - z_min <= jump z_min.
  auto try_add = [&](int a, int b, int c) {
    const float za = cp[4 * a + 2], zb = cp[4 * b + 2], zc = cp[4 * c + 2];
    const float lo = std::min(za, std::min(zb, zc)), hi = std::max(za, std::max(zb, zc));
    if (hi - lo > jump * lo) return;
    tri[0] = a;
    tri[1] = b;
    tri[2] = c;
    tri += 3;
    used[a] = used[b] = used[c] = 0;
  };
  for (int gy = 0; gy + 1 < gh; ++gy) {
    const int* row0 = &grid_index_[static_cast<size_t>(gy) * gw];
    const int* row1 = row0 + gw;
    // Blocks with a valid node in both rows lie within both rows' valid ranges.
    const int begin = std::max(row_range_[2 * gy], row_range_[2 * gy + 2]) - 1;
    const int end = std::min(row_range_[2 * gy + 1], row_range_[2 * gy + 3]);
    for (int gx = std::max(begin, 0); gx + 1 < gw && gx < end; ++gx) {
      const int tl = row0[gx], tr = row0[gx + 1], bl = row1[gx], br = row1[gx + 1];
      if ((tl | tr | bl | br) >= 0) {
        // Counter-clockwise as seen from the camera (x right, y down, z forward).
        try_add(tl, bl, tr);
        try_add(tr, bl, br);
        continue;
      }
      if ((tl < 0) + (tr < 0) + (bl < 0) + (br < 0) > 1) continue;
      if (tl < 0) {
        try_add(tr, bl, br);
      } else if (tr < 0) {
        try_add(tl, bl, br);
      } else if (bl < 0) {
        try_add(tl, br, tr);
      } else {
        try_add(tl, bl, tr);
      }
    }
  }
  const int num_triangles = static_cast<int>((tri - triangles_.data()) / 3);

  // 3. Final vertex ids (vertices without triangles were left at -1 when they are dropped).
  int num_vertices = 0;
  for (int i = 0; i < candidates; ++i) {
    if (remap_[i] == 0) remap_[i] = num_vertices++;
  }

  // 4. Normals (camera frame): sums of unit triangle normals, normalised, facing the camera.
  // 4-float (SIMD) vectors: x, y, z, 0.
  normal_sums_.assign(4 * static_cast<size_t>(candidates), 0.0f);
  float* ns = normal_sums_.data();
  for (int f = 0; f < num_triangles; ++f) {
    const int* t = &triangles_[3 * static_cast<size_t>(f)];
    AddUnitTriangleNormal(cp + 4 * t[0], cp + 4 * t[1], cp + 4 * t[2], ns + 4 * t[0], ns + 4 * t[1],
                          ns + 4 * t[2]);
  }

  // 5. World points and normals of the kept vertices; triangles renumbered.
  const Eigen::Isometry3d camera_to_world = cam.world_to_camera.inverse();
  const Eigen::Matrix3d r = camera_to_world.linear();
  const Eigen::Vector3d t = camera_to_world.translation();
  scan->points.resize(num_vertices, 3);
  scan->normals.resize(num_vertices, 3);
  vertex_pixels_.resize(num_vertices);
  double* px = scan->points.col(0).data();
  double* py = scan->points.col(1).data();
  double* pz = scan->points.col(2).data();
  double* nx = scan->normals.col(0).data();
  double* ny = scan->normals.col(1).data();
  double* nz = scan->normals.col(2).data();
  // Local copies: the output arrays could otherwise alias them and force reloads.
  const double r00 = r(0, 0), r01 = r(0, 1), r02 = r(0, 2), r10 = r(1, 0), r11 = r(1, 1),
               r12 = r(1, 2), r20 = r(2, 0), r21 = r(2, 1), r22 = r(2, 2);
  const double tx = t.x(), ty = t.y(), tz = t.z();
  const int* remap = remap_.data();
  const int* pixels = grid_pixel_.data();
  int* vertex_pixels = vertex_pixels_.data();
  for (int i = 0; i < candidates; ++i) {
    const int k = remap[i];
    if (k < 0) continue;
    const double cx = cp[4 * i], cy = cp[4 * i + 1], cz = cp[4 * i + 2];
    px[k] = r00 * cx + r01 * cy + r02 * cz + tx;
    py[k] = r10 * cx + r11 * cy + r12 * cz + ty;
    pz[k] = r20 * cx + r21 * cy + r22 * cz + tz;
    double mx = ns[4 * i], my = ns[4 * i + 1], mz = ns[4 * i + 2];
    const double len2 = mx * mx + my * my + mz * mz;
    if (len2 > 0) {
      // Unit length, facing the camera centre (the origin of the camera frame).
      double scale = 1.0 / std::sqrt(len2);
      if (mx * cx + my * cy + mz * cz > 0) scale = -scale;
      mx *= scale;
      my *= scale;
      mz *= scale;
    }
    nx[k] = r00 * mx + r01 * my + r02 * mz;
    ny[k] = r10 * mx + r11 * my + r12 * mz;
    nz[k] = r20 * mx + r21 * my + r22 * mz;
    vertex_pixels[k] = pixels[i];
  }
  scan->triangles.resize(num_triangles, 3);
  int* t0 = scan->triangles.col(0).data();
  int* t1 = scan->triangles.col(1).data();
  int* t2 = scan->triangles.col(2).data();
  for (int i = 0; i < num_triangles; ++i) {
    t0[i] = remap_[triangles_[3 * i]];
    t1[i] = remap_[triangles_[3 * i + 1]];
    t2[i] = remap_[triangles_[3 * i + 2]];
  }
  if (stats) {
    stats->candidate_pixels = candidates;
    stats->vertices = num_vertices;
    stats->triangles = num_triangles;
    stats->isolated_dropped = candidates - num_vertices;
  }
}

void ComputeOrientedVertexNormals(const Eigen::MatrixX3d& vertices,
                                  const Eigen::MatrixX3i& triangles,
                                  const Eigen::Vector3d& viewpoint, Eigen::MatrixX3d* normals) {
  ComputeVertexNormals(vertices, triangles, normals);
  for (int i = 0; i < vertices.rows(); ++i) {
    if (normals->row(i).dot(viewpoint.transpose() - vertices.row(i)) < 0) {
      normals->row(i) *= -1.0;
    }
  }
}

}  // namespace artex
