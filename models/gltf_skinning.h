// glTF's linear-blend skinning of the skin that WriteAnimatedGlb writes (models/template_io.h),
// and the per-frame corrective shapes that make it reproduce artex's LBS+SLERP skinning
// (models/skinning.h) exactly: docs/formats-template.md, "Exact animation".
//
// The glb skin puts weight w_l on the vertex's joint k and 1 - w_l on its parent (the global
// similarity node for the root), with joint matrices J_j = G o T_root o ... o T_j, where
// G(x) = s0 R0 x + t0 and T_i(x) = R_i (x - t_i) + t_i. A viewer therefore computes
//   p = w_l J_k(v + d) + (1 - w_l) J_parent(k)(v + d),
// d being the rest-space displacement of the active morph targets. Per vertex this map is
// affine, so the d that makes p equal artex's S(v; theta) solves one 3 x 3 linear system.
#pragma once

#include <Eigen/Core>

#include "models/pose.h"
#include "models/template.h"

namespace artex {

// V x 3 positions a glTF viewer computes for the template's vertices at `pose`, with the
// rest-space offsets `offsets` (V x 3 morph displacement; null: none). Throws artex::Error
// when the pose's joint count differs from the template's or offsets has the wrong shape.
void GltfSkinnedPositions(const Template& tmpl, const Pose& pose, const Eigen::MatrixX3d* offsets,
                          Eigen::MatrixX3d* positions);

struct GltfCorrectiveOptions {
  // A vertex whose blended linear map has |det| below this (relative to s0^3) keeps d = 0: its
  // two joint rotations nearly cancel (a 180-degree bend at w_l = 0.5), where no finite
  // correction exists. Counted in GltfCorrectiveStats::singular_vertices.
  double min_relative_determinant = 1e-6;
  bool IsValid(std::string* error) const;
};

struct GltfCorrectiveStats {
  int singular_vertices = 0;
  double max_offset = 0.0;  // m, largest |d|
};

// Rest-space offsets d (V x 3) with GltfSkinnedPositions(tmpl, pose, &d) == target (V x 3,
// e.g. Skinning::Apply of the same pose). Throws artex::Error on shapes or invalid options.
void GltfCorrectiveOffsets(const Template& tmpl, const Pose& pose, const Eigen::MatrixX3d& target,
                           const GltfCorrectiveOptions& options, Eigen::MatrixX3d* offsets,
                           GltfCorrectiveStats* stats = nullptr);

}  // namespace artex
