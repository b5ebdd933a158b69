// First-frame initialisation (docs/fitting.md "Initialisation and fit quality"): the template in
// a predefined pose (rest pose by default), pre-aligned to the scan by a similarity transform:
//   1. coarse: yaw from the mean scan normal (the subject faces the camera; the template faces
//      +Z), the initial pose's (nominal) scale or, on request, the ratio of the vertical
//      extents, translation from the centroids of the scan and of the template vertices facing
//      the camera;
//   2. similarity ICP: each (subsampled) scan point paired with its nearest template vertex
//      (distance and normal gated), Umeyama's closed form, iterated. Colour is not used.
// Only the global similarity (scale, translation, rotation) of the pose is changed.
#pragma once

#include <memory>
#include <string>

#include "models/pose.h"
#include "models/skinning.h"
#include "sensors/scan.h"

namespace artex {

struct IcpInitOptions {
  bool coarse_alignment = true;  // step 1 (false: start ICP from the given global similarity)
  bool facing_camera = true;     // coarse yaw from the mean scan normal (else keep rotation)
  bool estimate_scale = true;    // scale estimated by Umeyama (else the initial scale, rigid)
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
  // Points per leaf of the template's kd-tree (IcpTemplate). Speed only: the nearest vertex is
  // the same. 24 rather than nanoflann's usual 10: the first frame's ICP 11-13 % faster
  // (docs/fitting-speed.md, "The first frame: candidate fits side by side").
  int kd_leaf_size = 24;
  // > 0: the template's nearest-vertex search on a uniform grid of cubic cells of this side
  // (m, template frame; NearestGrid) instead of the kd-tree: the same nearest vertex, under a
  // tenth of the build, but each query's cost grows with (max_distance / grid_cell)^3, so for
  // alignments that start close (the tracker's scale sample, `fitting.scale_sample_grid_cell`).
  double grid_cell = 0.0;

  bool IsValid(std::string* error) const;
};

struct IcpInitResult {
  Pose pose;  // `initial` with its global similarity replaced
  int iterations = 0;
  int num_pairs = 0;    // pairs of the last iteration
  int num_samples = 0;  // subsampled scan points paired (or rejected) per iteration
  double rms = 0.0;     // RMS pair distance of the last iteration (m)
  bool converged = false;
};

class NearestGrid;
class PointCloudIndex;

// The articulated template of a pose without its global similarity (scale 1, no rotation or
// translation): T x 3 vertices and normals and their nearest-neighbour index, posed once and
// shared by every alignment that starts from that articulation (solvers/initializer.h aligns
// several facings of each arm pose).
class IcpTemplate {
 public:
  // The vertices' index: a kd-tree of kd_leaf_size points per leaf, or with grid_cell > 0 a
  // NearestGrid of that cell (IcpInitOptions). Throws artex::Error for a pose with the wrong
  // joint count, kd_leaf_size < 1 or an invalid grid_cell.
  IcpTemplate(const Skinning& skinning, const Pose& articulation, int kd_leaf_size = 24,
              double grid_cell = 0.0);
  ~IcpTemplate();
  const Eigen::MatrixX3d& vertices() const { return vertices_; }
  const Eigen::MatrixX3d& normals() const { return normals_; }
  // PointCloudIndex::NearestWithin over the vertices, by whichever index was built.
  int NearestWithin(const Eigen::Vector3d& query, double bound2, double* distance2) const;
  int num_joints() const { return num_joints_; }

 private:
  Eigen::MatrixX3d vertices_, normals_;
  std::unique_ptr<PointCloudIndex> index_;
  std::unique_ptr<NearestGrid> grid_;
  int num_joints_ = 0;
};

// Throws artex::Error on invalid options, an empty scan or a pose with the wrong joint count.
IcpInitResult AlignByIcp(const Skinning& skinning, const Pose& initial, const Scan& scan,
                         const IcpInitOptions& options);
// The same against a posed template (initial's articulation is taken to be target's).
IcpInitResult AlignByIcp(const IcpTemplate& target, const Pose& initial, const Scan& scan,
                         const IcpInitOptions& options);

}  // namespace artex
