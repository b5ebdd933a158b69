// The pool of earlier colour images used for texturing (paper sec. 4): each entry keeps its
// colour image cropped to the subject, the posed template mesh of its frame, its camera, and
// what texturing reads from it repeatedly (per-triangle visibility and quality, colours at the
// template vertices and along mesh edges), computed once when the image enters the pool.
// Pruning follows the paper's coarse-histogram rule; a hard cap bounds memory.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cstdint>
#include <limits>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "render/camera.h"
#include "texture/visibility.h"

namespace artex {

// Mesh connectivity used by texturing: the F triangles and the E interior edges, each shared by
// exactly two triangles (the MRF's neighbourhood).
struct TextureMesh {
  Eigen::MatrixX3i triangles;   // F x 3
  Eigen::MatrixX2i edges;       // E x 2 vertex indices
  Eigen::MatrixX2i edge_faces;  // E x 2 triangles on either side
  // Every triangle once, breadth first over shared edges from the lowest unvisited triangle:
  // neighbours come close together (view selection numbers its MRF nodes in this order, for
  // the memory locality of the solvers).
  std::vector<int> triangle_order;
  static TextureMesh Build(const Eigen::MatrixX3i& triangles);
};

struct ImagePoolOptions {
  int max_images = 12;       // pruning starts above this many images; >= 1
  int hard_max_images = 24;  // oldest images are dropped regardless above this; >= max_images
  int histogram_bins = 4;    // coarse histogram of W over the pool (pruning rule); 1..255
  int crop_margin = 8;       // pixels kept around the subject's projection; >= 0
  int edge_samples = 5;      // colour samples along each edge for the seam cost; >= 2
  // Sample colours only from pixels showing the sampled surface: a pixel of the bilinear
  // footprint counts when the visibility z-buffer there is within
  //   depth_tolerance + sqrt(2) (z / fx) tan(acos W)
  // of the sample's depth z (VisibilityOptions::depth_tolerance plus the depth change across
  // one pixel diagonal of a surface seen at quality W, W clamped at >= 0.05), and the bilinear
  // weights are renormalised over those.
  // Near silhouettes and occlusion borders plain bilinear sampling mixes in the background or
  // the occluder. Vertex and edge colours without any such pixel are unknown (NaN); texels
  // then fall back to plain bilinear. Keeps the z-buffer with each image (4 bytes per pixel of
  // the subject's bounding box at VisibilityOptions::raster_scale^2). false: plain bilinear
  // sampling everywhere.
  bool surface_aware_sampling = true;
  // A vertex's colour (the seam levelling's input and the fitting's rgb(v')) is measured in an
  // image only when every triangle around the vertex is visible there: at silhouettes and
  // occlusion borders the one sample mixes surfaces or is seen edge-on. false: when any
  // triangle around it is visible.
  bool vertex_colors_need_full_ring = true;

  bool IsValid(std::string* error) const;
};

// Colours, one row per point (3 channels contiguous).
using ColorRows = Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>;
// Edge colours, one row per sample (3 channels contiguous), in 16-bit fixed point: a channel c
// in [0, 1] is stored as round(c * kEdgeColorScale), and all three channels of a sample not seen
// as kEdgeColorUnseen. Half the memory of floats: with 24 images pooled the edge colours are
// most of the pool's memory (docs/realtime-later-rounds.md, "Edge colours in 16 bits").
using EdgeColorRows = Eigen::Matrix<std::uint16_t, Eigen::Dynamic, 3, Eigen::RowMajor>;
constexpr std::uint16_t kEdgeColorUnseen = 65535;
constexpr float kEdgeColorScale = 65534.0f;
// A colour channel seen as stored in EdgeColorRows: std::lround(clamp(c, 0, 1) *
// kEdgeColorScale) without the library call (a sample's three channels cost a call each). Halfway
// cases round up, as lround's away from zero; x - trunc(x) is exact below 2^23. NaN gives 0, as
// lround's result once cast.
inline std::uint16_t EdgeColorValue(float c) {
  const float x = std::clamp(c, 0.0f, 1.0f) * kEdgeColorScale;
  if (!(x >= 0.0f)) return 0;
  const int t = static_cast<int>(x);  // towards zero
  return static_cast<std::uint16_t>(t + (x - static_cast<float>(t) >= 0.5f));
}

// The colour of an edge sample (row of EdgeColorRows); NaN where not seen.
inline Eigen::Vector3f EdgeColor(const EdgeColorRows& colors, Eigen::Index row) {
  if (colors(row, 0) == kEdgeColorUnseen)
    return Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN());
  return colors.row(row).transpose().cast<float>() / kEdgeColorScale;
}

