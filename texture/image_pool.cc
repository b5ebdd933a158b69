#include "texture/image_pool.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <sstream>
#include <utility>

#include "models/error.h"

namespace artex {
namespace {
// Surface-aware sampling: qualities below this are clamped (bounds the slope tolerance).
constexpr double kMinSurfaceQuality = 0.05;
// Pruning keeps one byte per triangle and image: 1 + the histogram bin.
constexpr int kMaxHistogramBins = 255;
// Vertices and edges per parallel task when sampling an entry's colours.
constexpr int kVertexGrain = 2048;
constexpr int kEdgeGrain = 1024;

// PoolEntry::SampleSurface without fallback at many points of one entry (vertex and edge
// colours), with the tolerance's slope and offset computed once by the caller: the same colours
// bit for bit. Reads the z-buffer directly where a bilinear cell lies inside it at full raster
// scale.
class SurfaceSampler {
 public:
  explicit SurfaceSampler(const PoolEntry& entry)
      : entry_(entry),
        direct_(!entry.surface.depth.empty() && entry.surface.scale == 1.0),
        dx_(entry.offset.x() - entry.surface.x0),
        dy_(entry.offset.y() - entry.surface.y0) {}

  // Colour of the point at camera coordinates (x, y, z) (m), accepting z-buffer depths within
  // `tolerance` of z; false when the point is outside the crop or no tap is on the surface.
  bool operator()(double x, double y, double z, double tolerance, Eigen::Vector3f* color) const {
    const PinholeCamera& camera = entry_.camera;
    const double u = camera.fx * x / z + camera.cx;
    const double v = camera.fy * y / z + camera.cy;
    if (entry_.surface.depth.empty()) return entry_.Sample(Eigen::Vector2d(u, v), color);
    PoolEntry::BilinearCell cell;
    if (!entry_.Cell(u, v, &cell)) return false;
    const SurfaceDepth& surface = entry_.surface;
    if (direct_ && cell.x0 + dx_ >= 0 && cell.y0 + dy_ >= 0 && cell.x1 + dx_ < surface.width &&
        cell.y1 + dy_ < surface.height) {
      const auto depth_at = [this, &surface](int cx, int cy) {
        return surface.depth[static_cast<std::size_t>(cy + dy_) * surface.width + cx + dx_];
      };
      return entry_.BlendSurface(cell, z, tolerance, depth_at, color);
    }
    const auto depth_at = [this, &surface](int cx, int cy) {
      return surface.At(cx + entry_.offset.x(), cy + entry_.offset.y());
    };
    return entry_.BlendSurface(cell, z, tolerance, depth_at, color);
  }

