// Texture atlas for a closed triangle mesh split into charts (docs/template.md, "UV atlas"):
// per-corner UVs with seams on chart borders, annulus charts opened along a cheapest seam
// path, least-squares conformal maps per chart (LSCM, Levy et al. 2002; Tutte embedding with
// mean-value weights as a fold-free fallback), uniform texel density and shelf packing into
// [0,1]^2 with a texel gap. UVs follow glTF: u to the right, v downwards (row = v * height).
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

namespace artex {

struct UvAtlasOptions {
  int atlas_size = 2048;          // atlas side (texels); the padding is measured in these texels
  double padding_texels = 4.0;    // gap between charts and to the atlas border (texels), >= 0
  int rotation_steps = 90;        // chart orientations tried in [0, 90) deg for the tightest box
  double seam_cost_weight = 20.0; // seam path edge cost = length * (1 + weight * seam_cost)
  int packing_iterations = 40;    // bisection steps on the atlas scale
  double min_uv_area_ratio = 1e-3;  // LSCM result rejected (Tutte used) when a triangle's
                                    // uv/3D area ratio falls below this fraction of the chart's

  bool IsValid(std::string* error) const;
};

struct UvAtlas {
  Eigen::MatrixX2d uvs;           // U x 2 in [0,1]^2 (glTF convention)
  Eigen::MatrixX3i uv_triangles;  // F x 3 indices into uvs
  Eigen::VectorXi uv_vertex;      // U: mesh vertex each uv belongs to
};

struct UvAtlasSummary {
  int num_charts = 0;
  int num_cylinder_cuts = 0;       // annulus charts opened along a seam path
  int num_tutte_fallbacks = 0;     // charts where LSCM folded and Tutte's embedding was used
  double coverage = 0.0;           // fraction of [0,1]^2 covered by triangles
  double texels_per_metre = 0.0;   // nominal texel density (atlas_size * packing scale)
  // Per-triangle texel density sqrt(uv area / 3D area) relative to the atlas mean:
  double density_min = 0.0, density_max = 0.0;  // extremes
  double density_p05 = 0.0, density_p95 = 0.0;  // 5th / 95th area-weighted percentiles
};

// vertices: V x 3; triangles: F x 3 counter-clockwise from outside; triangle_chart: F chart ids
// (>= 0, any numbering); seam_cost: V values >= 0 where a low cost marks the preferred side for
// the seam that opens an annulus chart (empty: shortest path). Every chart, taken as the
// triangles with its id glued along shared edges, must be connected and a topological disc or
// annulus; otherwise throws artex::Error naming the chart. Output triangles keep the mesh's
// orientation: UvSignedArea(...) > 0 for every triangle (charts are not mirrored when the atlas
// is viewed as an image).
void BuildUvAtlas(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                  const Eigen::VectorXi& triangle_chart, const Eigen::VectorXd& seam_cost,
                  const UvAtlasOptions& options, UvAtlas* atlas, UvAtlasSummary* summary);

// Signed area of a uv triangle as seen in the atlas image (v downwards): positive when a / b / c
// appear counter-clockwise on screen, i.e. when the chart is not mirrored.
double UvSignedArea(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c);

// Fills the statistics of `summary` (coverage, density) for an existing atlas; num_charts and
// the cut/fallback counters are left untouched.
void MeasureUvAtlas(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                    const Eigen::MatrixX2d& uvs, const Eigen::MatrixX3i& uv_triangles,
                    int atlas_size, UvAtlasSummary* summary);

}  // namespace artex
