#include "texture/texel_sampling.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "models/error.h"

namespace artex {
namespace {
// Triangles projecting onto more pixels than this skip the whole-triangle z-buffer check of
// SampleTriangle (the per-texel tests are then cheaper).
constexpr int kMaxSurfaceCheckPixels = 4096;
}  // namespace

AtlasMap::AtlasMap(const Template& tmpl, int size) : size_(size) {
  if (!tmpl.has_uvs()) throw Error("texture atlas: the template has no UV atlas (uv_triangles)");
  if (size < 16) {
    std::ostringstream msg;
    msg << "texture.atlas_size: expected >= 16, found " << size;
    throw Error(msg.str());
  }
  const int f_count = tmpl.num_triangles();
  const std::size_t total = static_cast<std::size_t>(size) * size;
  texel_triangle_.assign(total, -1);
  std::vector<Eigen::Vector3f> texel_bary(total, Eigen::Vector3f::Zero());
  for (int f = 0; f < f_count; ++f) {
    Eigen::Vector2d p[3];
    for (int c = 0; c < 3; ++c) p[c] = tmpl.uvs.row(tmpl.uv_triangles(f, c)).transpose() * size;
    const double area =
        (p[1] - p[0]).x() * (p[2] - p[0]).y() - (p[1] - p[0]).y() * (p[2] - p[0]).x();
    if (std::abs(area) < 1e-12) continue;
    const int x0 =
        std::max(0, static_cast<int>(std::floor(std::min({p[0].x(), p[1].x(), p[2].x()}))));
    const int x1 =
        std::min(size - 1, static_cast<int>(std::ceil(std::max({p[0].x(), p[1].x(), p[2].x()}))));
    const int y0 =
        std::max(0, static_cast<int>(std::floor(std::min({p[0].y(), p[1].y(), p[2].y()}))));
    const int y1 =
        std::min(size - 1, static_cast<int>(std::ceil(std::max({p[0].y(), p[1].y(), p[2].y()}))));
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        const Eigen::Vector2d q(x + 0.5, y + 0.5);
        const double b1 =
            ((q - p[0]).x() * (p[2] - p[0]).y() - (q - p[0]).y() * (p[2] - p[0]).x()) / area;
        const double b2 =
            ((p[1] - p[0]).x() * (q - p[0]).y() - (p[1] - p[0]).y() * (q - p[0]).x()) / area;
        const double b0 = 1.0 - b1 - b2;
        if (b0 < 0 || b1 < 0 || b2 < 0) continue;
        const int texel = y * size + x;
        if (texel_triangle_[texel] >= 0) continue;  // shared boundary: first triangle wins
        texel_triangle_[texel] = f;
        texel_bary[texel] = Eigen::Vector3f(b0, b1, b2);
      }
    }
  }
  // Triangle-major order (texels of a triangle in row-major order), by a counting sort.
  offsets_.assign(f_count + 1, 0);
  for (std::size_t t = 0; t < total; ++t)
    if (texel_triangle_[t] >= 0) ++offsets_[texel_triangle_[t] + 1];
  for (int f = 0; f < f_count; ++f) offsets_[f + 1] += offsets_[f];
  texels_.resize(offsets_[f_count]);
  bary_.resize(offsets_[f_count]);
  texel_position_.assign(total, -1);
  std::vector<int> fill(offsets_.begin(), offsets_.end() - 1);
  for (std::size_t t = 0; t < total; ++t) {
    const int f = texel_triangle_[t];
    if (f < 0) continue;
    const int position = fill[f]++;
    texels_[position] = static_cast<int>(t);
    bary_[position] = texel_bary[t];
    texel_position_[t] = position;
  }
}

double AtlasMap::Coverage() const {
  return static_cast<double>(texels_.size()) / (static_cast<double>(size_) * size_);
}