 private:
  const PoolEntry& entry_;
  const bool
      direct_;  // full-scale z-buffer: crop pixel (x, y) is z-buffer pixel (x + dx_, y + dy_)
  const int dx_, dy_;
};

// PoolEntry::vertex_colors: the colour of every vertex v with quality[v] <= 1 and a finite
// projection pixels[v], seen at that quality; cam: 3 x V camera coordinates (m).
void SampleVertexColors(const PoolEntry& entry, const Eigen::Matrix3Xd& cam,
                        const std::vector<Eigen::Vector2d>& pixels,
                        const std::vector<float>& quality, ColorRows* colors) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const SurfaceSampler sample(entry);
  const int v_count = static_cast<int>(cam.cols());
  colors->resize(v_count, 3);
  const auto sample_range = [&](const tbb::blocked_range<int>& range) {
    for (int v = range.begin(); v < range.end(); ++v) {
      const double x = cam(0, v), y = cam(1, v), z = cam(2, v);
      Eigen::Vector3f color;
      bool seen = false;
      if (quality[v] <= 1.0f && pixels[v].allFinite()) {
        double tolerance_offset = 0.0, tolerance_slope = 0.0;
        entry.SurfaceTolerance(quality[v], &tolerance_offset, &tolerance_slope);
        seen = sample(x, y, z, tolerance_offset + tolerance_slope * z, &color);
      }
      if (seen)
        colors->row(v) = color.transpose();
      else
        colors->row(v).setConstant(nan);
    }
  };
  tbb::parallel_for(tbb::blocked_range<int>(0, v_count, kVertexGrain), sample_range);
}

// PoolEntry::edge_colors: `samples` colours along every edge with a visible side, at the points
// (1 - t) a + t b, t = (k + 0.5) / samples, seen at the lower quality of its visible sides.
void SampleEdgeColors(const PoolEntry& entry, const TextureMesh& mesh, const Eigen::Matrix3Xd& cam,
                      int samples, EdgeColorRows* colors) {
  const SurfaceSampler sample(entry);
  const TriangleVisibility& vis = entry.visibility;
  const int e_count = static_cast<int>(mesh.edges.rows());
  colors->resize(static_cast<Eigen::Index>(e_count) * samples, 3);
  const auto sample_range = [&](const tbb::blocked_range<int>& range) {
    for (int e = range.begin(); e < range.end(); ++e) {
      const Eigen::Index first_row = static_cast<Eigen::Index>(e) * samples;
      const int f0 = mesh.edge_faces(e, 0), f1 = mesh.edge_faces(e, 1);
      if (!vis.visible[f0] && !vis.visible[f1]) {
        colors->middleRows(first_row, samples).setConstant(kEdgeColorUnseen);
        continue;
      }
      const float quality = std::min(vis.visible[f0] ? vis.quality[f0] : 1.0f,
                                     vis.visible[f1] ? vis.quality[f1] : 1.0f);
      double tolerance_offset = 0.0, tolerance_slope = 0.0;
      entry.SurfaceTolerance(quality, &tolerance_offset, &tolerance_slope);
      const double* a = cam.col(mesh.edges(e, 0)).data();
      const double* b = cam.col(mesh.edges(e, 1)).data();
      for (int k = 0; k < samples; ++k) {
        const double t = (k + 0.5) / samples;
        const double x = (1 - t) * a[0] + t * b[0];
        const double y = (1 - t) * a[1] + t * b[1];
        const double z = (1 - t) * a[2] + t * b[2];
        Eigen::Vector3f color;
        std::uint16_t* row = colors->row(first_row + k).data();
        if (sample(x, y, z, tolerance_offset + tolerance_slope * z, &color)) {
          for (int c = 0; c < 3; ++c) row[c] = EdgeColorValue(color[c]);
        } else {
          row[0] = row[1] = row[2] = kEdgeColorUnseen;
        }
      }
    }
  };
  tbb::parallel_for(tbb::blocked_range<int>(0, e_count, kEdgeGrain), sample_range);
}
}  // namespace

TextureMesh TextureMesh::Build(const Eigen::MatrixX3i& triangles) {
  TextureMesh mesh;
  mesh.triangles = triangles;
  std::map<std::pair<int, int>, std::vector<int>> faces_of_edge;
  for (int f = 0; f < triangles.rows(); ++f) {
    for (int c = 0; c < 3; ++c) {
      int a = triangles(f, c), b = triangles(f, (c + 1) % 3);
      if (a > b) std::swap(a, b);
      faces_of_edge[{a, b}].push_back(f);
    }
  }
  std::vector<std::array<int, 4>> edges;
  for (const auto& [key, faces] : faces_of_edge) {
    if (faces.size() == 2) edges.push_back({key.first, key.second, faces[0], faces[1]});
  }
  // Breadth-first triangle order over the shared edges (CSR adjacency of the triangles).
  const int f_count = static_cast<int>(triangles.rows());
  std::vector<int> offsets(f_count + 1, 0), neighbours(2 * edges.size());
  for (const auto& e : edges) {
    ++offsets[e[2] + 1];
    ++offsets[e[3] + 1];
  }
  for (int f = 0; f < f_count; ++f) offsets[f + 1] += offsets[f];
  std::vector<int> fill(offsets.begin(), offsets.end() - 1);
  for (const auto& e : edges) {
    neighbours[fill[e[2]]++] = e[3];
    neighbours[fill[e[3]]++] = e[2];
  }
  std::vector<uint8_t> seen(f_count, 0);
  mesh.triangle_order.reserve(f_count);
  for (int root = 0; root < f_count; ++root) {
    if (seen[root]) continue;
    seen[root] = 1;
    mesh.triangle_order.push_back(root);
    for (std::size_t k = mesh.triangle_order.size() - 1; k < mesh.triangle_order.size(); ++k) {
      const int f = mesh.triangle_order[k];
      for (int p = offsets[f]; p < offsets[f + 1]; ++p) {
        if (seen[neighbours[p]]) continue;
        seen[neighbours[p]] = 1;
        mesh.triangle_order.push_back(neighbours[p]);
      }
    }
  }
  // Edges by the earlier of their triangles in that order (ties: vertex pairs), so that passes
  // over the edges visit neighbouring triangles together.
  std::vector<int> position(f_count);
  for (int k = 0; k < f_count; ++k) position[mesh.triangle_order[k]] = k;
  std::vector<int> key(edges.size());
  for (std::size_t e = 0; e < edges.size(); ++e)
    key[e] = std::min(position[edges[e][2]], position[edges[e][3]]);
  std::vector<int> by_key(edges.size());
  std::iota(by_key.begin(), by_key.end(), 0);
  std::stable_sort(by_key.begin(), by_key.end(), [&key](int a, int b) { return key[a] < key[b]; });
  mesh.edges.resize(static_cast<Eigen::Index>(edges.size()), 2);
  mesh.edge_faces.resize(static_cast<Eigen::Index>(edges.size()), 2);
  for (std::size_t k = 0; k < edges.size(); ++k) {
    const std::array<int, 4>& edge = edges[by_key[k]];
    mesh.edges.row(k) << edge[0], edge[1];
    mesh.edge_faces.row(k) << edge[2], edge[3];
  }
  return mesh;
}

