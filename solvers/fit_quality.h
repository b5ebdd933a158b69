// Fit quality without ground truth (docs/fitting.md "Initialisation and fit quality"): how well a
// posed template explains one scan, from three measures that a wrong fit cannot all pass (an EM
// cost cannot tell: it is a weighted mean over the correspondences that exist, whatever their
// number):
//   inlier_fraction:  scan points within inlier_distance of the posed template (distance to
//                     the nearest posed vertex; the template's vertex spacing of ~1 cm is well
//                     below the default distance), i.e. how much of the scan the fit explains;
//   support_fraction: pixels of the template's rendering from the depth camera (its visible,
//                     camera-facing surface) whose observed depth (scan points projected into
//                     the same raster, the median of each pixel's front layer) is within
//                     support_tolerance, i.e. how much of the fit the scan confirms (a model
//                     on the wall or beside the person has none);
//   depth_residual_m: mean truncated |z_model - z_observed| over the union of the template's
//                     silhouette and the scan's foreground; a pixel covered by one of them
//                     only counts depth_truncation.
// All rasters are the depth camera's image subsampled to about raster_width pixels across.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "render/camera.h"
#include "sensors/scan.h"

namespace artex {

enum class FitQualityLabel { kGood, kDoubtful, kLost };
const char* FitQualityLabelName(FitQualityLabel label);  // "good", "doubtful", "lost"

// Label thresholds measured on the virtual Kinect walk at 2.5 m (tests/solvers/
// fit_quality_test.cc): the true subject surface and the tracked fits reach inliers >= 0.97,
// support >= 0.95, residual <= 20 mm (the residual includes the silhouette rims and the
// projector shadow, one-sided pixels); the template upside down on the person, 1 m beside
// it or against the back wall stay at inliers <= 0.29, support <= 0.27, residual >= 79 mm.
struct FitQualityOptions {
  double inlier_distance = 0.025;   // m: a scan point within this of the fit is explained
  int max_scan_points = 3000;       // inlier test on a fixed-stride subsample of the scan
  // Rasters about this many pixels wide: the depth image divided by max(1, round(width /
  // raster_width)) (a subject of a few pixels would make support and residual meaningless).
  int raster_width = 160;
  double support_tolerance = 0.03;  // m: |z_model - z_observed| of a supported pixel
  // A raster pixel's observed depth is the median of its front layer: its scan points, front to
  // back, up to the first gap between consecutive depths wider than this (m; > 0): an arm in
  // front of the torso is observed at the arm, and the sensor noise of the layer averages out.
  double layer_gap = 0.05;
  double depth_truncation = 0.10;   // m: truncation of the depth residual
  // Labels: kLost when any lost_* bound is crossed, else kGood when all good_* bounds hold,
  // else kDoubtful.
  double good_min_inlier_fraction = 0.85;
  double good_min_support_fraction = 0.65;
  double good_max_depth_residual = 0.045;  // m
  double lost_min_inlier_fraction = 0.6;
  double lost_min_support_fraction = 0.45;
  double lost_max_depth_residual = 0.065;  // m
  // Per body part (with `vertex_part`): a part with at least part_min_visible vertices visible
  // from the depth camera (in the image, in front of or on the rendered surface) of which fewer
  // than part_min_support have observed depth within support_tolerance is unsupported: a
  // limb raised into empty space or held in front of the body where the scan is behind it. A
  // frame with an unsupported part is not good (doubtful at best). part_min_support 0: off,
  // the default: a correct forearm in the sensor's dropout band along a depth edge has no
  // observed depth either (docs/real-data.md "Fit quality without ground truth"; 0.25 measured).
  int part_min_visible = 40;
  double part_min_support = 0.0;
  // Joints whose vertices are not checked (FitQualityParts): the feet, whose scan the floor
  // removal takes with the floor.
  std::vector<std::string> part_ignore = {"l_ankle", "r_ankle"};

  bool IsValid(std::string* error) const;
};

struct FitQuality {
  double inlier_fraction = 0.0;   // [0, 1]
  double support_fraction = 0.0;  // [0, 1]; 0 when the template is not visible at all
  double depth_residual_m = 0.0;  // [0, depth_truncation]
  FitQualityLabel label = FitQualityLabel::kLost;
  // Ranking score in [0, 1] (higher is better): the mean of inlier_fraction, support_fraction
  // and 1 - depth_residual_m / depth_truncation.
  double score = 0.0;
  int scan_samples = 0;  // scan points tested for inliers
  int model_pixels = 0;  // rendered template pixels
  int union_pixels = 0;  // pixels of the template's silhouette or the scan's foreground
  int unsupported_parts = 0;  // visible parts without scan support (with vertex_part)
  double seconds = 0.0;

  std::string BriefReport() const;
};

// The per-part map of EvaluateFitQuality for a template: its vertex_joint, with the vertices of
// the joints named in options.part_ignore set to -1 (not checked).
Eigen::VectorXi FitQualityParts(const Eigen::VectorXi& vertex_joint,
                                const std::vector<std::string>& joint_names,
                                const FitQualityOptions& options);

// posed_vertices: V x 3 world (m), triangles: F x 3 (counter-clockwise = outwards); the scan
// and the depth camera (intrinsics and world_to_camera) of the same frame. An empty scan gives
// inlier_fraction 0. vertex_part: null, or V part indices (>= 0; -1: not checked; FitQualityParts)
// for the per-part support. Throws artex::Error on invalid options, a triangle index out of
// range or a vertex_part of the wrong size.
FitQuality EvaluateFitQuality(const Eigen::MatrixX3d& posed_vertices,
                              const Eigen::MatrixX3i& triangles, const Scan& scan,
                              const PinholeCamera& depth_camera, const FitQualityOptions& options,
                              const Eigen::VectorXi* vertex_part = nullptr);

}  // namespace artex