int SampleTriangle(const AtlasMap& map, int f, const Eigen::MatrixX3i& triangles,
                   const PoolEntry& entry, TexelBuffer* texels) {
  // The texel's surface point w . (a, b, c) is projected through the entry's camera; camera
  // coordinates are linear in the barycentrics, so the corners are transformed once.
  Eigen::Vector3d corner[3];
  for (int k = 0; k < 3; ++k)
    corner[k] = entry.camera.world_to_camera * entry.vertices.row(triangles(f, k)).transpose();
  Eigen::Vector3f* color = texels->color.data();
  uint8_t* valid = texels->valid.data();
  int written = 0;
  double tolerance_offset = 0.0, tolerance_slope = 0.0;
  entry.SurfaceTolerance(entry.visibility.quality[f], &tolerance_offset, &tolerance_slope);
  const PinholeCamera& camera = entry.camera;
  // When every z-buffer pixel around the triangle's projection is within the tolerance of every
  // depth on the triangle, each texel's bilinear footprint lies on the surface: plain sampling
  // gives the same colours without the per-pixel tests.
  bool on_surface = entry.surface.depth.empty();
  if (!on_surface && corner[0].z() > 0.0 && corner[1].z() > 0.0 && corner[2].z() > 0.0) {
    double u_min = std::numeric_limits<double>::infinity(), v_min = u_min;
    double u_max = -u_min, v_max = -u_min, z_min = u_min, z_max = -u_min;
    for (const Eigen::Vector3d& k : corner) {
      const double u = camera.fx * k.x() / k.z() + camera.cx;
      const double v = camera.fy * k.y() / k.z() + camera.cy;
      u_min = std::min(u_min, u);
      u_max = std::max(u_max, u);
      v_min = std::min(v_min, v);
      v_max = std::max(v_max, v);
      z_min = std::min(z_min, k.z());
      z_max = std::max(z_max, k.z());
    }
    const double tolerance = tolerance_offset + tolerance_slope * z_min;
    const int x0 = static_cast<int>(std::floor(u_min)),
              x1 = static_cast<int>(std::floor(u_max)) + 1;
    const int y0 = static_cast<int>(std::floor(v_min)),
              y1 = static_cast<int>(std::floor(v_max)) + 1;
    on_surface = (x1 - x0 + 1) * (y1 - y0 + 1) <= kMaxSurfaceCheckPixels;
    for (int y = y0; y <= y1 && on_surface; ++y) {
      for (int x = x0; x <= x1 && on_surface; ++x) {
        const float d = entry.surface.At(x, y);
        on_surface = d - z_min <= tolerance && z_max - d <= tolerance;
      }
    }
  }
  for (int p = map.first(f); p < map.last(f); ++p) {
    const Eigen::Vector3f& w = map.barycentric_at(p);
    const Eigen::Vector3d c = w.x() * corner[0] + w.y() * corner[1] + w.z() * corner[2];
    const double inv_z = 1.0 / c.z();
    const double u = camera.fx * c.x() * inv_z + camera.cx;
    const double v = camera.fy * c.y() * inv_z + camera.cy;
    Eigen::Vector3f value;
    const bool sampled =
        on_surface ? entry.Sample(Eigen::Vector2d(u, v), &value)
                   : entry.SampleSurfaceAt(u, v, c.z(), tolerance_offset + tolerance_slope * c.z(),
                                           true, &value);
    if (!sampled) continue;
    color[p] = value;
    valid[p] = 1;
    ++written;
  }
  return written;
}

void ClearTriangle(const AtlasMap& map, int f, TexelBuffer* texels) {
  for (int p = map.first(f); p < map.last(f); ++p) {
    texels->color[p].setZero();
    texels->valid[p] = 0;
  }
}

cv::Mat ComposeAtlas(const AtlasMap& map, const TexelBuffer& base,
                     const Eigen::MatrixX3f* corner_corrections, int padding) {
  const int size = map.size();
  cv::Mat out(size, size, CV_32FC3, cv::Scalar(0, 0, 0));
  cv::Mat mask(size, size, CV_8UC1, cv::Scalar(0));
  const bool correct = corner_corrections != nullptr && corner_corrections->rows() > 0;
  auto* color = reinterpret_cast<cv::Vec3f*>(out.data);
  tbb::parallel_for(tbb::blocked_range<int>(0, map.num_triangles(), 256),
                    [&](const tbb::blocked_range<int>& range) {
                      for (int f = range.begin(); f < range.end(); ++f) {
                        for (int p = map.first(f); p < map.last(f); ++p) {
                          const int t = *(map.texels_begin(f) + (p - map.first(f)));
                          Eigen::Vector3f c = base.color[p];
                          if (base.valid[p]) {
                            mask.data[t] = 255;
                            if (correct) {
                              const Eigen::Vector3f& w = map.barycentric_at(p);
                              c += w.x() * corner_corrections->row(3 * f).transpose() +
                                   w.y() * corner_corrections->row(3 * f + 1).transpose() +
                                   w.z() * corner_corrections->row(3 * f + 2).transpose();
                            }
                          }
                          color[t] = cv::Vec3f(c.x(), c.y(), c.z());
                        }
                      }
                    });
  // Padding: each pass fills empty texels with the mean of their filled 8-neighbours.
  for (int pass = 0; pass < padding; ++pass) {
    cv::Mat next = out.clone();
    cv::Mat next_mask = mask.clone();
    tbb::parallel_for(0, size, [&](int y) {
      for (int x = 0; x < size; ++x) {
        if (mask.at<uint8_t>(y, x)) continue;
        cv::Vec3f sum(0, 0, 0);
        int n = 0;
        for (int dy = -1; dy <= 1; ++dy) {
          for (int dx = -1; dx <= 1; ++dx) {
            const int yy = y + dy, xx = x + dx;
            if (yy < 0 || xx < 0 || yy >= size || xx >= size || !mask.at<uint8_t>(yy, xx)) continue;
            sum += out.at<cv::Vec3f>(yy, xx);
            ++n;
          }
        }
        if (n > 0) {
          next.at<cv::Vec3f>(y, x) = sum / static_cast<float>(n);
          next_mask.at<uint8_t>(y, x) = 255;
        }
      }
    });
    out = next;
    mask = next_mask;
  }
  cv::Mat out8;
  out.convertTo(out8, CV_8UC3, 255.0);
  return out8;
}

cv::Mat UnlevelledPatch(const AtlasMap& map, const TexelBuffer& base, const cv::Rect& rect) {
  cv::Mat patch(rect.height, rect.width, CV_8UC3, cv::Scalar(0, 0, 0));
  for (int y = 0; y < rect.height; ++y) {
    auto* row = patch.ptr<cv::Vec3b>(y);
    for (int x = 0; x < rect.width; ++x) {
      const int p = map.position((rect.y + y) * map.size() + rect.x + x);
      if (p < 0) continue;
      const Eigen::Vector3f& c = base.color[p];
      row[x] = cv::Vec3b(cv::saturate_cast<uchar>(255.0f * c.x()),
                         cv::saturate_cast<uchar>(255.0f * c.y()),
                         cv::saturate_cast<uchar>(255.0f * c.z()));
    }
  }
  return patch;
}

}  // namespace artex
