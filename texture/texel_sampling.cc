#include "texture/texel_sampling.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>
#include <sstream>

#include "models/error.h"
#include "models/uv_raster.h"

namespace artex {
namespace {
// Triangles projecting onto more pixels than this skip the whole-triangle z-buffer check of
// SampleTriangle (the per-texel tests are then cheaper).
constexpr int kMaxSurfaceCheckPixels = 4096;

// Fast path of SampleTriangle. A triangle whose projection keeps kInsideMargin pixels from the
// border of the crop's interpolation range is sampled from its footprint (the crop pixels and
// z-buffer depths under it, read once) without per-texel bounds checks; the margin is far above
// the rounding of a texel's projection against its corners' (< 1e-12 px in double) and the
// float error bound below. Texels are projected in blocks of kTexelBlock (loops over arrays,
// which the compiler vectorises).
constexpr double kInsideMargin = 1e-3;
constexpr int kTexelBlock = 64;
// Texels whose colour is plain bilinear (all texels of a triangle without surface-aware tests)
// get their positions in float when the footprint has at most kFloatFootprintSide pixels a side
// and the corner depths differ by a factor of at most kFloatDepthRatio; otherwise, and for
// surface-aware sampling (whose depth tests must see exactly the entry's cells and depths), in
// double exactly as PoolEntry::SampleSurface. Float positions are evaluated relative to the
// footprint's centre, |x| <= 4 px: with u = 2^-24 and depth ratio r <= 1.1, the numerator (a
// 3-term dot product of rounded coefficients) and denominator errors contribute <= 16 r u each,
// the reciprocal and product 8 u, the shift back by the centre 8 u: <= 52 u ~ 3.1e-6 px per
// axis. A bilinear colour in [0, 1] changes by at most 1 per pixel along each axis, so colours
// differ from the double-precision ones by < 7e-6.
constexpr int kFloatFootprintSide = 8;
constexpr double kFloatDepthRatio = 1.1;
// Relative widening of a triangle's corner depth range that contains the depth of each of its
// texels: texel barycentrics are floats >= 0 whose sum is 1 within ~6e-8.
constexpr double kDepthRangeMargin = 1e-6;

// The projection of a triangle's texels: operations and their order are those of
// PoolEntry::SampleSurface, so every texel gets exactly its pixel position and depth there.
struct TriangleProjection {
  Eigen::Vector3d corner[3];  // camera coordinates (m)
  double fx, fy, cx, cy;      // intrinsics (pixels)

  // Full-image pixel (u, v) and camera depth z of the point with barycentrics w0, w1, w2.
  void Project(double w0, double w1, double w2, double* u, double* v, double* z) const {
    const double x = w0 * corner[0].x() + w1 * corner[1].x() + w2 * corner[2].x();
    const double y = w0 * corner[0].y() + w1 * corner[1].y() + w2 * corner[2].y();
    *z = w0 * corner[0].z() + w1 * corner[1].z() + w2 * corner[2].z();
    const double inv_z = 1.0 / *z;
    *u = fx * x * inv_z + cx;
    *v = fy * y * inv_z + cy;
  }
};

// SampleTriangle's whole-triangle z-buffer check: every depth depth_at(x, y) of the pixels
// x0..x1, y0..y1 is within `tolerance` of every depth in [z_min, z_max].
// Rows are tested whole (no early exit inside a row, which lets the compiler vectorise).
template <typename DepthAt>
bool AllNearSurface(int x0, int x1, int y0, int y1, const DepthAt& depth_at, double z_min,
                    double z_max, double tolerance) {
  for (int y = y0; y <= y1; ++y) {
    bool near = true;
    for (int x = x0; x <= x1; ++x) {
      const double d = depth_at(x, y);
      near &= (d - z_min <= tolerance) & (z_max - d <= tolerance);
    }
    if (!near) return false;
  }
  return true;
}

// The crop pixels around one triangle's projection: colours as floats (channels / 255, 3 per
// pixel, rows of `width` pixels) and, for surface-aware sampling, z-buffer depths
// (SurfaceDepth::At: +inf where there is no surface) and the outcomes of the depth test that
// are the same for every texel depth of the triangle.
struct Footprint {
  static constexpr int kMaxPixels = 1024;  // larger footprints take the general path
  int x0 = 0, y0 = 0;                      // crop pixel of element 0
  int width = 0, height = 0;
  // One float of padding: a pixel is read as 4 lanes (its 3 channels and one ignored value).
  float color[3 * kMaxPixels + 1];
  float depth[kMaxPixels];
  // Per pixel, the outcome of PoolEntry::SampleSurfaceAt's depth test when it is the same for
  // every texel depth of the triangle (kPasses, kFails), else 0.
  static constexpr uint8_t kPasses = 1, kFails = 2;
  uint8_t outcome[kMaxPixels];
  // Per cell, by the element of its tap (x0, y0): 1 when the depth test passes at all 4 taps
  // or fails at all 4 for every texel depth (then the surface-aware colour is the plain one).
  uint8_t uniform[kMaxPixels];

