#include "sensors/depth_mesh.h"

#include <cmath>

#include "models/error.h"
#include "models/normals.h"
#include "sensors/image_io.h"

namespace artex {
namespace {

// Accumulates unit triangle normals into per-vertex sums, normalises them and flips those that
// face away from `viewpoint`. points/normals: V entries; normals are overwritten.
void AccumulateNormals(const std::vector<Eigen::Vector3d>& points,
                       const std::vector<Eigen::Vector3i>& triangles,
                       const Eigen::Vector3d& viewpoint, std::vector<Eigen::Vector3d>* normals) {
  normals->assign(points.size(), Eigen::Vector3d::Zero());
  for (const Eigen::Vector3i& t : triangles) {
    const Eigen::Vector3d& a = points[t[0]];
    const Eigen::Vector3d n = (points[t[1]] - a).cross(points[t[2]] - a);
    const double len = n.norm();
    if (!(len > 0)) continue;
    const Eigen::Vector3d u = n / len;
    (*normals)[t[0]] += u;
    (*normals)[t[1]] += u;
    (*normals)[t[2]] += u;
  }
  for (size_t i = 0; i < points.size(); ++i) {
    Eigen::Vector3d& n = (*normals)[i];
    const double len = n.norm();
    if (!(len > 0)) {
      n.setZero();
      continue;
    }
    n /= len;
    if (n.dot(viewpoint - points[i]) < 0) n = -n;
  }
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

  // 1. Grid nodes with a valid, masked depth get provisional vertex ids.
  grid_index_.resize(static_cast<size_t>(gw) * gh);
  grid_z_.clear();
  grid_pixel_.clear();
  for (int gy = 0; gy < gh; ++gy) {
    const int v = gy * step;
    const uint16_t* d = depth.ptr<uint16_t>(v);
    const uint8_t* m = mask.empty() ? nullptr : mask.ptr<uint8_t>(v);
    int* idx = &grid_index_[static_cast<size_t>(gy) * gw];
    for (int gx = 0; gx < gw; ++gx) {
      const int u = gx * step;
      if (d[u] == 0 || (m && !m[u])) {
        idx[gx] = -1;
        continue;
      }
      idx[gx] = static_cast<int>(grid_z_.size());
      grid_z_.push_back(d[u] * inv_scale);
      grid_pixel_.push_back(v * cam.width + u);
    }
  }
  const int candidates = static_cast<int>(grid_z_.size());

  // 2. Triangles of each 2x2 block whose depth differences stay below the threshold.
  const float jump = static_cast<float>(options_.max_relative_jump * step);
  auto connected = [&](int a, int b) {
    const float za = grid_z_[a], zb = grid_z_[b];
    return std::abs(za - zb) <= jump * std::min(za, zb);
  };
  auto try_add = [&](int a, int b, int c) {
    if (connected(a, b) && connected(b, c) && connected(a, c)) triangles_.emplace_back(a, b, c);
  };
  triangles_.clear();
  for (int gy = 0; gy + 1 < gh; ++gy) {
    const int* row0 = &grid_index_[static_cast<size_t>(gy) * gw];
    const int* row1 = row0 + gw;
    for (int gx = 0; gx + 1 < gw; ++gx) {
      const int tl = row0[gx], tr = row0[gx + 1], bl = row1[gx], br = row1[gx + 1];
      const int valid = (tl >= 0) + (tr >= 0) + (bl >= 0) + (br >= 0);
      if (valid < 3) continue;
      // Counter-clockwise as seen from the camera (x right, y down, z forward).
      if (valid == 4) {
        try_add(tl, bl, tr);
        try_add(tr, bl, br);
      } else if (tl < 0) {
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

  // 3. Final vertex ids (dropping vertices without triangles when asked).
  remap_.assign(candidates, options_.drop_isolated_points ? -1 : 0);
  int num_vertices = candidates;
  if (options_.drop_isolated_points) {
    for (const Eigen::Vector3i& t : triangles_) remap_[t[0]] = remap_[t[1]] = remap_[t[2]] = 0;
  }
  num_vertices = 0;
  for (int i = 0; i < candidates; ++i) {
    if (remap_[i] == 0) remap_[i] = num_vertices++;
  }
  for (Eigen::Vector3i& t : triangles_) t = Eigen::Vector3i(remap_[t[0]], remap_[t[1]], remap_[t[2]]);

  // 4. World points.
  points_.resize(num_vertices);
  vertex_pixels_.resize(num_vertices);
  const float* rays = projector_.rays();
  const Eigen::Isometry3d camera_to_world = cam.world_to_camera.inverse();
  const Eigen::Matrix3d r = camera_to_world.linear();
  const Eigen::Vector3d t = camera_to_world.translation();
  for (int i = 0; i < candidates; ++i) {
    const int k = remap_[i];
    if (k < 0) continue;
    const int p = grid_pixel_[i];
    const double z = grid_z_[i];
    const Eigen::Vector3d c(rays[2 * p] * z, rays[2 * p + 1] * z, z);
    points_[k] = r * c + t;
    vertex_pixels_[k] = p;
  }

  // 5. Normals towards the camera centre.
  AccumulateNormals(points_, triangles_, t, &normals_);

  scan->points.resize(num_vertices, 3);
  scan->normals.resize(num_vertices, 3);
  for (int k = 0; k < 3; ++k) {
    double* pc = scan->points.col(k).data();
    double* nc = scan->normals.col(k).data();
    for (int i = 0; i < num_vertices; ++i) {
      pc[i] = points_[i][k];
      nc[i] = normals_[i][k];
    }
  }
  const int num_triangles = static_cast<int>(triangles_.size());
  scan->triangles.resize(num_triangles, 3);
  for (int k = 0; k < 3; ++k) {
    int* tc = scan->triangles.col(k).data();
    for (int i = 0; i < num_triangles; ++i) tc[i] = triangles_[i][k];
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