bool ImagePoolOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (max_images < 1)
    msg << "pool.max_images: expected >= 1, found " << max_images;
  else if (hard_max_images < max_images)
    msg << "pool.hard_max_images: expected >= pool.max_images (" << max_images << "), found "
        << hard_max_images;
  else if (histogram_bins < 1 || histogram_bins > kMaxHistogramBins)
    msg << "pool.histogram_bins: expected [1, " << kMaxHistogramBins << "], found "
        << histogram_bins;
  else if (crop_margin < 0)
    msg << "pool.crop_margin: expected >= 0, found " << crop_margin;
  else if (edge_samples < 2)
    msg << "pool.edge_samples: expected >= 2, found " << edge_samples;
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

std::size_t PoolEntry::MemoryBytes() const {
  return image.total() * image.elemSize() + vertices.size() * sizeof(double) +
         visibility.visible.size() * 5 + vertex_colors.size() * 4 + vertex_coloured.size() +
         edge_colors.size() * sizeof(std::uint16_t) +
         surface.MemoryBytes();
}

void PoolEntry::SurfaceTolerance(double quality, double* tolerance_offset,
                                 double* tolerance_slope) const {
  const double w = std::max(quality, kMinSurfaceQuality);
  *tolerance_offset = depth_tolerance;
  // Depth change across one pixel diagonal (sqrt(2) z / fx) of a surface tilted by acos(W).
  *tolerance_slope = std::sqrt(2.0) / camera.fx * std::sqrt(1.0 - w * w) / w;
}

bool PoolEntry::SampleSurface(const Eigen::Vector3d& point, double quality, bool fallback,
                              Eigen::Vector3f* color) const {
  const double z = point.z();
  double offset0 = 0.0, slope = 0.0;
  SurfaceTolerance(quality, &offset0, &slope);
  return SampleSurfaceAt(camera.fx * point.x() / z + camera.cx,
                         camera.fy * point.y() / z + camera.cy, z, offset0 + slope * z, fallback,
                         color);
}

ImagePool::ImagePool(const TextureMesh* mesh, const ImagePoolOptions& pool_options,
                     const VisibilityOptions& visibility_options)
    : mesh_(mesh), options_(pool_options), visibility_options_(visibility_options) {
  std::string why;
  if (!options_.IsValid(&why)) throw Error(why);
  if (!visibility_options_.IsValid(&why)) throw Error(why);
}

int ImagePool::Add(int frame_index, const cv::Mat& color_bgr, const PinholeCamera& camera,
                   const Eigen::MatrixX3d& posed_vertices) {
  return Insert(MakeEntry(frame_index, color_bgr, camera, posed_vertices));
}

