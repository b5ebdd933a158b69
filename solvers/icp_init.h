// First-frame initialisation (DESIGN.md "First frame"): the template in a predefined pose
// (rest pose by default), pre-aligned to the scan by a similarity transform:
//   1. coarse: yaw from the mean scan normal (the subject faces the camera; the template faces
//      +Z), the initial pose's (nominal) scale or, on request, the ratio of the vertical
//      extents, translation from the centroids of the scan and of the template vertices facing
//      the camera;
//   2. similarity ICP: each (subsampled) scan point paired with its nearest template vertex
//      (distance and normal gated), Umeyama's closed form, iterated. Colour is not used.
// Only the global similarity (scale, translation, rotation) of the pose is changed.
#pragma once

#include <string>

#include "models/pose.h"
#include "models/skinning.h"
#include "sensors/scan.h"

namespace artex {

struct IcpInitOptions {
  bool coarse_alignment = true;   // step 1 (false: start ICP from the given global similarity)
  bool facing_camera = true;      // coarse yaw from the mean scan normal (else keep rotation)
  bool estimate_scale = true;     // scale estimated by Umeyama (else the initial scale, rigid)
  // Coarse scale from the ratio of the scan's and the template's vertical extents (when
  // estimate_scale). Off by default: a person cut by the image border or the depth range
  // (upper body only) has a short extent and got scales of 0.54-0.76; the nominal scale of
  // the initial pose is refined by Umeyama and by the EM fit's free scale instead.
  bool scale_from_extent = false;
  int max_iterations = 40;
  double max_distance = 0.25;     // pair rejection distance (m, world frame)
  double min_normal_dot = 0.3;    // pair rejection: n_scan . n_template below this
  int max_scan_points = 4000;     // scan subsampled by a fixed stride to at most this many
  double tolerance = 1e-5;        // stop when the similarity changes less (m / rad / scale)
  double extent_quantile = 0.01;  // scale_from_extent: extent between this quantile, 1 - it

  bool IsValid(std::string* error) const;
};

struct IcpInitResult {
  Pose pose;            // `initial` with its global similarity replaced
  int iterations = 0;
  int num_pairs = 0;    // pairs of the last iteration
  int num_samples = 0;  // subsampled scan points paired (or rejected) per iteration
  double rms = 0.0;     // RMS pair distance of the last iteration (m)
  bool converged = false;
};

// Throws artex::Error on invalid options, an empty scan or a pose with the wrong joint count.
IcpInitResult AlignByIcp(const Skinning& skinning, const Pose& initial, const Scan& scan,
                         const IcpInitOptions& options);

}  // namespace artex
