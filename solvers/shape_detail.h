// Surface detail on top of the subject shape model (docs/shape.md, "Surface detail"): one offset
// per rest vertex along its rest normal, estimated from frames tracked with the final shape
// (scans and fitted poses). Bone lengths and girths scale whole segments; they make no waist,
// no chest, no flat foot of another body. The detail moves the vertices the scans show onto
// them, smoothly:
//   min_d  sum_v c_v (d_v - d'_v - r_v)^2 + smoothness sum_(i,j) (d_i - d_j)^2
//          + prior_weight sum_v d_v^2,   |d_v| <= max_offset,
// with c_v the vertex's observations over the frames and r_v their mean residual (divided by
// the pose's scale s0: offsets are in the template's rest units). An observation is, in one
// frame, the median distance along the posed vertex normal from the posed vertex (with the
// current offsets d') to the scan points on its normal line (within max_tangential of it and
// max_distance of the vertex, their normals within normal_min_cos of the vertex's), taken where
// the vertex faces the depth camera, is not hidden by the posed template itself (its z-buffer)
// and has such points. Each frame's residuals are grouped by the vertex's facing cosine
// (bias_bins bins) and segment (bias_per_segment), and each group's mean is subtracted: on the
// virtual Kinect the subject's own template, fitted, sat 2 mm behind the noisy scans facing the
// camera and 4-5 mm outside them at grazing angles, a bias of the sensor and the fit, not of the
// shape (and a segment's size is its girth's). The sum over (i, j) runs over the mesh's edges, so
// unseen vertices (the back, the soles) take a smooth continuation of their seen neighbours'
// offsets, decaying with prior_weight. `iterations` repeats the measurement with the offsets
// applied. The posed offset is taken along the rest normal carried by the skinning, which is
// the posed normal to first order. The rig, triangles and UVs are kept, so a texture atlas
// still applies.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "models/pose.h"
#include "models/template.h"
#include "render/camera.h"
#include "sensors/scan.h"

namespace artex {

struct ShapeDetailOptions {
  // Estimate the detail after the last calibration round (shape.mode other than fixed).
  bool enabled = true;
  // Frames tracked with the final shape (every shape.calibration_stride-th accepted one) kept
  // after the last round, besides that round's own (shape.calibration_frames): the depth noise
  // and each frame's pose error average out over more frames. 0: the last round's frames alone.
  int frames = 10;
  int iterations = 2;                // measure, solve; >= 1
  double max_distance = 0.03;        // m: scan points farther from the vertex are ignored
  double normal_min_cos = 0.5;       // scan point normal . vertex normal at least this
  // m: a scan point at most this far off the vertex's normal line is on it
  double max_tangential = 0.005;
  double visibility_min_cos = 0.2;   // vertex normal . direction to the camera above this
  double occlusion_tolerance = 0.01; // m: a vertex behind the template's own z-buffer is hidden
  double smoothness = 4.0;           // per mesh edge, against one observation of a vertex
  double prior_weight = 0.01;        // towards no offset, per vertex
  double max_offset = 0.03;          // m (rest units): |d_v| bound
  // Each frame's residuals, binned by the vertex's facing cosine (visibility_min_cos to 1 in
  // this many equal bins), have their bin's mean subtracted: the mean is the pose's offset
  // against the scan and the depth noise's bias at that viewing angle, not the shape (the
  // girths carry a segment's size). 0: none; 1: the frame's mean.
  int bias_bins = 4;
  // ... and by the vertex's segment (its joint): a thin limb's bias is not the trunk's.
  bool bias_per_segment = true;

  bool IsValid(std::string* error) const;
};

struct ShapeDetailSummary {
  int frames = 0;
  int iterations = 0;
  int observed_vertices = 0;  // vertices with an observation in the last iteration
  int observations = 0;       // their observations, summed over the frames
  // Mean |residual| of the observations (their group means subtracted) before the first and
  // after the last solve (m, posed),
  // the latter measured again with the final offsets.
  double residual_before = 0.0, residual_after = 0.0;
  double frame_mean_residual = 0.0;  // the frames' mean residual, averaged (m; + outwards)
  // Of the final offsets over all vertices (m): mean (signed, + outwards), rms, largest |d|.
  double mean_offset = 0.0, rms_offset = 0.0, max_offset = 0.0;
  int at_bound = 0;                           // vertices at +-max_offset
  double seconds = 0.0;
};

// The template with every rest vertex moved by offsets[v] along its rest vertex normal
// (models/normals.h). Throws artex::Error when offsets has not one entry per vertex.
Template ApplySurfaceDetail(const Template& shaped, const Eigen::VectorXd& offsets);

// The offsets (V, m in rest units) that put `shaped` (a subject template, the shape model
// applied) posed as poses[f] onto scans[f], as above; `depth_camera` is the scans' camera. Throws
// artex::Error on invalid options, a pose with another joint count, or scans and poses of
// different counts. No frames: all zero.
Eigen::VectorXd EstimateSurfaceDetail(const Template& shaped, const std::vector<const Scan*>& scans,
                                      const std::vector<Pose>& poses,
                                      const PinholeCamera& depth_camera,
                                      const ShapeDetailOptions& options,
                                      ShapeDetailSummary* summary = nullptr);

}  // namespace artex