std::unique_ptr<PoolEntry> ImagePool::MakeEntry(int frame_index, const cv::Mat& color_bgr,
                                                const PinholeCamera& camera,
                                                const Eigen::MatrixX3d& posed_vertices) const {
  if (color_bgr.type() != CV_8UC3 || color_bgr.cols != camera.width ||
      color_bgr.rows != camera.height) {
    std::ostringstream msg;
    msg << "frame " << frame_index << ": expected a " << camera.width << "x" << camera.height
        << " 8-bit BGR colour image, found " << color_bgr.cols << "x" << color_bgr.rows << " with "
        << color_bgr.channels() << " channel(s)";
    throw Error(msg.str());
  }
  auto entry = std::make_unique<PoolEntry>();
  entry->frame_index = frame_index;
  entry->camera = camera;
  entry->depth_tolerance = visibility_options_.depth_tolerance;
  const int v_count = static_cast<int>(posed_vertices.rows());
  Eigen::Matrix3Xd cam(3, v_count);
  std::vector<Eigen::Vector2d> pixels(v_count);  // NaN behind the camera
  // The visibility z-buffer and the crop do not depend on each other: computed concurrently.
  tbb::parallel_invoke(
      [&] {
        entry->visibility =
            ComputeVisibility(posed_vertices, mesh_->triangles, camera, visibility_options_,
                              options_.surface_aware_sampling ? &entry->surface : nullptr);
      },
      [&] {
        entry->vertices = posed_vertices;
        // Camera coordinates of every vertex (sample points along edges are linear in them).
        const Eigen::Matrix3d rotation = camera.world_to_camera.linear();
        const Eigen::Vector3d translation = camera.world_to_camera.translation();
        for (int v = 0; v < v_count; ++v)
          cam.col(v) = rotation * posed_vertices.row(v).transpose() + translation;
        // Crop to the projection of the subject.
        double min_x = std::numeric_limits<double>::infinity(), min_y = min_x;
        double max_x = -min_x, max_y = -min_x;
        for (int v = 0; v < v_count; ++v) {
          pixels[v] = Eigen::Vector2d(camera.fx * cam(0, v) / cam(2, v) + camera.cx,
                                      camera.fy * cam(1, v) / cam(2, v) + camera.cy);
          if (!(cam(2, v) > 0.0)) pixels[v].setConstant(std::numeric_limits<double>::quiet_NaN());
          if (!pixels[v].allFinite()) continue;
          min_x = std::min(min_x, pixels[v].x());
          min_y = std::min(min_y, pixels[v].y());
          max_x = std::max(max_x, pixels[v].x());
          max_y = std::max(max_y, pixels[v].y());
        }
        // Clamped as doubles first: with no vertex in view the box is infinite, and converting
        // an infinity (or a far-off pixel) to int is undefined behaviour (issue 20, UBSan).
        const double margin = options_.crop_margin;
        auto to_pixel = [](double x, int size) {
          return static_cast<int>(std::clamp(x, 0.0, static_cast<double>(size)));
        };
        const int x0 = to_pixel(std::floor(min_x) - margin, camera.width);
        const int y0 = to_pixel(std::floor(min_y) - margin, camera.height);
        const int x1 = to_pixel(std::ceil(max_x) + margin + 1, camera.width);
        const int y1 = to_pixel(std::ceil(max_y) + margin + 1, camera.height);
        if (x1 > x0 && y1 > y0) {
          entry->image = color_bgr(cv::Rect(x0, y0, x1 - x0, y1 - y0)).clone();
          entry->offset = {x0, y0};
        } else {
          entry->image = cv::Mat(1, 1, CV_8UC3, cv::Scalar(0, 0, 0));
          entry->offset = {-10, -10};  // nothing samples inside
        }
      });
  // Vertex colours where a triangle around is visible (with vertex_colors_need_full_ring: all
  // are), seen at the lowest quality of those; colours along edges.
  const TriangleVisibility& vis = entry->visibility;
  std::vector<float> vertex_quality(v_count, 2.0f);  // > 1: not seen
  for (int f = 0; f < mesh_->triangles.rows(); ++f) {
    if (!vis.visible[f]) continue;
    for (int c = 0; c < 3; ++c) {
      float& q = vertex_quality[mesh_->triangles(f, c)];
      q = std::min(q, vis.quality[f]);
    }
  }
  if (options_.vertex_colors_need_full_ring) {
    for (int f = 0; f < mesh_->triangles.rows(); ++f) {
      if (vis.visible[f]) continue;
      for (int c = 0; c < 3; ++c) vertex_quality[mesh_->triangles(f, c)] = 2.0f;
    }
  }
  SampleVertexColors(*entry, cam, pixels, vertex_quality, &entry->vertex_colors);
  SampleEdgeColors(*entry, *mesh_, cam, options_.edge_samples, &entry->edge_colors);
  return entry;
}

