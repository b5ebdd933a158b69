// E-step of the EM fitting (paper eq. 3-4, docs/design.md "Fitting energy"): the correspondence
// weights p_st between scan points s and posed template vertices t, reduced per template vertex
// to P_t = sum_s p_st and mu_t = sum_s p_st v_s / P_t (energies/one_to_many_correspondence.h).
//   dense:     every (s, t) pair, O(S T) (the paper's cost; the exact reference)
//   radius:    scan points within a radius of v'_t (kd-tree over the scan, built once per frame);
//              optionally over a voxel-subsampled scan (cell = radius * voxel_fraction) whose
//              cells carry their point count as multiplicity, so large radii stay O(T k)
//   k-nearest: the k nearest scan points of v'_t
// Plus the one-to-one nearest-neighbour search of the articulated ICP baseline.
#pragma once

#include <Eigen/Core>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "energies/one_to_many_correspondence.h"
#include "energies/one_to_one_correspondence.h"
#include "sensors/scan.h"

namespace artex {

enum class EStepMode { kDense, kRadius, kKNearest };
const char* EStepModeName(EStepMode mode);

struct EStepOptions {
  EStepMode mode = EStepMode::kRadius;
  OneToManyOptions weights;  // eps, lambda_c, colour, per-scan-point normalisation
  int k = 8;                 // neighbours per template vertex (kKNearest)
  // kRadius: scan subsampled on a voxel grid of cell radius * voxel_fraction (0: full scan).
  // The weights are smooth at the radius scale, so 0.25 keeps ~50 cells per template vertex.
  double voxel_fraction = 0.25;
  // kRadius: per-frame candidate lists. The first E-step at a radius gathers, per template
  // vertex, the (subsampled) scan points within radius + candidate_margin (m) of its position;
  // later E-steps at that radius only re-weight these candidates. Exact: a block of vertices is
  // gathered again as soon as one of them has moved more than the margin since its gather
  // (the template moves little within a frame, so that is rare). 0: a kd-tree radius search
  // per vertex and E-step.
  double candidate_margin = 0.01;
  // kRadius, voxel_fraction > 0: the subsampled scan's cell (m) for every radius, so that one
  // cloud serves E-steps of several radii (0: radius * voxel_fraction, a cloud per radius).
  double voxel_cell = 0.0;
  // kRadius with candidate lists: lists gathered within list_radius + candidate_margin serve
  // every E-step of a radius up to list_radius (m), so that one gather serves several radii; a
  // vertex keeps its list while it stays within list_radius + candidate_margin - radius of
  // where it was gathered. 0 (or a radius above it): lists per radius, as above.
  double list_radius = 0.0;
  int kdtree_leaf_size = 10;  // nanoflann leaf size
  bool parallel = true;       // TBB over template vertices
  int grain_size = 256;       // template vertices per TBB task

  bool IsValid(std::string* error) const;
};

// kd-tree over an N x 3 point set (copied). Queries are thread-safe.
class PointCloudIndex {
 public:
  // Throws artex::Error for leaf_size < 1.
  explicit PointCloudIndex(const Eigen::MatrixX3d& points, int leaf_size = 10);
  ~PointCloudIndex();
  PointCloudIndex(const PointCloudIndex&) = delete;
  PointCloudIndex& operator=(const PointCloudIndex&) = delete;

  int size() const;
  // Index of the nearest point (-1 when empty) and its squared distance.
  int Nearest(const Eigen::Vector3d& query, double* distance2) const;
  // The same nearest point when its squared distance is below `bound2`, else -1 (distance2:
  // +inf): the search skips every part of the tree farther than the bound, so a tight bound
  // (e.g. the distance to last iteration's nearest point) makes it faster. Ties resolve as in
  // Nearest.
  int NearestWithin(const Eigen::Vector3d& query, double bound2, double* distance2) const;
  // Up to k nearest, ascending; returns how many were written.
  int KNearest(const Eigen::Vector3d& query, int k, int* indices, double* distances2) const;
  // Replaces *out with (index, squared distance) of the points within `radius` (unsorted).
  void Radius(const Eigen::Vector3d& query, double radius,
              std::vector<std::pair<int, double>>* out) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The posed template as the E-step sees it (T rows each).
struct PosedTemplateView {
  const Eigen::MatrixX3d* vertices = nullptr;  // v'_t (m)
  const Eigen::MatrixX3d* normals = nullptr;   // n(v'_t), unit
  const Eigen::MatrixX3d* colors = nullptr;    // rgb(v'_t) in [0,1]; null: colour term off
};

// Exact dense E-step over all pairs (parallel, vectorised). Throws artex::Error on mismatched
// shapes. With weights.normalize_per_scan_point, p_st is divided by sum_t p_st.
void DenseEStep(const Scan& scan, const PosedTemplateView& posed, const OneToManyOptions& options,
                CorrespondenceTargets* targets, bool parallel = true);

// Per-frame correspondence search: builds the kd-trees it needs once (the full scan's, and the
// voxel-subsampled scans' per radius, on first use), then serves E-steps for successive poses.
class EStep {
 public:
  // Throws artex::Error on invalid options or a scan with inconsistent shapes.
  EStep(const Scan& scan, const EStepOptions& options);
  ~EStep();

  const EStepOptions& options() const { return options_; }
  const Scan& scan() const { return scan_; }

  // P_t, mu_t for the posed template; `radius` (m) is used by kRadius only.
  void Compute(const PosedTemplateView& posed, double radius, CorrespondenceTargets* targets);
  // One-to-one nearest scan point per template vertex, gated by options (max distance, normal
  // compatibility n_s . n'_t >= min_normal_dot).
  void FindNearest(const PosedTemplateView& posed, const OneToOneOptions& options,
                   NearestTargets* targets) const;

  // Work counters since construction: neighbour queries (kd-tree radius / k-nearest searches
  // and candidate gathers) and the scan candidates visited by the candidate-list E-steps.
  long long neighbor_queries() const { return neighbor_queries_; }
  long long candidates_visited() const { return candidates_visited_; }

 private:
  struct Cloud;       // a (possibly subsampled) scan with multiplicities and its kd-tree
  struct Candidates;  // per-radius candidate lists (candidate_margin > 0)
  // The cloud of E-steps at `radius`, gathered within gather_radius + candidate_margin; *key
  // (optional) is set to the cloud's key (voxel size, gather radius).
  const Cloud& CloudForRadius(double radius, double gather_radius,
                              std::pair<double, double>* key = nullptr);
  double GatherRadius(double radius) const;  // list_radius when it covers radius, else radius
  const Cloud& FullCloud() const;  // the whole scan, with its kd-tree, built on first use

  Scan scan_;
  EStepOptions options_;
  std::unique_ptr<Cloud> full_;  // the whole scan as a cloud, filled by FullCloud()
  mutable std::once_flag full_index_once_;
  // Keyed by voxel size and gather radius.
  std::map<std::pair<double, double>, std::unique_ptr<Cloud>> subsampled_;
  // Keyed by the cloud (its voxel size and gather radius): lists index their cloud's points.
  std::map<std::pair<double, double>, std::unique_ptr<Candidates>> candidates_;
  long long neighbor_queries_ = 0;
  long long candidates_visited_ = 0;
};

}  // namespace artex