  void ReadColor(const cv::Mat& image) {
    constexpr float kInv255 = 1.0f / 255.0f;
    for (int y = 0; y < height; ++y) {
      const uint8_t* src = image.ptr<uint8_t>(y0 + y) + 3 * x0;
      float* dst = color + 3 * y * width;
      for (int i = 0; i < 3 * width; ++i) dst[i] = src[i] * kInv255;
    }
    color[3 * width * height] = 0.0f;
  }

  void ReadDepth(const SurfaceDepth& surface, const Eigen::Vector2i& offset) {
    const int sx = x0 + offset.x() - surface.x0, sy = y0 + offset.y() - surface.y0;
    if (surface.scale == 1.0 && sx >= 0 && sy >= 0 && sx + width <= surface.width &&
        sy + height <= surface.height) {
      for (int y = 0; y < height; ++y) {
        std::memcpy(depth + y * width,
                    surface.depth.data() + static_cast<std::size_t>(sy + y) * surface.width + sx,
                    width * sizeof(float));
      }
      return;
    }
    for (int y = 0; y < height; ++y) {
      for (int x = 0; x < width; ++x)
        depth[y * width + x] = surface.At(x0 + x + offset.x(), y0 + y + offset.y());
    }
  }
  float DepthAt(int x, int y) const { return depth[y * width + x]; }

  // Fills `outcome` and `uniform` for texel depths z in [z_lo, z_hi] (z_lo > 0) and the tolerance
  // tolerance_offset + tolerance_slope * z of PoolEntry::SampleSurfaceAt. A tap's outcome is
  // decided at the ends of the range: rounding is monotone, so a test that passes (fails) there
  // with the smallest (largest) tolerance does so for every z in between, exactly as evaluated
  // per texel.
  // Returns whether every cell is uniform.
  bool FindUniformCells(double z_lo, double z_hi, double tolerance_offset, double tolerance_slope) {
    const double tolerance_lo = tolerance_offset + tolerance_slope * z_lo;
    const double tolerance_hi = tolerance_offset + tolerance_slope * z_hi;
    const double tolerance_min = std::min(tolerance_lo, tolerance_hi);
    const double tolerance_max = std::max(tolerance_lo, tolerance_hi);
    for (int i = 0; i < width * height; ++i) {
      const double d = depth[i];
      const bool passes = (d - z_lo <= tolerance_min) & (z_hi - d <= tolerance_min);
      const bool fails = (d - z_hi > tolerance_max) | (z_lo - d > tolerance_max);
      outcome[i] = passes * kPasses + fails * kFails;
    }
    bool all_uniform = true;
    for (int y = 0; y + 1 < height; ++y) {
      for (int x = 0; x + 1 < width; ++x) {
        const int i = y * width + x;
        uniform[i] =
            (outcome[i] & outcome[i + 1] & outcome[i + width] & outcome[i + width + 1]) != 0;
        all_uniform &= uniform[i];
      }
    }
    return all_uniform;
  }
};

// The projection of a triangle's texels in float, as footprint coordinates (pixels from
// footprint pixel (0, 0)): the projective map (w . hx, w . hy) / (w . z) of homogeneous corner
// coordinates, relative to the footprint's centre and scaled by the first corner's depth
// (values ~1; see kFloatFootprintSide).
struct FloatFootprintMap {
  float hx[3], hy[3], z[3];
  float centre_x, centre_y;

