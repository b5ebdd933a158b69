// Template files: glTF 2.0 binary (.glb) skinned meshes that any glTF viewer or Blender can
// open, with the paper's per-vertex skinning constants (joint k, w_l, tau; eq. 2) kept in
// custom attributes so that reading back is exact up to float precision.
// Layout and conventions: docs/formats-template.md.
//
// The standard glTF skin is a linear-blend approximation of the paper's model: weight w_l on
// joint k and 1 - w_l on its parent (the root joint's parent is the global-similarity node).
// It is exact when no joint twists; glTF cannot express the cylindrical SLERP of the twist.
#pragma once

#include <string>
#include <vector>

#include "models/gltf_skinning.h"
#include "models/pose.h"
#include "models/template.h"

namespace artex {

// An optional base-colour texture embedded as PNG. Either `png` holds an encoded PNG file,
// or `rgb` holds width x height RGB8 pixels, row-major, row 0 at v = 0 (glTF convention).
struct GlbTexture {
  std::vector<unsigned char> png;
  std::vector<unsigned char> rgb;
  int width = 0;
  int height = 0;

  bool empty() const { return png.empty() && rgb.empty(); }
};

struct GlbReadOptions {
  // Largest accepted |sum of WEIGHTS_0 (+ WEIGHTS_1) - 1| per vertex.
  double weight_sum_tolerance = 1e-3;
  // Largest accepted distance of a stored weight or tau from [0, 1] (float round-off).
  double unit_interval_tolerance = 1e-6;
  // Deepest accepted nesting of JSON objects and arrays (artex writes 5 levels); deeper files
  // are rejected before the glTF parser sees them (it recurses per level).
  int max_json_depth = 64;
};

// Writes `tmpl` (must pass Template::IsValid) as a skinned glTF binary, through a temporary
// file and a rename. Throws artex::Error naming `path` on an invalid template, texture or an
// I/O failure; never leaves a partial file.
void WriteTemplateGlb(const std::string& path, const Template& tmpl,
                      const GlbTexture* texture = nullptr);

// As WriteTemplateGlb, plus one animation with a keyframe per pose at `frame_rate` Hz: joint
// rotations R_j on the joint nodes, the global similarity (s0, R0, t0) on the root node,
// linearly interpolated (quaternion slerp). Every pose must have tmpl.num_joints() joints,
// finite entries and a positive scale; frame_rate > 0; at least one pose.
void WriteAnimatedGlb(const std::string& path, const Template& tmpl,
                      const std::vector<Pose>& poses, double frame_rate,
                      const GlbTexture* texture = nullptr);

// The animated glb's skin is glTF's plain linear blend, which differs from artex's LBS+SLERP
// wherever a joint twists or a vertex blends two joints (up to several cm at the hips on a
// walk). With `exact`, every pose also gets a morph target holding the rest-space corrective
// displacement (models/gltf_skinning.h), weighted 1 at its own keyframe, so that any glTF
// viewer reproduces artex's fitted geometry at every keyframe (to float precision); between
// keyframes the correctives blend linearly. Cost: 12 bytes per glTF vertex and frame.
struct AnimatedGlbOptions {
  bool exact = true;
  GltfCorrectiveOptions corrective;
  bool IsValid(std::string* error) const;
};

// What an animated glb reproduces: the distance (mm) between a glTF viewer's skinned vertices
// and artex's Skinning::Apply at the keyframes, over all frames and vertices.
struct AnimatedGlbSummary {
  int frames = 0;
  int morph_targets = 0;
  double lbs_max_residual_mm = 0.0;    // plain glTF LBS (no correctives)
  double lbs_mean_residual_mm = 0.0;
  double exact_max_residual_mm = 0.0;  // as written (equal to lbs_* without `exact`)
  double exact_mean_residual_mm = 0.0;
  int singular_vertices = 0;  // (frame, vertex) pairs left uncorrected (GltfCorrectiveOptions)
  std::size_t bytes = 0;      // file size
};

void WriteAnimatedGlb(const std::string& path, const Template& tmpl,
                      const std::vector<Pose>& poses, double frame_rate, const GlbTexture* texture,
                      const AnimatedGlbOptions& options, AnimatedGlbSummary* summary = nullptr);

// In-memory encoders behind the two writers (GLB bytes).
std::string EncodeTemplateGlb(const Template& tmpl, const GlbTexture* texture = nullptr);
std::string EncodeAnimatedGlb(const Template& tmpl, const std::vector<Pose>& poses,
                              double frame_rate, const GlbTexture* texture = nullptr);
std::string EncodeAnimatedGlb(const Template& tmpl, const std::vector<Pose>& poses,
                              double frame_rate, const GlbTexture* texture,
                              const AnimatedGlbOptions& options,
                              AnimatedGlbSummary* summary = nullptr);

// Reads a file written by WriteTemplateGlb / WriteAnimatedGlb (animations are ignored). The
// embedded base-colour image, if any and if `texture` is non-null, is returned as PNG bytes
// (texture->png; empty when the file has none). Throws artex::Error naming `path` and the
// problem: unreadable, truncated or malformed GLB, missing artex attributes (files without
// them must go through ImportGltfSkinnedMesh), non-finite values, skin weights that do not sum
// to 1, cycles in the joint hierarchy, or a result failing Template::IsValid.
Template ReadTemplateGlb(const std::string& path, GlbTexture* texture = nullptr,
                         const GlbReadOptions& options = GlbReadOptions());

// Per-vertex linear-blend skinning weights: for every vertex a list of (joint, weight) pairs
// with weights summing to 1. Shared by the importers (models/makehuman_import.h).
struct JointWeight {
  int joint = 0;
  double weight = 0.0;
};
using VertexJointWeights = std::vector<std::vector<JointWeight>>;

struct GltfImportOptions {
  GlbReadOptions read;
  // Vertices whose positions coincide exactly (UV-seam copies) are merged into one template
  // vertex; their first copy's skin weights are kept.
  bool weld_identical_positions = true;
  // Joint weights below this are dropped before the conversion (then renormalised).
  double min_joint_weight = 1e-4;
};

// Imports any glTF 2.0 (.glb or .gltf with embedded buffers) skinned mesh without artex
// attributes: the first node with both a mesh and a skin, all its triangle primitives. The
// rest pose is the scene's default node pose; joint centres are the joint nodes' world
// positions there; the joint tree follows the node hierarchy (exactly one root joint);
// linear-blend weights are converted by ConvertLbsWeights (models/makehuman_import.h), twist
// axes by DefaultTwistAxes. If `lbs_weights` is non-null it receives the original weights
// (after welding and thresholding) per template vertex, over template joint indices.
// Throws artex::Error naming `path` and the problem.
Template ImportGltfSkinnedMesh(const std::string& path,
                               const GltfImportOptions& options = GltfImportOptions(),
                               VertexJointWeights* lbs_weights = nullptr);

// Facts about a template for `artex template info` and import reports.
struct TemplateSummaryOptions {
  int uv_grid = 1024;  // UV coverage is measured on a uv_grid x uv_grid raster of [0,1]^2; >= 16
};

struct TemplateSummary {
  int num_vertices = 0;
  int num_triangles = 0;
  int num_joints = 0;
  int num_pose_parameters = 0;
  std::vector<int> vertices_per_joint;  // J: vertices whose joint k is j
  Eigen::Vector3d bbox_min = Eigen::Vector3d::Zero();
  Eigen::Vector3d bbox_max = Eigen::Vector3d::Zero();
  // UV atlas (zeros without one).
  int num_uvs = 0;
  int num_charts = 0;          // distinct triangle_chart values (0 when absent)
  double uv_coverage = 0.0;    // fraction of the unit square covered by UV triangles
  double uv_overlap = 0.0;     // fraction of the covered raster cells covered more than once
  // Topology.
  int boundary_edges = 0;      // edges with one incident triangle
  int non_manifold_edges = 0;  // edges with more than two incident triangles
  int misoriented_edges = 0;   // interior edges traversed in the same direction by both sides
  int components = 0;          // connected components (over triangles' vertices)
  int unreferenced_vertices = 0;
  int euler_characteristic = 0;  // V - E + F over referenced vertices
  bool closed_manifold() const {
    return boundary_edges == 0 && non_manifold_edges == 0 && misoriented_edges == 0;
  }
};

// The template must pass Template::IsValid (throws artex::Error otherwise, or for a uv_grid
// below 16).
TemplateSummary SummarizeTemplate(const Template& tmpl,
                                  const TemplateSummaryOptions& options = TemplateSummaryOptions());

}  // namespace artex
