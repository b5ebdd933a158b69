#include "texture/texel_sampling.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "models/error.h"

namespace artex {

AtlasMap::AtlasMap(const Template& tmpl, int size) : size_(size) {
  if (!tmpl.has_uvs()) throw Error("texture atlas: the template has no UV atlas (uv_triangles)");
  if (size < 16) {
    std::ostringstream msg;
    msg << "texture.atlas_size: expected >= 16, found " << size;
    throw Error(msg.str());
  }
  const int f_count = tmpl.num_triangles();
  texel_triangle_.assign(static_cast<std::size_t>(size) * size, -1);
  texel_bary_.assign(static_cast<std::size_t>(size) * size, Eigen::Vector3f::Zero());
  std::vector<std::vector<int>> per_triangle(f_count);
  for (int f = 0; f < f_count; ++f) {
    Eigen::Vector2d p[3];
    for (int c = 0; c < 3; ++c) p[c] = tmpl.uvs.row(tmpl.uv_triangles(f, c)).transpose() * size;
    const double area = (p[1] - p[0]).x() * (p[2] - p[0]).y() - (p[1] - p[0]).y() * (p[2] - p[0]).x();
    if (std::abs(area) < 1e-12) continue;
    const int x0 = std::max(0, static_cast<int>(std::floor(std::min({p[0].x(), p[1].x(), p[2].x()}))));
    const int x1 = std::min(size - 1, static_cast<int>(std::ceil(std::max({p[0].x(), p[1].x(), p[2].x()}))));
    const int y0 = std::max(0, static_cast<int>(std::floor(std::min({p[0].y(), p[1].y(), p[2].y()}))));
    const int y1 = std::min(size - 1, static_cast<int>(std::ceil(std::max({p[0].y(), p[1].y(), p[2].y()}))));
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        const Eigen::Vector2d q(x + 0.5, y + 0.5);
        const double b1 = ((q - p[0]).x() * (p[2] - p[0]).y() - (q - p[0]).y() * (p[2] - p[0]).x()) / area;
        const double b2 = ((p[1] - p[0]).x() * (q - p[0]).y() - (p[1] - p[0]).y() * (q - p[0]).x()) / area;
        const double b0 = 1.0 - b1 - b2;
        if (b0 < 0 || b1 < 0 || b2 < 0) continue;
        const int texel = y * size + x;
        if (texel_triangle_[texel] >= 0) continue;  // shared boundary: first triangle wins
        texel_triangle_[texel] = f;
        texel_bary_[texel] = Eigen::Vector3f(b0, b1, b2);
        per_triangle[f].push_back(texel);
      }
    }
  }
  offsets_.assign(f_count + 1, 0);
  for (int f = 0; f < f_count; ++f) offsets_[f + 1] = offsets_[f] + static_cast<int>(per_triangle[f].size());
  texels_.reserve(offsets_[f_count]);
  for (auto& list : per_triangle) texels_.insert(texels_.end(), list.begin(), list.end());
}

double AtlasMap::Coverage() const {
  return static_cast<double>(texels_.size()) / (static_cast<double>(size_) * size_);
}

int SampleTriangle(const AtlasMap& map, int f, const Eigen::MatrixX3i& triangles,
                   const PoolEntry& entry, AtlasImage* atlas) {
  const Eigen::Vector3d a = entry.vertices.row(triangles(f, 0));
  const Eigen::Vector3d b = entry.vertices.row(triangles(f, 1));
  const Eigen::Vector3d c = entry.vertices.row(triangles(f, 2));
  auto* color = reinterpret_cast<cv::Vec3f*>(atlas->color.data);
  uint8_t* mask = atlas->mask.data;
  int written = 0;
  for (const int* t = map.texels_begin(f); t != map.texels_end(f); ++t) {
    const Eigen::Vector3f& w = map.barycentric(*t);
    const Eigen::Vector3d point = w.x() * a + w.y() * b + w.z() * c;
    Eigen::Vector3f value;
    if (!entry.Sample(entry.camera.Project(point), &value)) continue;
    color[*t] = cv::Vec3f(value.x(), value.y(), value.z());
    mask[*t] = 255;
    ++written;
  }
  return written;
}

void ClearTriangle(const AtlasMap& map, int f, AtlasImage* atlas) {
  auto* color = reinterpret_cast<cv::Vec3f*>(atlas->color.data);
  for (const int* t = map.texels_begin(f); t != map.texels_end(f); ++t) {
    color[*t] = cv::Vec3f(0, 0, 0);
    atlas->mask.data[*t] = 0;
  }
}

cv::Mat ComposeAtlas(const AtlasMap& map, const AtlasImage& base,
                     const Eigen::MatrixX3f* corner_corrections, int padding) {
  const int size = map.size();
  cv::Mat out = base.color.clone();
  cv::Mat mask = base.mask.clone();
  if (corner_corrections != nullptr && corner_corrections->rows() > 0) {
    auto* color = reinterpret_cast<cv::Vec3f*>(out.data);
    for (int t = 0; t < size * size; ++t) {
      const int f = map.triangle(t);
      if (f < 0 || !mask.data[t]) continue;
      const Eigen::Vector3f& w = map.barycentric(t);
      const Eigen::Vector3f g = w.x() * corner_corrections->row(3 * f).transpose() +
                                w.y() * corner_corrections->row(3 * f + 1).transpose() +
                                w.z() * corner_corrections->row(3 * f + 2).transpose();
      color[t] += cv::Vec3f(g.x(), g.y(), g.z());
    }
  }
  // Padding: each pass fills empty texels with the mean of their filled 8-neighbours.
  for (int pass = 0; pass < padding; ++pass) {
    cv::Mat next = out.clone();
    cv::Mat next_mask = mask.clone();
    for (int y = 0; y < size; ++y) {
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
    }
    out = next;
    mask = next_mask;
  }
  cv::Mat out8;
  out.convertTo(out8, CV_8UC3, 255.0);
  return out8;
}

}  // namespace artex