  FloatFootprintMap(const TriangleProjection& projection, const Footprint& footprint,
                    const Eigen::Vector2i& offset)
      : centre_x(static_cast<float>(footprint.width / 2)),
        centre_y(static_cast<float>(footprint.height / 2)) {
    const double cx = projection.cx - offset.x() - footprint.x0 - centre_x;
    const double cy = projection.cy - offset.y() - footprint.y0 - centre_y;
    const double scale = 1.0 / projection.corner[0].z();
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d& c = projection.corner[k];
      hx[k] = static_cast<float>((projection.fx * c.x() + cx * c.z()) * scale);
      hy[k] = static_cast<float>((projection.fy * c.y() + cy * c.z()) * scale);
      z[k] = static_cast<float>(c.z() * scale);
    }
  }
};

// The bilinear cells of up to kTexelBlock texels in a Footprint: PoolEntry::Cell for positions
// whose cells lie inside the crop (so no clamping).
struct FootprintCells {
  int index[kTexelBlock];  // footprint element of tap (x0, y0); (x0 + 1, y0) is index + 1...
  float fx[kTexelBlock];   // fractions, as PoolEntry::Cell
  float fy[kTexelBlock];
  double depth[kTexelBlock];  // camera depth (m) of the texel's point (double projection only)

  // Texels at positions first .. first + n - 1 (n <= kTexelBlock) of `map`, exactly as
  // PoolEntry::SampleSurface and PoolEntry::Cell (offset: the crop origin).
  void Project(const TriangleProjection& projection, const Eigen::Vector2i& offset,
               const Footprint& footprint, const AtlasMap& map, int first, int n);
  // The same in float (no depths).
  void Project(const FloatFootprintMap& m, int width, const AtlasMap& map, int first, int n);
};

void FootprintCells::Project(const TriangleProjection& projection, const Eigen::Vector2i& offset,
                             const Footprint& footprint, const AtlasMap& map, int first, int n) {
  const float* b0 = map.barycentrics(0) + first;
  const float* b1 = map.barycentrics(1) + first;
  const float* b2 = map.barycentrics(2) + first;
  const double ox = offset.x(), oy = offset.y();
  // Crop pixel (x0, y0) is footprint element (y0 - footprint.y0) * width + x0 - footprint.x0.
  const double origin = static_cast<double>(footprint.y0) * footprint.width + footprint.x0;
  for (int i = 0; i < n; ++i) {
    double u, v;
    projection.Project(b0[i], b1[i], b2[i], &u, &v, &depth[i]);
    const double x = u - ox, y = v - oy;  // crop pixels
    // Cell corner (x0, y0) = (int) (x, y), held in double (exact small integers).
    const double x0 = static_cast<int>(x), y0 = static_cast<int>(y);
    fx[i] = static_cast<float>(x - x0);
    fy[i] = static_cast<float>(y - y0);
    index[i] = static_cast<int>(y0 * footprint.width + x0 - origin);
  }
}

void FootprintCells::Project(const FloatFootprintMap& m, int width, const AtlasMap& map, int first,
                             int n) {
  const float* b0 = map.barycentrics(0) + first;
  const float* b1 = map.barycentrics(1) + first;
  const float* b2 = map.barycentrics(2) + first;
  for (int i = 0; i < n; ++i) {
    const float w0 = b0[i], w1 = b1[i], w2 = b2[i];
    const float inv_z = 1.0f / (w0 * m.z[0] + w1 * m.z[1] + w2 * m.z[2]);
    const float x = (w0 * m.hx[0] + w1 * m.hx[1] + w2 * m.hx[2]) * inv_z + m.centre_x;
    const float y = (w0 * m.hy[0] + w1 * m.hy[1] + w2 * m.hy[2]) * inv_z + m.centre_y;
    const float x0 = static_cast<int>(x), y0 = static_cast<int>(y);  // exact small integers
    fx[i] = x - x0;
    fy[i] = y - y0;
    index[i] = static_cast<int>(y0 * width + x0);
  }
}

// Stores a texel's colour: 4 lanes at once when `spill` (the 4th lands on the next texel's
// first channel, which is written afterwards), else 3 floats.
inline void PutTexel(const float rgbx[4], bool spill, float* out) {
  if (spill)
    std::memcpy(out, rgbx, 4 * sizeof(float));
  else
    std::memcpy(out, rgbx, 3 * sizeof(float));
}

// Bilinear colour at a cell (footprint element `index` of tap (x0, y0), fractions fx, fy), as
// lerps along x then y: PoolEntry::Sample's arithmetic up to the order of operations (results
// agree to float rounding, ~1e-7). Colours are computed as 4 lanes (3 channels and a
// meaningless 4th), which is 4-lane arithmetic, and stored by PutTexel.
inline void SampleFootprint(const Footprint& footprint, int index, float fx, float fy, bool spill,
                            float* out) {
  const float* t00 = footprint.color + 3 * index;
  const float* t10 = t00 + 3;
  const float* t01 = t00 + 3 * footprint.width;
  const float* t11 = t01 + 3;
  float rgbx[4];
  for (int c = 0; c < 4; ++c) {
    const float top = t00[c] + fx * (t10[c] - t00[c]);
    const float bottom = t01[c] + fx * (t11[c] - t01[c]);
    rgbx[c] = top + fy * (bottom - top);
  }
  PutTexel(rgbx, spill, out);
}

// PoolEntry::SampleSurfaceAt with fallback at cell k (double projection): the taps that pass
// the depth test (the footprint's outcome where it is decided for every texel depth, else the
// same double-precision test as there), bilinear weights renormalised over them; plain bilinear
// when there are none. A failed tap adds 0 to the sums rather than being skipped (the same
// sums), and a tap of zero weight needs no test. In a uniform cell the test passes at every tap
// (the renormalised weights are the bilinear ones: their sum is 1 within float rounding) or at
// none, so the colour is plain bilinear.
inline void SampleSurfaceFootprint(const Footprint& footprint, const FootprintCells& cells, int k,
                                   double tolerance_offset, double tolerance_slope, bool spill,
                                   float* out) {
  const int i = cells.index[k], w = footprint.width;
  const float fx = cells.fx[k], fy = cells.fy[k];
  if (footprint.uniform[i]) {
    SampleFootprint(footprint, i, fx, fy, spill, out);
    return;
  }
  const float weights[4] = {(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy};
  const int taps[4] = {i, i + 1, i + w, i + w + 1};
  uint8_t outcome[4];
  for (int t = 0; t < 4; ++t) outcome[t] = footprint.outcome[taps[t]];
  float on_weights[4];
  if (outcome[0] && outcome[1] && outcome[2] && outcome[3]) {  // decided at every tap
    for (int t = 0; t < 4; ++t)
      on_weights[t] = outcome[t] == Footprint::kPasses ? weights[t] : 0.0f;
  } else {
    const double z = cells.depth[k];
    const double tolerance = tolerance_offset + tolerance_slope * z;
    for (int t = 0; t < 4; ++t)
      on_weights[t] = std::abs(footprint.depth[taps[t]] - z) <= tolerance ? weights[t] : 0.0f;
  }
  const float total = on_weights[0] + on_weights[1] + on_weights[2] + on_weights[3];
  if (total <= 0.0f) {
    SampleFootprint(footprint, i, fx, fy, spill, out);
    return;
  }
  const float scale = 1.0f / total;
  const float* t00 = footprint.color + 3 * i;
  const float* t01 = t00 + 3 * w;
  float rgbx[4];
  for (int c = 0; c < 4; ++c) {
    rgbx[c] = (on_weights[0] * t00[c] + on_weights[1] * t00[3 + c] + on_weights[2] * t01[c] +
               on_weights[3] * t01[3 + c]) *
              scale;
  }
  PutTexel(rgbx, spill, out);
}

// The first front's texels in rows [y0, y1) (in raster order): the empty texels with a filled
// texel among their 8 neighbours; mask 0 or 255, row_filled: whether a row holds a filled
// texel. The pointers and size are parameters, not captures: the byte stores below could alias
// anything reached through memory, which would then be reloaded at every texel.
void FirstFrontOfRows(const uint8_t* mask, int size, const std::vector<uint8_t>& row_filled,
                      int y0, int y1, std::vector<int>* out) {
  // A row's texels with a filled texel in the column of the three rows around them, then
  // those with one in the 3 x 3 neighbourhood (column padded by a zero on each side).
  std::vector<uint8_t> column_buffer(size + 2, 0), near_buffer(size + 8, 0);
  uint8_t* __restrict column = column_buffer.data();
  uint8_t* __restrict near = near_buffer.data();
  for (int y = y0; y < y1; ++y) {
    if (!row_filled[y] && !(y > 0 && row_filled[y - 1]) && !(y + 1 < size && row_filled[y + 1]))
      continue;
    const uint8_t* row = mask + static_cast<std::size_t>(y) * size;
    const uint8_t* above = y > 0 ? row - size : row;
    const uint8_t* below = y + 1 < size ? row + size : row;
    for (int x = 0; x < size; ++x) column[x + 1] = above[x] | row[x] | below[x];
    for (int x = 0; x < size; ++x)
      near[x] = (column[x] | column[x + 1] | column[x + 2]) & static_cast<uint8_t>(~row[x]);
    // Eight texels at a time (near_buffer's zero tail completes the last word).
    for (int x = 0; x < size; x += 8) {
      uint64_t word;
      std::memcpy(&word, near + x, sizeof(word));
      if (word == 0) continue;
      for (int k = x; k < std::min(size, x + 8); ++k) {
        if (near[k]) out->push_back(y * size + k);
      }
    }
  }
}

// Padding: each pass fills the empty texels next to filled ones with the mean of their filled
// 8-neighbours (summed in the order dy, dx = -1 .. 1). Only the front is visited: the empty
// texels next to the ones the last pass filled (the first pass: next to any filled texel), so a
// pass costs the charts' perimeter, not the atlas. mask: 0 empty or 255 filled on entry (1 marks
// the next front meanwhile).
void PadAtlas(int padding, cv::Mat* out, cv::Mat* mask_image) {
  if (padding <= 0) return;
  const int size = out->rows;
  uint8_t* mask = mask_image->data;
  auto* color = reinterpret_cast<cv::Vec3f*>(out->data);
  // The first front: the empty texels next to a filled one, in raster order. Rows are scanned
  // in parallel bands (each band's texels in order, the bands concatenated in order), and a row
  // none of whose three rows around it holds a filled texel is skipped (most of the atlas).
  std::vector<uint8_t> row_filled(size, 0);
  tbb::parallel_for(tbb::blocked_range<int>(0, size, 64), [&](const tbb::blocked_range<int>& r) {
    for (int y = r.begin(); y < r.end(); ++y) {
      const uint8_t* row = mask + static_cast<std::size_t>(y) * size;
      row_filled[y] = std::find(row, row + size, uint8_t{255}) != row + size;
    }
  });
  constexpr int kBandRows = 64;
  const int bands = (size + kBandRows - 1) / kBandRows;
  std::vector<std::vector<int>> band_front(bands);
  tbb::parallel_for(0, bands, [&](int b) {
    FirstFrontOfRows(mask, size, row_filled, b * kBandRows, std::min(size, (b + 1) * kBandRows),
                     &band_front[b]);
  });
  std::vector<int> front;
  for (const std::vector<int>& band : band_front)
    front.insert(front.end(), band.begin(), band.end());
  std::vector<cv::Vec3f> values;
  std::vector<int> next;
  for (int pass = 0; pass < padding && !front.empty(); ++pass) {
    values.resize(front.size());
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, front.size(), 1024),
        [&](const tbb::blocked_range<std::size_t>& range) {
          for (std::size_t i = range.begin(); i < range.end(); ++i) {
            const int y = front[i] / size, x = front[i] % size;
            cv::Vec3f sum(0, 0, 0);
            int n = 0;
            for (int dy = -1; dy <= 1; ++dy) {
              for (int dx = -1; dx <= 1; ++dx) {
                const int yy = y + dy, xx = x + dx;
                if (yy < 0 || xx < 0 || yy >= size || xx >= size || mask[yy * size + xx] != 255)
                  continue;
                sum += color[yy * size + xx];
                ++n;
              }
            }
            values[i] = sum / static_cast<float>(n);  // n >= 1 on the front
          }
        });
    for (std::size_t i = 0; i < front.size(); ++i) {
      color[front[i]] = values[i];
      mask[front[i]] = 255;
    }
    if (pass + 1 == padding) break;
    next.clear();
    for (const int t : front) {
      const int y = t / size, x = t % size;
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const int yy = y + dy, xx = x + dx;
          if (yy < 0 || xx < 0 || yy >= size || xx >= size || mask[yy * size + xx]) continue;
          mask[yy * size + xx] = 1;
          next.push_back(yy * size + xx);
        }
      }
    }
    front.swap(next);
  }
}

