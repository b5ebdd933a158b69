// Texture MRF terms of the paper (eq. 6-14, docs/design.md "Texture") for per-triangle view
// selection: quality W, the data term D with its lifetime part, the seam colour cost Pi, the
// temporal seam cost Psi, and V = (1 - alpha) Pi + alpha Psi. Pure functions of their inputs;
// the image sampling that produces Pi's colour differences lives in texture/.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <limits>
#include <string>
#include <vector>

namespace artex {

struct TextureTermOptions {
  double beta = 0.7;    // D = beta (1 - W) + (1 - beta) min(t_max, age) / t_max; [0, 1]
  double t_max = 60.0;  // lifetime saturation (frames); > 0
  double alpha = 0.3;   // V = (1 - alpha) Pi + alpha Psi; [0, 1]
  double lambda = 1.0;  // smoothness weight of sum V (eq. 14); >= 0
  // Psi = min(1, d / seam_distance_scale), d = distance (m, along the rest mesh) from the edge
  // to the nearest seam of the previous labelling; > 0.
  double seam_distance_scale = 0.10;
  // Views with W below this are treated as not visible (grazing views give smeared texels).
  double min_quality = 0.05;
  // Hysteresis (not in the paper; 0 = the paper's energy, configs/paper/texturing.yaml):
  // added to D(f, l) for every label l other than f's previous image while that image is still
  // pooled, so a triangle keeps its source until another image is better by more than this.
  // With the lifetime term alone the newest image is cheaper by (1 - beta) / t_max per frame
  // of age for every triangle, and a whole region relabelled at once keeps its seams
  // (docs/texturing.md): without hysteresis most visible triangles move to the newest image
  // every frame. One frame of age costs (1 - beta) / t_max (0.005 at the defaults), so the
  // default 0.02 (incremental texturing) is four frames of age. >= 0.
  double switch_cost = 0.02;

  bool IsValid(std::string* error) const;
};

// W = max(0, -n . v): n the unit triangle normal, v the unit viewing direction from the camera
// centre towards the triangle (paper eq. 12).
double TriangleQuality(const Eigen::Vector3d& normal, const Eigen::Vector3d& view_direction);

// The lifetime part of D: (1 - beta) min(t_max, max(0, age)) / t_max, the same for every
// triangle of one image.
inline double ViewAgeCost(double age_frames, const TextureTermOptions& options) {
  return (1.0 - options.beta) *
         (std::min(options.t_max, std::max(0.0, age_frames)) / options.t_max);
}

// D(f, l) of eq. 13 from the image's ViewAgeCost: +inf when not visible or quality <
// min_quality. (Inline: evaluated for every triangle and pooled image each frame.)
inline double ViewDataCostFromAge(bool visible, double quality, double age_cost,
                                  const TextureTermOptions& options) {
  if (!visible || quality < options.min_quality) return std::numeric_limits<double>::infinity();
  return options.beta * (1.0 - quality) + age_cost;
}

// D(f, l) of eq. 13 for an image age_frames old.
inline double ViewDataCost(bool visible, double quality, double age_frames,
                           const TextureTermOptions& options) {
  return ViewDataCostFromAge(visible, quality, ViewAgeCost(age_frames, options), options);
}

// V_ij for l_i != l_j: (1 - alpha) Pi + alpha Psi (0 when the labels are equal: the caller
// does not call it then).
inline double SeamPairCost(double colour_cost, double temporal_cost,
                           const TextureTermOptions& options) {
  return (1.0 - options.alpha) * colour_cost + options.alpha * temporal_cost;
}

// Psi per mesh edge from a per-vertex distance field d (m) to the previous seams.
inline double TemporalSeamCost(double distance, const TextureTermOptions& options) {
  return std::min(1.0, distance / options.seam_distance_scale);
}

// Distance (m, shortest paths along mesh edges of `vertices`) from every vertex to the nearest
// vertex in `sources`; +inf everywhere when sources is empty (no previous seams: Psi = 1).
// vertices: V x 3; triangles: F x 3.
std::vector<double> MeshDistanceField(const Eigen::MatrixX3d& vertices,
                                      const Eigen::MatrixX3i& triangles,
                                      const std::vector<int>& sources);

// The same distance field for many source sets on one mesh: the vertex adjacency and the edge
// lengths are built once (Dijkstra per call).
class MeshGeodesics {
 public:
  // vertices: V x 3; triangles: F x 3 with indices in [0, V).
  MeshGeodesics(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles);
  int num_vertices() const { return static_cast<int>(offsets_.size()) - 1; }
  // As MeshDistanceField; sources outside [0, V) are ignored. Distances above max_distance are
  // +inf (the search stops there; distances up to it are exact).
  std::vector<double> DistanceField(
      const std::vector<int>& sources,
      double max_distance = std::numeric_limits<double>::infinity()) const;
  // The longest edge (m), 0 without edges.
  double max_edge_length() const { return max_edge_length_; }

 private:
  // DistanceField by Dijkstra with a binary heap (any bound).
  std::vector<double> HeapDistanceField(const std::vector<int>& sources, double max_distance) const;

  std::vector<int> offsets_;     // V + 1 (CSR)
  std::vector<int> neighbours_;  // unique neighbours per vertex
  std::vector<double> lengths_;  // edge length per neighbour entry
  double max_edge_length_ = 0.0;
  double min_edge_length_ = std::numeric_limits<double>::infinity();
};

}  // namespace artex
