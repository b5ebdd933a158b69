// The texture atlas: which triangle (and where in it) every texel belongs to, sampling of a
// triangle's texels from its source image through that frame's posed mesh and camera
// (bilinear), additive seam-levelling corrections, and padding at chart borders so that
// mip-mapping does not bleed background into the charts.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "models/template.h"
#include "texture/image_pool.h"

namespace artex {

// Texel centres (x + 0.5, y + 0.5) / size in UV space covered by each triangle's UV triangle.
class AtlasMap {
 public:
  // Throws artex::Error when the template has no UVs or size < 16.
  AtlasMap(const Template& tmpl, int size);
  int size() const { return size_; }
  int32_t triangle(int texel) const { return texel_triangle_[texel]; }
  const Eigen::Vector3f& barycentric(int texel) const { return texel_bary_[texel]; }
  // Texels of triangle f.
  const int* texels_begin(int f) const { return &texels_[offsets_[f]]; }
  const int* texels_end(int f) const { return &texels_[offsets_[f + 1]]; }
  double Coverage() const;  // fraction of texels covered by a triangle

 private:
  int size_;
  std::vector<int32_t> texel_triangle_;
  std::vector<Eigen::Vector3f> texel_bary_;
  std::vector<int> offsets_;
  std::vector<int> texels_;
};

// Float atlas (channel order of the pool images, [0, 1]) with a coverage mask.
struct AtlasImage {
  cv::Mat color;  // CV_32FC3, size x size
  cv::Mat mask;   // CV_8UC1, 255 where a triangle's texel has been sampled
};

// Samples every texel of triangle f from pool entry `entry` (bilinear, through the entry's
// posed vertices and camera). Texels whose point falls outside the crop keep their old value.
// Returns the number of texels written.
int SampleTriangle(const AtlasMap& map, int f, const Eigen::MatrixX3i& triangles,
                   const PoolEntry& entry, AtlasImage* atlas);
// Clears the texels of triangle f (untextured).
void ClearTriangle(const AtlasMap& map, int f, AtlasImage* atlas);

// base + barycentric interpolation of per-corner corrections (rows 3 f + c), then `padding`
// passes of dilation into empty texels. Returns an 8-bit image (CV_8UC3).
cv::Mat ComposeAtlas(const AtlasMap& map, const AtlasImage& base,
                     const Eigen::MatrixX3f* corner_corrections, int padding);

}  // namespace artex