struct PoolEntry {
  int frame_index = 0;
  cv::Mat image;                 // CV_8UC3 (BGR), cropped
  Eigen::Vector2i offset{0, 0};  // crop origin in the full image (pixels)
  PinholeCamera camera;          // full-image colour camera
  SurfaceDepth surface;          // visibility z-buffer (empty without surface-aware sampling)
  double depth_tolerance = 0.0;  // VisibilityOptions::depth_tolerance used for `surface`
  Eigen::MatrixX3d vertices;     // V x 3 posed template of that frame (world, m)
  TriangleVisibility visibility;
  // V x 3 colours (channel order of `image`, [0, 1]) at the projected vertices; NaN where not
  // measured (ImagePoolOptions::vertex_colors_need_full_ring, surface_aware_sampling).
  ColorRows vertex_colors;
  // V: 1 where vertex_colors' row is finite (all three channels), else 0. Set by
  // ImagePool::Insert: a byte per vertex, which readers that ask only whether a vertex has a
  // colour scan without touching the colours.
  std::vector<uint8_t> vertex_coloured;
  // (E * edge_samples) x 3 colours along every edge (rows e * samples + k); kEdgeColorUnseen
  // where the edge is not seen (neither side visible) or the sample has no surface pixel.
  EdgeColorRows edge_colors;

  // Bilinear colour at a full-image pixel position; false outside the crop.
  inline bool Sample(const Eigen::Vector2d& pixel, Eigen::Vector3f* color) const;
  // Colour of the surface point at camera coordinates `point` (m) seen at quality W = quality:
  // surface-aware bilinear sampling (ImagePoolOptions::surface_aware_sampling) when the entry
  // keeps its z-buffer, else plain. Without a pixel on the surface: plain bilinear when
  // `fallback`, else false. false outside the crop.
  bool SampleSurface(const Eigen::Vector3d& point, double quality, bool fallback,
                     Eigen::Vector3f* color) const;
  // SampleSurface at full-image pixel (u, v) for a point at camera depth z, with the accepted
  // depth difference `tolerance` (m) already computed (SurfaceTolerance).
  inline bool SampleSurfaceAt(double u, double v, double z, double tolerance, bool fallback,
                              Eigen::Vector3f* color) const;
  // The accepted depth difference is tolerance_offset + tolerance_slope * z for a surface seen
  // at quality W (see ImagePoolOptions::surface_aware_sampling).
  void SurfaceTolerance(double quality, double* tolerance_offset, double* tolerance_slope) const;
  std::size_t MemoryBytes() const;

  // The crop's bilinear cell (taps x0..x1, y0..y1 and fractions) around the full-image position
  // (u, v); false outside the crop. Shared by both samplers.
  struct BilinearCell {
    int x0, y0, x1, y1;
    float fx, fy;
  };
  bool Cell(double u, double v, BilinearCell* cell) const;
  // The surface-aware blend of SampleSurfaceAt over `cell` for a point at camera depth z (m):
  // depth_at(x, y) is the z-buffer depth at crop pixel (x, y), asked only for taps of positive
  // weight. false when no such tap is within `tolerance` of z.
  template <class DepthAt>
  bool BlendSurface(const BilinearCell& cell, double z, double tolerance, const DepthAt& depth_at,
                    Eigen::Vector3f* color) const;
};

inline bool PoolEntry::Cell(double u, double v, BilinearCell* cell) const {
  const double x = u - offset.x();
  const double y = v - offset.y();
  if (!(x >= 0.0 && y >= 0.0 && x <= image.cols - 1 && y <= image.rows - 1)) return false;
  cell->x0 = std::min(static_cast<int>(x), image.cols - 2 < 0 ? 0 : image.cols - 2);
  cell->y0 = std::min(static_cast<int>(y), image.rows - 2 < 0 ? 0 : image.rows - 2);
  cell->x1 = std::min(cell->x0 + 1, image.cols - 1);
  cell->y1 = std::min(cell->y0 + 1, image.rows - 1);
  cell->fx = static_cast<float>(x - cell->x0);
  cell->fy = static_cast<float>(y - cell->y0);
  return true;
}

inline bool PoolEntry::Sample(const Eigen::Vector2d& pixel, Eigen::Vector3f* color) const {
  BilinearCell cell;
  if (!Cell(pixel.x(), pixel.y(), &cell)) return false;
  const int x0 = cell.x0, y0 = cell.y0, x1 = cell.x1, y1 = cell.y1;
  const float fx = cell.fx, fy = cell.fy;
  const auto* r0 = image.ptr<cv::Vec3b>(y0);
  const auto* r1 = image.ptr<cv::Vec3b>(y1);
  for (int c = 0; c < 3; ++c) {
    const float top = r0[x0][c] * (1 - fx) + r0[x1][c] * fx;
    const float bottom = r1[x0][c] * (1 - fx) + r1[x1][c] * fx;
    (*color)[c] = (top * (1 - fy) + bottom * fy) / 255.0f;
  }
  return true;
}

