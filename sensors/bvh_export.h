// BVH export of a tracked motion (the inverse of the importer in sensors/bvh.h): the template's
// joint tree becomes the BVH HIERARCHY (OFFSET = t_j - t_parent, the root at t_root), each pose
// one MOTION line. BVH conventions as the importer's: rotations in degrees, applied in channel
// order (R = R_c1 R_c2 R_c3), global = global_parent * [offset, R_local]. With R_local = R_j and
// the root's R0 R_root, the BVH joints' world positions equal artex's posed joint centres
// (Skinning::PosedJointCenters) and their world rotations R0 R_root ... R_j (docs/motions.md).
#pragma once

#include <string>
#include <vector>

#include "models/pose.h"
#include "models/template.h"

namespace artex {

struct BvhExportOptions {
  double units_per_metre = 100.0;  // BVH length unit: 100 = centimetres (CMU, Blender); > 0
  // Rotation channel order of every joint, a permutation of "XYZ" (R = R_1 R_2 R_3).
  std::string rotation_order = "ZXY";
  // BVH has no scale channel: OFFSETs are scaled by the median of the poses' global scales
  // (tracking fixes it after the first frames); the per-frame root position keeps its own.
  // Length (m, before scaling) of the End Site of every leaf joint along its twist axis; 0: the
  // extent of the joint's vertices along the axis.
  double end_site_length = 0.0;
  bool IsValid(std::string* error) const;
};

// BVH text for `poses` (each with tmpl.num_joints() joints, finite, positive scale) at
// frame_rate Hz. Throws artex::Error on invalid input or options.
std::string EncodeBvh(const Template& tmpl, const std::vector<Pose>& poses, double frame_rate,
                      const BvhExportOptions& options = BvhExportOptions());
// EncodeBvh written atomically (temporary + rename); errors name `path`.
void WriteBvh(const std::string& path, const Template& tmpl, const std::vector<Pose>& poses,
              double frame_rate, const BvhExportOptions& options = BvhExportOptions());

}  // namespace artex