// ComposeAtlas's texels of triangles [begin, end): base plus the corrections interpolated
// (when given) into `color`, 255 into `mask` where valid. The pointers are locals: the byte
// stores into the mask could alias anything reached through memory.
void ScatterTexels(const AtlasMap& map, const TexelBuffer& base,
                   const Eigen::MatrixX3f* corner_corrections, int begin, int end,
                   cv::Vec3f* color, uint8_t* mask) {
  if (begin >= end || map.num_covered() == 0) return;
  const int* texels = map.texels_begin(0);  // triangle-major: position p's texel is texels[p]
  const Eigen::Vector3f* base_color = base.color.data();
  const uint8_t* valid = base.valid.data();
  const float* b0 = map.barycentrics(0);
  const float* b1 = map.barycentrics(1);
  const float* b2 = map.barycentrics(2);
  for (int f = begin; f < end; ++f) {
    Eigen::Vector3f c0 = Eigen::Vector3f::Zero(), c1 = c0, c2 = c0;
    if (corner_corrections) {
      c0 = corner_corrections->row(3 * f).transpose();
      c1 = corner_corrections->row(3 * f + 1).transpose();
      c2 = corner_corrections->row(3 * f + 2).transpose();
    }
    for (int p = map.first(f), last = map.last(f); p < last; ++p) {
      const int t = texels[p];
      Eigen::Vector3f c = base_color[p];
      if (valid[p]) {
        mask[t] = 255;
        if (corner_corrections) c += b0[p] * c0 + b1[p] * c1 + b2[p] * c2;
      }
      color[t] = cv::Vec3f(c.x(), c.y(), c.z());
    }
  }
}

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
    const UvTriangleCells t = UvTriangleOnGrid(tmpl, f, size);
    const Eigen::Vector2d* p = t.p;
    const double area = t.area2;
    if (std::abs(area) < 1e-12) continue;
    // Inside by the barycentrics it records (not CellCentreInside: they can differ at edges).
    for (int y = t.y0; y <= t.y1; ++y) {
      for (int x = t.x0; x <= t.x1; ++x) {
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
  for (std::vector<float>& b : bary_) b.resize(offsets_[f_count]);
  texel_position_.assign(total, -1);
  std::vector<int> fill(offsets_.begin(), offsets_.end() - 1);
  for (std::size_t t = 0; t < total; ++t) {
    const int f = texel_triangle_[t];
    if (f < 0) continue;
    const int position = fill[f]++;
    texels_[position] = static_cast<int>(t);
    for (int c = 0; c < 3; ++c) bary_[c][position] = texel_bary[t][c];
    texel_position_[t] = position;
  }
}

double AtlasMap::Coverage() const {
  return static_cast<double>(texels_.size()) / (static_cast<double>(size_) * size_);
}

int SampleTriangle(const AtlasMap& map, int f, const Eigen::MatrixX3i& triangles,
                   const PoolEntry& entry, TexelBuffer* texels) {
  if (map.first(f) == map.last(f)) return 0;
  // The texel's surface point w . (a, b, c) is projected through the entry's camera; camera
  // coordinates are linear in the barycentrics, so the corners are transformed once.
  TriangleProjection projection;
  for (int k = 0; k < 3; ++k)
    projection.corner[k] =
        entry.camera.world_to_camera * entry.vertices.row(triangles(f, k)).transpose();
  const PinholeCamera& camera = entry.camera;
  projection.fx = camera.fx;
  projection.fy = camera.fy;
  projection.cx = camera.cx;
  projection.cy = camera.cy;
  const double ox = entry.offset.x(), oy = entry.offset.y();  // crop origin
  Eigen::Vector3f* color = texels->color.data();
  uint8_t* valid = texels->valid.data();
  double tolerance_offset = 0.0, tolerance_slope = 0.0;
  entry.SurfaceTolerance(entry.visibility.quality[f], &tolerance_offset, &tolerance_slope);
  const SurfaceDepth& surface = entry.surface;
  const Eigen::Vector3d* corner = projection.corner;

  // Bounding box of the projected triangle (full-image pixels) and its depth range. With every
  // corner in front of the camera, each texel projects inside the corners' convex hull (its
  // barycentrics are >= 0 and the projection is invariant to their scale), up to rounding.
  const bool in_front = corner[0].z() > 0.0 && corner[1].z() > 0.0 && corner[2].z() > 0.0;
  double u_min = std::numeric_limits<double>::infinity(), v_min = u_min;
  double u_max = -u_min, v_max = -u_min, z_min = u_min, z_max = -u_min;
  if (in_front) {
    for (const Eigen::Vector3d& k : projection.corner) {
      const double u = camera.fx * k.x() / k.z() + camera.cx;
      const double v = camera.fy * k.y() / k.z() + camera.cy;
      u_min = std::min(u_min, u);
      u_max = std::max(u_max, u);
      v_min = std::min(v_min, v);
      v_max = std::max(v_max, v);
      z_min = std::min(z_min, k.z());
      z_max = std::max(z_max, k.z());
    }
  }

  // Fast path: the whole projection lies inside the crop's interpolation range, so every
  // texel's bilinear cell is in the crop without clamping, and the crop pixels and z-buffer
  // depths of all cells (the footprint) are read once.
  const double x_min = u_min - ox, x_max = u_max - ox;
  const double y_min = v_min - oy, y_max = v_max - oy;
  const bool inside = in_front && x_min >= kInsideMargin && y_min >= kInsideMargin &&
                      x_max <= entry.image.cols - 1 - kInsideMargin &&
                      y_max <= entry.image.rows - 1 - kInsideMargin;
  Footprint footprint;
  if (inside) {
    footprint.x0 = static_cast<int>(x_min - kInsideMargin);
    footprint.y0 = static_cast<int>(y_min - kInsideMargin);
    footprint.width = static_cast<int>(x_max + kInsideMargin) + 2 - footprint.x0;
    footprint.height = static_cast<int>(y_max + kInsideMargin) + 2 - footprint.y0;
  }
  const bool fast = inside && footprint.width * footprint.height <= Footprint::kMaxPixels;

  // When every z-buffer pixel around the triangle's projection is within the tolerance of every
  // depth on the triangle, each texel's bilinear footprint lies on the surface: plain sampling
  // gives the same colours without the per-pixel tests.
  bool on_surface = surface.depth.empty();
  if (!on_surface && in_front && u_max - u_min < kMaxSurfaceCheckPixels &&
      v_max - v_min < kMaxSurfaceCheckPixels) {
    const double tolerance = tolerance_offset + tolerance_slope * z_min;
    const int x0 = static_cast<int>(std::floor(u_min)),
              x1 = static_cast<int>(std::floor(u_max)) + 1;
    const int y0 = static_cast<int>(std::floor(v_min)),
              y1 = static_cast<int>(std::floor(v_max)) + 1;
    if ((x1 - x0 + 1) * (y1 - y0 + 1) <= kMaxSurfaceCheckPixels) {
      if (fast) {  // the footprint covers these pixels
        footprint.ReadDepth(surface, entry.offset);
        const int dx = entry.offset.x() + footprint.x0, dy = entry.offset.y() + footprint.y0;
        on_surface = AllNearSurface(
            x0 - dx, x1 - dx, y0 - dy, y1 - dy,
            [&](int x, int y) { return footprint.DepthAt(x, y); }, z_min, z_max, tolerance);
      } else {
        on_surface = AllNearSurface(
            x0, x1, y0, y1, [&](int x, int y) { return surface.At(x, y); }, z_min, z_max,
            tolerance);
      }
    }
  }

  const int first = map.first(f), last = map.last(f);
  if (fast) {
    footprint.ReadColor(entry.image);
    // When every cell is uniform, every texel's surface-aware colour is the plain one.
    const bool plain = on_surface || footprint.FindUniformCells(z_min * (1.0 - kDepthRangeMargin),
                                                                z_max * (1.0 + kDepthRangeMargin),
                                                                tolerance_offset, tolerance_slope);
    const bool float_positions = plain && footprint.width <= kFloatFootprintSide &&
                                 footprint.height <= kFloatFootprintSide &&
                                 z_max <= kFloatDepthRatio * z_min;
    const FloatFootprintMap approximate(projection, footprint, entry.offset);
    float* out = color[first].data();  // Vector3f: 3 contiguous floats per texel
    FootprintCells cells;
    for (int block = first; block < last; block += kTexelBlock) {
      const int n = std::min(kTexelBlock, last - block);
      if (float_positions)
        cells.Project(approximate, footprint.width, map, block, n);
      else
        cells.Project(projection, entry.offset, footprint, map, block, n);
      // Every texel but the triangle's last is stored with a spilling 4th lane.
      const int spilling = block + n < last ? n : n - 1;
      float* block_out = out + 3 * (block - first);
      if (plain) {
        for (int k = 0; k < n; ++k) {
          SampleFootprint(footprint, cells.index[k], cells.fx[k], cells.fy[k], k < spilling,
                          block_out + 3 * k);
        }
      } else {
        for (int k = 0; k < n; ++k) {
          SampleSurfaceFootprint(footprint, cells, k, tolerance_offset, tolerance_slope,
                                 k < spilling, block_out + 3 * k);
        }
      }
    }
    std::fill(valid + first, valid + last, 1);
    return last - first;
  }
  // General path (a corner behind the camera, the projection reaching the crop's border, or a
  // large footprint): the pool entry's checked samplers.
  int written = 0;
  for (int p = first; p < last; ++p) {
    double u, v, z;
    projection.Project(map.barycentrics(0)[p], map.barycentrics(1)[p], map.barycentrics(2)[p], &u,
                       &v, &z);
    Eigen::Vector3f value;
    const bool sampled =
        on_surface
            ? entry.Sample(Eigen::Vector2d(u, v), &value)
            : entry.SampleSurfaceAt(u, v, z, tolerance_offset + tolerance_slope * z, true, &value);
    if (!sampled) continue;
    color[p] = value;
    valid[p] = 1;
    ++written;
  }
  return written;
}

void ClearTriangle(const AtlasMap& map, int f, TexelBuffer* texels) {
  std::fill(texels->color.begin() + map.first(f), texels->color.begin() + map.last(f),
            Eigen::Vector3f::Zero());
  std::fill(texels->valid.begin() + map.first(f), texels->valid.begin() + map.last(f), 0);
}

cv::Mat ComposeAtlas(const AtlasMap& map, const TexelBuffer& base,
                     const Eigen::MatrixX3f* corner_corrections, int padding,
                     AtlasScratch* scratch) {
  const int size = map.size();
  AtlasScratch local;
  AtlasScratch& work = scratch ? *scratch : local;
  work.color.create(size, size, CV_32FC3);  // kept when of this size and type already
  work.mask.create(size, size, CV_8UC1);
  work.color.setTo(cv::Scalar(0, 0, 0));
  work.mask.setTo(cv::Scalar(0));
  const bool correct = corner_corrections != nullptr && corner_corrections->rows() > 0;
  auto* color = reinterpret_cast<cv::Vec3f*>(work.color.data);
  uint8_t* mask = work.mask.data;
  tbb::parallel_for(tbb::blocked_range<int>(0, map.num_triangles(), 256),
                    [&](const tbb::blocked_range<int>& range) {
                      ScatterTexels(map, base, correct ? corner_corrections : nullptr,
                                    range.begin(), range.end(), color, mask);
                    });
  PadAtlas(padding, &work.color, &work.mask);
  cv::Mat out8;
  work.color.convertTo(out8, CV_8UC3, 255.0);
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