int ImagePool::Insert(std::unique_ptr<PoolEntry> entry) {
  if (!entry) throw Error("ImagePool::Insert: expected an entry, found none");
  const TriangleVisibility& vis = entry->visibility;
  if (static_cast<int>(vis.visible.size()) != mesh_->triangles.rows()) {
    throw Error("ImagePool::Insert: expected visibility of " +
                std::to_string(mesh_->triangles.rows()) + " triangles, found " +
                std::to_string(vis.visible.size()));
  }
  // The entry's histogram level per triangle for pruning: 0 where not visible, else 1 + the bin
  // of W (the last bin includes W = 1).
  const int bins = options_.histogram_bins;
  std::vector<uint8_t> level(vis.visible.size(), 0);
  for (std::size_t f = 0; f < level.size(); ++f) {
    if (vis.visible[f])
      level[f] =
          static_cast<uint8_t>(1 + std::min(bins - 1, static_cast<int>(vis.quality[f] * bins)));
  }
  entry->vertex_coloured.resize(entry->vertex_colors.rows());
  for (Eigen::Index v = 0; v < entry->vertex_colors.rows(); ++v)
    entry->vertex_coloured[v] = entry->vertex_colors.row(v).allFinite() ? 1 : 0;
  slot_frames_.push_back(entry->frame_index);
  entries_.push_back(std::move(entry));
  levels_.push_back(std::move(level));
  return size() - 1;
}

int ImagePool::SlotOfFrame(int frame_index) const {
  const auto it = std::find(slot_frames_.begin(), slot_frames_.end(), frame_index);
  return it == slot_frames_.end() ? -1 : static_cast<int>(it - slot_frames_.begin());
}

bool ImagePool::IsUniquelyBest(int slot) const {
  const int bins = options_.histogram_bins;
  const int f_count = static_cast<int>(mesh_->triangles.rows());
  const auto bin_of = [bins](float w) { return std::min(bins - 1, static_cast<int>(w * bins)); };
  for (int f = 0; f < f_count; ++f) {
    if (!entries_[slot]->visibility.visible[f]) continue;
    const int my_bin = bin_of(entries_[slot]->visibility.quality[f]);
    bool unique = true;
    for (int s = 0; s < size() && unique; ++s) {
      if (s == slot || !entries_[s]->visibility.visible[f]) continue;
      if (bin_of(entries_[s]->visibility.quality[f]) >= my_bin) unique = false;
    }
    if (unique) return true;
  }
  return false;
}

std::vector<uint8_t> ImagePool::UniquelyBestSlots() const {
  const int slots = size();
  const std::size_t f_count = static_cast<std::size_t>(mesh_->triangles.rows());
  // Per triangle: the best level over the slots, how many slots reach it (counted up to 2), and
  // the level that makes a slot uniquely best there (0: none).
  std::vector<uint8_t> best(f_count, 0), count(f_count, 0);
  for (int s = 0; s < slots; ++s) {
    const uint8_t* level = levels_[s].data();
    for (std::size_t f = 0; f < f_count; ++f) best[f] = std::max(best[f], level[f]);
  }
  for (int s = 0; s < slots; ++s) {
    const uint8_t* level = levels_[s].data();
    for (std::size_t f = 0; f < f_count; ++f)
      count[f] = std::min<uint8_t>(2, count[f] + (level[f] == best[f]));
  }
  std::vector<uint8_t>& unique = best;
  for (std::size_t f = 0; f < f_count; ++f) unique[f] = count[f] == 1 ? best[f] : 0;
  std::vector<uint8_t> keep(slots, 0);
  for (int s = 0; s < slots; ++s) {
    const uint8_t* level = levels_[s].data();
    uint8_t found = 0;
    for (std::size_t f = 0; f < f_count; ++f) found |= (level[f] == unique[f]) & (unique[f] != 0);
    keep[s] = found;
  }
  return keep;
}

std::vector<int> ImagePool::Prune() {
  std::vector<int> dropped;
  // The paper's rule, oldest first: drop an image unless it is uniquely best for a triangle.
  while (size() > options_.max_images) {
    const std::vector<uint8_t> keep = UniquelyBestSlots();
    const auto it = std::find(keep.begin(), keep.end(), 0);
    if (it == keep.end()) break;
    const int s = static_cast<int>(it - keep.begin());
    dropped.push_back(entries_[s]->frame_index);
    entries_.erase(entries_.begin() + s);
    slot_frames_.erase(slot_frames_.begin() + s);
    levels_.erase(levels_.begin() + s);
  }
  // Memory bound: beyond the hard cap the oldest go regardless.
  while (size() > options_.hard_max_images) {
    dropped.push_back(entries_.front()->frame_index);
    entries_.erase(entries_.begin());
    slot_frames_.erase(slot_frames_.begin());
    levels_.erase(levels_.begin());
  }
  return dropped;
}

std::size_t ImagePool::MemoryBytes() const {
  std::size_t bytes = 0;
  for (const auto& e : entries_) bytes += e->MemoryBytes();
  for (const auto& l : levels_) bytes += l.size();
  return bytes;
}

}  // namespace artex
