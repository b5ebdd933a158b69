// The texture atlas: which triangle (and where in it) every texel belongs to, sampling of a
// triangle's texels from its source image through that frame's posed mesh and camera
// (bilinear), additive seam-levelling corrections, and padding at chart borders so that
// mip-mapping does not bleed background into the charts.
//
// Texel colours are stored triangle by triangle (each triangle's texels contiguous, in the order
// of AtlasMap::texels_begin(f)), so that resampling a triangle reads and writes contiguous
// memory; ComposeAtlas scatters them into the 2D image.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <opencv2/core.hpp>
#include <vector>

#include "models/template.h"
#include "texture/image_pool.h"

namespace artex {

// Texel centres (x + 0.5, y + 0.5) / size in UV space covered by each triangle's UV triangle.
// A texel on a boundary shared by several UV triangles belongs to the lowest-index one.
class AtlasMap {
 public:
  // Throws artex::Error when the template has no UVs or size < 16.
  AtlasMap(const Template& tmpl, int size);
  int size() const { return size_; }
  // Triangle owning texel y * size + x, -1 for none.
  int32_t triangle(int texel) const { return texel_triangle_[texel]; }
  // Position of a covered texel in the triangle-major order (index into texels and TexelBuffer),
  // -1 for an uncovered texel.
  int position(int texel) const { return texel_position_[texel]; }
  // Barycentrics of the texel centre in its triangle (corners 0, 1, 2); the texel must be covered.
  Eigen::Vector3f barycentric(int texel) const { return barycentric_at(texel_position_[texel]); }
  // Texels of triangle f (texel indices y * size + x) and their positions first(f) .. last(f).
  const int* texels_begin(int f) const { return &texels_[offsets_[f]]; }
  const int* texels_end(int f) const { return &texels_[offsets_[f + 1]]; }
  int first(int f) const { return offsets_[f]; }
  int last(int f) const { return offsets_[f + 1]; }
  // Barycentrics by position (triangle-major order).
  Eigen::Vector3f barycentric_at(int position) const {
    return {bary_[0][position], bary_[1][position], bary_[2][position]};
  }
  // Barycentric coordinate c (corner 0, 1 or 2) of every covered texel, by position.
  const float* barycentrics(int c) const { return bary_[c].data(); }
  int num_covered() const { return static_cast<int>(texels_.size()); }
  int num_triangles() const { return static_cast<int>(offsets_.size()) - 1; }
  double Coverage() const;  // fraction of texels covered by a triangle

 private:
  int size_;
  std::vector<int32_t> texel_triangle_;  // size^2
  std::vector<int32_t> texel_position_;  // size^2
  std::vector<int> offsets_;             // F + 1
  std::vector<int> texels_;              // covered texels, triangle-major
  std::vector<float> bary_[3];           // per corner, per position
};

// Texel colours (channel order of the pool images, [0, 1]) in the AtlasMap's triangle-major
// order, with a flag per texel.
struct TexelBuffer {
  std::vector<Eigen::Vector3f> color;  // num_covered(); 0 where never sampled or cleared
  std::vector<uint8_t> valid;          // num_covered(); 1 where a triangle's texel was sampled
  explicit TexelBuffer(const AtlasMap& map)
      : color(map.num_covered(), Eigen::Vector3f::Zero()), valid(map.num_covered(), 0) {}
  TexelBuffer() = default;
};

// Samples every texel of triangle f from pool entry `entry` (bilinear, through the entry's
// posed vertices and camera; surface-aware, PoolEntry::SampleSurface at the triangle's quality
// in that image; colours agree with it within float rounding, < 1e-5). Texels whose point
// falls outside the crop keep their old value.
// Returns the number of texels written. Different triangles may be sampled concurrently.
int SampleTriangle(const AtlasMap& map, int f, const Eigen::MatrixX3i& triangles,
                   const PoolEntry& entry, TexelBuffer* texels);
// Clears the texels of triangle f (untextured).
void ClearTriangle(const AtlasMap& map, int f, TexelBuffer* texels);

// The working images of ComposeAtlas (the colours in floats and the filled mask: 13 bytes a
// texel), kept by a caller that composes again and again, so that a composition writes into
// memory touched before instead of fresh pages (which the kernel must fault in and zero).
struct AtlasScratch {
  cv::Mat color, mask;
};

// base + barycentric interpolation of per-corner corrections (rows 3 f + c), then `padding`
// passes of dilation into empty texels. Returns an 8-bit image (CV_8UC3, size x size). With
// `scratch`, its images are the working images (allocated on the first call, reused after); the
// result is the same.
cv::Mat ComposeAtlas(const AtlasMap& map, const TexelBuffer& base,
                     const Eigen::MatrixX3f* corner_corrections, int padding,
                     AtlasScratch* scratch = nullptr);

// The unlevelled colours of the texels in `rect` (uncovered and cleared texels black) as an
// 8-bit image (CV_8UC3, rect size); rect must lie inside the atlas.
cv::Mat UnlevelledPatch(const AtlasMap& map, const TexelBuffer& base, const cv::Rect& rect);

}  // namespace artex