template <class DepthAt>
inline bool PoolEntry::BlendSurface(const BilinearCell& cell, double z, double tolerance,
                                    const DepthAt& depth_at, Eigen::Vector3f* color) const {
  const float fx = cell.fx, fy = cell.fy;
  float total = 0.0f;
  float sum[3] = {0.0f, 0.0f, 0.0f};
  const auto tap = [&](int x, int y, const cv::Vec3b* row, float weight) {
    if (weight <= 0.0f) return;
    const float d = depth_at(x, y);
    if (!(std::abs(d - z) <= tolerance)) return;
    const cv::Vec3b& c = row[x];
    for (int ch = 0; ch < 3; ++ch) sum[ch] += weight * c[ch];
    total += weight;
  };
  const cv::Vec3b* row0 = image.ptr<cv::Vec3b>(cell.y0);
  const cv::Vec3b* row1 = image.ptr<cv::Vec3b>(cell.y1);
  tap(cell.x0, cell.y0, row0, (1 - fx) * (1 - fy));
  tap(cell.x1, cell.y0, row0, fx * (1 - fy));
  tap(cell.x0, cell.y1, row1, (1 - fx) * fy);
  tap(cell.x1, cell.y1, row1, fx * fy);
  if (total <= 0.0f) return false;
  const float scale = 1.0f / (255.0f * total);
  *color = Eigen::Vector3f(sum[0] * scale, sum[1] * scale, sum[2] * scale);
  return true;
}

inline bool PoolEntry::SampleSurfaceAt(double u, double v, double z, double tolerance,
                                       bool fallback, Eigen::Vector3f* color) const {
  if (surface.depth.empty()) return Sample(Eigen::Vector2d(u, v), color);
  BilinearCell cell;
  if (!Cell(u, v, &cell)) return false;
  const auto depth_at = [this](int x, int y) { return surface.At(x + offset.x(), y + offset.y()); };
  if (BlendSurface(cell, z, tolerance, depth_at, color)) return true;
  return fallback && Sample(Eigen::Vector2d(u, v), color);
}

class ImagePool {
 public:
  ImagePool(const TextureMesh* mesh, const ImagePoolOptions& pool_options,
            const VisibilityOptions& visibility_options);

  // Adds the image of a frame with its posed template; returns the new entry's slot.
  // Insert(MakeEntry(...)).
  int Add(int frame_index, const cv::Mat& color_bgr, const PinholeCamera& camera,
          const Eigen::MatrixX3d& posed_vertices);
  // The entry Add would pool for this frame (visibility, crop, vertex and edge colours), not
  // pooled yet. Reads only the mesh and the options, never the pooled entries: it may run on
  // one thread while another inserts, prunes or reads entries (a pipeline stage ahead of the
  // texturing). Throws artex::Error for an image of the wrong size or type.
  std::unique_ptr<PoolEntry> MakeEntry(int frame_index, const cv::Mat& color_bgr,
                                       const PinholeCamera& camera,
                                       const Eigen::MatrixX3d& posed_vertices) const;
  // Pools an entry from MakeEntry (newest); returns its slot.
  int Insert(std::unique_ptr<PoolEntry> entry);
  // Applies the pruning rule; returns the frame indices of the dropped images.
  std::vector<int> Prune();

  int size() const { return static_cast<int>(entries_.size()); }
  const PoolEntry& entry(int slot) const { return *entries_[slot]; }
  int SlotOfFrame(int frame_index) const;  // -1 when not in the pool
  std::size_t MemoryBytes() const;

  // True when the entry at `slot` is, for some triangle, the only image in the best non-empty
  // bin of that triangle's histogram of W over the pool (the paper's reason to keep it).
  bool IsUniquelyBest(int slot) const;
  // IsUniquelyBest for every slot at once (one pass over triangles and slots).
  std::vector<uint8_t> UniquelyBestSlots() const;

 private:
  const TextureMesh* mesh_;
  ImagePoolOptions options_;
  VisibilityOptions visibility_options_;
  std::vector<std::unique_ptr<PoolEntry>> entries_;  // oldest first
  std::vector<int> slot_frames_;                     // entries_[s]->frame_index (SlotOfFrame)
  // Per slot, per triangle: 0 where not visible, else 1 + the histogram bin of W.
  std::vector<std::vector<uint8_t>> levels_;
};

}  // namespace artex
