#include "solvers/shape_estimator.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <sstream>
#include <unordered_map>

#include "models/error.h"
#include "models/normals.h"
#include "models/skinning.h"
#include "render/rasterizer.h"
#include "sensors/silhouette.h"

namespace artex {

bool ShapeOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  const auto positive = [](double x) { return std::isfinite(x) && x > 0.0; };
  if (calibration_frames < 1) {
    msg << "shape.calibration_frames: expected >= 1, found " << calibration_frames;
  } else if (calibration_stride < 1) {
    msg << "shape.calibration_stride: expected >= 1, found " << calibration_stride;
  } else if (calibration_rounds < 1) {
    msg << "shape.calibration_rounds: expected >= 1, found " << calibration_rounds;
  } else if (radii.empty() || !std::all_of(radii.begin(), radii.end(), positive)) {
    msg << "shape.radii: expected a non-empty list of radii > 0 (m)";
  } else if (iterations_per_stage < 1) {
    msg << "shape.iterations_per_stage: expected >= 1, found " << iterations_per_stage;
  } else if (!(over_relaxation >= 1.0 && over_relaxation < 2.0)) {
    msg << "shape.over_relaxation: expected a value in [1, 2), found " << over_relaxation;
  } else if (!(visibility_min_cos >= -1.0 && visibility_min_cos < 1.0)) {
    msg << "shape.visibility_min_cos: expected a value in [-1, 1), found " << visibility_min_cos;
  } else if (!(std::isfinite(girth_max_radius) && girth_max_radius > 0.0)) {
    msg << "shape.girth_max_radius: expected a finite value > 0 (m), found " << girth_max_radius;
  } else if (!(std::isfinite(scan_to_model_weight) && scan_to_model_weight >= 0.0)) {
    msg << "shape.scan_to_model_weight: expected a finite value >= 0, found "
        << scan_to_model_weight;
  } else if (!(std::isfinite(scan_to_model_voxel) && scan_to_model_voxel >= 0.0)) {
    msg << "shape.scan_to_model_voxel: expected a finite value >= 0 (m; 0: every point), found "
        << scan_to_model_voxel;
  } else if (!(std::isfinite(scan_to_model_normal_distance) &&
               scan_to_model_normal_distance >= 0.0)) {
    msg << "shape.scan_to_model_normal_distance: expected a finite value >= 0 (m; 0: off), "
        << "found " << scan_to_model_normal_distance;
  } else if (!positive(scan_to_model_max_distance)) {
    msg << "shape.scan_to_model_max_distance: expected a finite value > 0 (m), found "
        << scan_to_model_max_distance;
  } else if (!(std::isfinite(chain_prior_weight) && chain_prior_weight >= 0.0)) {
    msg << "shape.chain_prior_weight: expected a finite value >= 0, found " << chain_prior_weight;
  } else if (!(std::isfinite(bias_mask_tolerance) && bias_mask_tolerance > 0.0)) {
    msg << "shape.bias_mask_tolerance: expected a finite value > 0 (m), found "
        << bias_mask_tolerance;
  } else if (bias_mask_radius_px < 0 || bias_mask_radius_px > 8) {
    msg << "shape.bias_mask_radius_px: expected 0..8, found " << bias_mask_radius_px;
  } else if (!(std::isfinite(bias_rendered_estep_max_radius) &&
               bias_rendered_estep_max_radius >= 0.0)) {
    msg << "shape.bias_rendered_estep_max_radius: expected a finite value >= 0 (m; 0: never), "
           "found "
        << bias_rendered_estep_max_radius;
  } else if (!(std::isfinite(floor_weight) && floor_weight >= 0.0)) {
    msg << "shape.floor_weight: expected a finite value >= 0 (0: off), found " << floor_weight;
  } else if (!(std::isfinite(limb_girth_prior_weight) && limb_girth_prior_weight >= 0.0)) {
    msg << "shape.limb_girth_prior_weight: expected a finite value >= 0, found "
        << limb_girth_prior_weight;
  } else if (!(std::isfinite(depth_prior_weight) && depth_prior_weight >= 0.0)) {
    msg << "shape.depth_prior_weight: expected a finite value >= 0, found " << depth_prior_weight;
  } else if (!(std::isfinite(prior_weight) && prior_weight >= 0.0)) {
    msg << "shape.prior_weight: expected a finite value >= 0, found " << prior_weight;
  } else if (!(std::isfinite(pose_damping) && pose_damping >= 0.0)) {
    msg << "shape.pose_damping: expected a finite value >= 0, found " << pose_damping;
  } else if (!(positive(bone_min) && bone_min <= 1.0 && std::isfinite(bone_max) &&
               bone_max >= 1.0)) {
    msg << "shape.bone_min/bone_max: expected 0 < bone_min <= 1 <= bone_max, found " << bone_min
        << ", " << bone_max;
  } else if (!(positive(girth_min) && girth_min <= 1.0 && std::isfinite(girth_max) &&
               girth_max >= 1.0)) {
    msg << "shape.girth_min/girth_max: expected 0 < girth_min <= 1 <= girth_max, found "
        << girth_min << ", " << girth_max;
  } else if (refine_every < 0) {
    msg << "shape.refine_every: expected >= 0 (0: frozen), found " << refine_every;
  } else if (!(std::isfinite(refine_prior_weight) && refine_prior_weight >= 0.0)) {
    msg << "shape.refine_prior_weight: expected a finite value >= 0, found " << refine_prior_weight;
  } else if (max_fit_vertices < 0) {
    msg << "shape.max_fit_vertices: expected >= 0 (0: all), found " << max_fit_vertices;
  } else if (!estep.IsValid(error)) {
    if (error) *error = "shape.estep: " + *error;
    return false;
  } else if (!detail.IsValid(error)) {
    return false;
  }
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

namespace {
// Mean point per occupied cubic cell of side `cell` (all points when cell <= 0); with
// `normals` (one per point) and `mean_normals`, also each cell's mean normal, normalised.
Eigen::MatrixX3d VoxelMeans(const Eigen::MatrixX3d& points, double cell,
                            const Eigen::MatrixX3d* normals = nullptr,
                            Eigen::MatrixX3d* mean_normals = nullptr) {
  const bool with_normals =
      normals != nullptr && mean_normals != nullptr && normals->rows() == points.rows();
  if (mean_normals != nullptr) mean_normals->resize(0, 3);
  if (!(cell > 0.0)) {
    if (with_normals) *mean_normals = *normals;
    return points;
  }
  std::unordered_map<std::int64_t, int> slot;
  std::vector<Eigen::Vector3d> sum, normal_sum;
  std::vector<int> count;
  for (int k = 0; k < points.rows(); ++k) {
    const Eigen::Vector3d p = points.row(k).transpose();
    const auto key = [&](int a) {
      return static_cast<std::int64_t>(std::floor(p[a] / cell)) & 0x1fffff;
    };
    const std::int64_t id = key(0) | key(1) << 21 | key(2) << 42;
    const auto [it, inserted] = slot.emplace(id, static_cast<int>(sum.size()));
    if (inserted) {
      sum.push_back(Eigen::Vector3d::Zero());
      normal_sum.push_back(Eigen::Vector3d::Zero());
      count.push_back(0);
    }
    sum[it->second] += p;
    if (with_normals) normal_sum[it->second] += normals->row(k).transpose();
    ++count[it->second];
  }
  Eigen::MatrixX3d out(sum.size(), 3);
  for (size_t c = 0; c < sum.size(); ++c) out.row(c) = sum[c].transpose() / count[c];
  if (with_normals) {
    mean_normals->resize(sum.size(), 3);
    for (size_t c = 0; c < sum.size(); ++c) {
      const double norm = normal_sum[c].norm();
      mean_normals->row(c).setZero();
      if (norm > 0.0) mean_normals->row(c) = normal_sum[c].transpose() / norm;
    }
  }
  return out;
}

// bias_scan_mask: the frame's free-space map (scan.silhouette) shows, at x's pixel, a surface
// other than the subject's behind x, or no surface where zero depth means free space: the
// camera would have seen x there. Such a vertex is the fit's error, not a hole of the sensor,
// and stays in the self E-step.
bool OverFreeSpace(const Scan& scan, const Eigen::Vector3d& x) {
  if (!scan.silhouette) return false;
  const SilhouetteMap& map = *scan.silhouette;
  double z = 0.0;
  const Eigen::Vector2d px = map.camera.Project(x, &z);
  if (!(z > 0.0)) return false;
  const int i = map.RasterIndex(px.x(), px.y());
  return i >= 0 && map.free_depth[i] > z;
}

// A fixed pseudo-random number in [0, 1) per index (splitmix64).
double Uniform01(std::uint64_t i) {
  std::uint64_t z = i + 0x9e3779b97f4a7c15ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  z ^= z >> 31;
  return static_cast<double>(z >> 11) * 0x1.0p-53;
}

// The bias correction's self scan from the posed template's vertices: those facing the depth
// camera (visibility_min_cos; all without a camera), each kept with probability cos(angle to
// the view ray) (bias_density), and where `keep` (the scan mask) says the sensor saw them.
template <typename Keep>
void VertexSelfScan(const Eigen::MatrixX3d& posed, const Eigen::MatrixX3d& normals,
                    const ShapeOptions& options, bool has_camera, const Eigen::Vector3d& eye,
                    const Keep& keep, Scan* out) {
  std::vector<int> visible;
  for (int v = 0; v < posed.rows(); ++v) {
    const Eigen::Vector3d x = posed.row(v).transpose();
    const double facing = has_camera ? normals.row(v).dot((eye - x).normalized()) : 1.0;
    if (facing <= options.visibility_min_cos) continue;
    // A depth camera samples a surface with a density ~ cos(angle to the view ray); the
    // template's vertices are uniform: keep each with that probability (a fixed pseudo-random
    // number per vertex) so the self E-step sees the scan's sampling.
    if (options.bias_density && has_camera && Uniform01(v) > facing) continue;
    if (!keep(x)) continue;
    visible.push_back(v);
  }
  const int n = static_cast<int>(visible.size());
  out->points.resize(n, 3);
  out->normals.resize(n, 3);
  for (int k = 0; k < n; ++k) {
    out->points.row(k) = posed.row(visible[k]);
    out->normals.row(k) = normals.row(visible[k]);
  }
  out->colors = Eigen::MatrixX3d::Zero(n, 3);
  out->color_valid.assign(n, 0);
}

// The self scan as `camera` samples the posed template: every pixel of its z-buffer,
// back-projected, the normal interpolated from the hit triangle's vertex normals, kept when it
// faces the camera by more than min_cos and `keep` (the scan mask) says the sensor saw it.
// `raster` is scratch space.
template <typename Keep>
void RenderedSelfScan(const Eigen::MatrixX3d& posed, const Eigen::MatrixX3d& normals,
                      const Eigen::MatrixX3i& triangles, const PinholeCamera& camera,
                      double min_cos, const Keep& keep, RasterBuffers* raster, Scan* out) {
  Rasterize(posed, triangles, camera, RasterOptions(), raster);
  const Eigen::Vector3d eye = camera.Center();
  // Rows in parallel, each into its own list; concatenated in row order.
  std::vector<std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>>> rows(raster->height);
  tbb::parallel_for(tbb::blocked_range<int>(0, raster->height, 16), [&](const auto& range) {
    for (int v = range.begin(); v < range.end(); ++v) {
      for (int u = 0; u < raster->width; ++u) {
        const int p = raster->index(u, v);
        if (!std::isfinite(raster->depth[p])) continue;
        const int t = raster->triangle_id[p];
        const Eigen::Vector2f b = raster->barycentric[p];
        const Eigen::Vector3d sum =
            (1.0 - b.x() - b.y()) * normals.row(triangles(t, 0)).transpose() +
            b.x() * normals.row(triangles(t, 1)).transpose() +
            b.y() * normals.row(triangles(t, 2)).transpose();
        if (!(sum.norm() > 0.0)) continue;
        const Eigen::Vector3d normal = sum.normalized();
        const Eigen::Vector3d x = camera.Unproject(u, v, raster->depth[p]);
        if (normal.dot((eye - x).normalized()) <= min_cos || !keep(x)) continue;
        rows[v].emplace_back(x, normal);
      }
    }
  });
  int n = 0;
  for (const auto& row : rows) n += static_cast<int>(row.size());
  out->points.resize(n, 3);
  out->normals.resize(n, 3);
  int k = 0;
  for (const auto& row : rows) {
    for (const auto& [x, normal] : row) {
      out->points.row(k) = x.transpose();
      out->normals.row(k) = normal.transpose();
      ++k;
    }
  }
  out->colors = Eigen::MatrixX3d::Zero(n, 3);
  out->color_valid.assign(n, 0);
}

// Per point of `index` (the fit vertices): how many of `samples` have it as their nearest
// (within sqrt(max_d2)) and their sum. With `normal_distance` s > 0, a sample p's nearest is
// the one of its kNormalCandidates nearest vertices x minimising |p - x|^2 + s^2 |n_p - n_x|^2
// (normals `sample_normals`, `vertex_normals`), the distance of x being the one compared
// with max_d2.
constexpr int kNormalCandidates = 8;
void NearestSums(const PointCloudIndex& index, const Eigen::MatrixX3d& samples, double max_d2,
                 std::vector<double>* count, Eigen::MatrixX3d* sum,
                 const Eigen::MatrixX3d* sample_normals = nullptr,
                 const Eigen::MatrixX3d* vertex_normals = nullptr, double normal_distance = 0.0) {
  count->assign(index.size(), 0.0);
  sum->setZero(index.size(), 3);
  const bool by_normal = normal_distance > 0.0 && sample_normals != nullptr &&
                         sample_normals->rows() == samples.rows() && vertex_normals != nullptr;
  const double s2 = normal_distance * normal_distance;
  std::array<int, kNormalCandidates> ids;
  std::array<double, kNormalCandidates> d2s;
  double d2 = 0.0;
  for (int k = 0; k < samples.rows(); ++k) {
    const Eigen::Vector3d p = samples.row(k).transpose();
    int i = -1;
    if (!by_normal) {
      i = index.Nearest(p, &d2);
    } else {
      const int found = index.KNearest(p, kNormalCandidates, ids.data(), d2s.data());
      const Eigen::RowVector3d n = sample_normals->row(k);
      double best = std::numeric_limits<double>::infinity();
      for (int c = 0; c < found; ++c) {
        const double e = d2s[c] + s2 * (vertex_normals->row(ids[c]) - n).squaredNorm();
        if (e < best) {
          best = e;
          i = ids[c];
          d2 = d2s[c];
        }
      }
    }
    if (i < 0 || d2 > max_d2) continue;
    (*count)[i] += 1.0;
    sum->row(i) += p.transpose();
  }
}

ShapeOptions Checked(const ShapeOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw Error(error);
  return options;
}
}  // namespace

void ScanToModelSums(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3d& vertex_normals,
                     const Eigen::MatrixX3d& samples, const Eigen::MatrixX3d& sample_normals,
                     double max_distance, double normal_distance, std::vector<double>* count,
                     Eigen::MatrixX3d* sum) {
  const PointCloudIndex index(vertices);
  NearestSums(index, samples, max_distance * max_distance, count, sum, &sample_normals,
              &vertex_normals, normal_distance);
}

ShapeEstimator::ShapeEstimator(const Template& base, const ShapeOptions& options)
    : options_(Checked(options)),
      model_(base, options.mode, options.symmetric, options.leaf_lengths, options.fork_widths,
             options.girth_depth) {
  q_ = Eigen::VectorXd::Zero(model_.num_parameters());
  const int v = base.num_vertices();
  const int stride = options_.max_fit_vertices > 0 && v > options_.max_fit_vertices
                         ? (v + options_.max_fit_vertices - 1) / options_.max_fit_vertices
                         : 1;
  for (int i = 0; i < v; i += stride) fit_vertices_.push_back(i);
  // Chain prior: bone j and the bone continuing it (the child stretching segment j) when the
  // two are collinear (cosine >= 0.9 of their rest offsets): thigh/shank, upper arm/forearm,
  // spine/chest/neck/head, not the lateral hip or shoulder offsets.
  const int nj = base.num_joints();
  std::vector<std::pair<int, int>> pairs;
  for (int j = 1; j < nj; ++j) {
    const Eigen::Vector3d bone = base.joints[j].center - base.joints[base.joints[j].parent].center;
    for (int c = j + 1; c < nj; ++c) {
      if (base.joints[c].parent != j) continue;
      const Eigen::Vector3d next = base.joints[c].center - base.joints[j].center;
      if (bone.norm() > 0.0 && next.norm() > 0.0 &&
          bone.dot(next) >= 0.9 * bone.norm() * next.norm()) {
        pairs.emplace_back(j, c);
      }
    }
  }
  chain_ = Eigen::MatrixXd::Zero(static_cast<int>(pairs.size()), model_.num_parameters());
  for (size_t k = 0; k < pairs.size(); ++k) {
    chain_.row(k) = model_.expansion().row(pairs[k].first) - model_.expansion().row(pairs[k].second);
  }
  // Limb girth pairs: a collinear pair (j, c) whose bone j leaves a fork (the bone ending at
  // j's parent is not collinear with it: hip, shoulder) joins segment parent(j), which spans
  // bone j, and segment j, which spans bone c (thigh and shank, upper arm and forearm).
  std::vector<std::pair<int, int>> limbs;
  for (const auto& [j, c] : pairs) {
    const int p = base.joints[j].parent;
    if (p <= 0) continue;  // bone j leaves the root: the trunk
    bool fork = true;
    for (const auto& [a, b] : pairs) fork = fork && !(a == p && b == j);
    if (fork) limbs.emplace_back(p, j);
  }
  limb_girth_ = Eigen::MatrixXd::Zero(static_cast<int>(limbs.size()), model_.num_parameters());
  for (size_t k = 0; k < limbs.size(); ++k) {
    limb_girth_.row(k) = model_.expansion().row(nj + limbs[k].first) -
                         model_.expansion().row(nj + limbs[k].second);
  }
}

ShapeEstimator::~ShapeEstimator() = default;

void ShapeEstimator::Bounds(int p, double* lo, double* hi) const {
  const int nj = model_.base().num_joints();
  const Eigen::MatrixXd& e = model_.expansion();
  // A parameter moves girth rows only (bones_girth's girths) or length rows: bones (also
  // kScale) or leaf segments.
  bool bone = false;
  for (int r = 0; r < nj; ++r) {
    bone = bone || e(r, p) != 0.0 || e(2 * nj + r, p) != 0.0 || e(3 * nj + r, p) != 0.0;
  }
  *lo = (bone ? options_.bone_min : options_.girth_min) - 1.0;
  *hi = (bone ? options_.bone_max : options_.girth_max) - 1.0;
}

void ShapeEstimator::ClampToBounds(Eigen::VectorXd* q) const {
  for (int p = 0; p < q->size(); ++p) {
    double lo = 0.0, hi = 0.0;
    Bounds(p, &lo, &hi);
    (*q)[p] = std::clamp((*q)[p], lo, hi);
  }
}

std::vector<std::string> ShapeEstimator::ParametersAtBounds() const {
  std::vector<std::string> names;
  for (int p = 0; p < q_.size(); ++p) {
    double lo = 0.0, hi = 0.0;
    Bounds(p, &lo, &hi);
    if (q_[p] <= lo + 1e-9 || q_[p] >= hi - 1e-9) names.push_back(model_.parameter_names()[p]);
  }
  return names;
}

void ShapeEstimator::SetDepthCamera(const PinholeCamera& camera,
                                    const OutOfViewOptions& out_of_view) {
  depth_camera_ = camera;
  out_of_view_ = out_of_view;
  has_depth_camera_ = true;
}

void ShapeEstimator::SetFloor(const Eigen::Vector3d& normal, double offset) {
  if (!normal.allFinite() || !(normal.norm() > 1e-9) || !std::isfinite(offset)) {
    throw Error("shape floor: expected a finite plane with a non-zero normal");
  }
  floor_normal_ = normal.normalized();
  floor_offset_ = offset / normal.norm();
  has_floor_ = true;
}

std::vector<int> ShapeEstimator::UnseenParameters(const std::vector<Pose>& poses) const {
  std::vector<int> unseen;
  const int nq = model_.num_parameters();
  if (!options_.hold_unseen || !has_depth_camera_ || !out_of_view_.enabled() || poses.empty() ||
      nq == 0) {
    return unseen;
  }
  const Template shaped = model_.Apply(q_);
  const Skinning skinning(shaped, SkinningOptions());
  const int nj = shaped.num_joints();
  std::vector<int> parents(nj);
  for (int j = 0; j < nj; ++j) parents[j] = shaped.joints[j].parent;
  const Eigen::MatrixXd& e = model_.expansion();
  std::vector<bool> seen(nq, false);
  Eigen::MatrixX3d posed, centers;
  for (const Pose& pose : poses) {
    skinning.Apply(pose, &posed);
    skinning.PosedJointCenters(pose, &centers);
    std::vector<bool> held(nj, false);
    for (int j : OutOfViewJoints(posed, shaped.vertex_joint, centers, parents, depth_camera_,
                                 out_of_view_)) {
      held[j] = true;
    }
    for (int row = 0; row < e.rows(); ++row) {
      // Rows: bone lengths, girths, leaf lengths, fork widths, depth factors (models/shape.h).
      const int kind = row / nj, j = row % nj;
      const bool bone = kind == 0 || kind == 3;
      const bool row_seen = !held[j] && !(bone && parents[j] >= 0 && held[parents[j]]);
      if (!row_seen) continue;
      for (int p = 0; p < nq; ++p) seen[p] = seen[p] || e(row, p) != 0.0;
    }
  }
  for (int p = 0; p < nq; ++p) {
    if (!seen[p]) unseen.push_back(p);
  }
  return unseen;
}

ShapeSolveSummary ShapeEstimator::Solve(const std::vector<const Scan*>& scans,
                                        std::vector<Pose>* poses, const Eigen::VectorXd& q_ref,
                                        double prior_weight) {
  const auto start = std::chrono::steady_clock::now();
  ShapeSolveSummary summary;
  const int nf = static_cast<int>(scans.size());
  summary.frames = nf;
  if (nf == 0 || static_cast<int>(poses->size()) != nf || model_.num_parameters() == 0) {
    return summary;
  }
  const Template& base = model_.base();
  const int nq = model_.num_parameters();
  const int np = base.num_pose_parameters();
  const int dim = nq + nf * np;
  const int n = static_cast<int>(fit_vertices_.size());
  std::vector<std::unique_ptr<EStep>> esteps;
  EStepOptions estep_options = options_.estep;
  estep_options.mode = EStepMode::kRadius;
  for (const Scan* s : scans) esteps.push_back(std::make_unique<EStep>(*s, estep_options));
  const bool scan_to_model = options_.scan_to_model_weight > 0.0;
  std::vector<Eigen::MatrixX3d> scan_samples(nf), scan_sample_normals(nf);
  if (scan_to_model) {
    for (int f = 0; f < nf; ++f) {
      scan_samples[f] = VoxelMeans(scans[f]->points, options_.scan_to_model_voxel,
                                   &scans[f]->normals, &scan_sample_normals[f]);
    }
  }
  const double max_d2 = options_.scan_to_model_max_distance * options_.scan_to_model_max_distance;
  // Floor term: per fit vertex below the floor, relative to the data term (normalised per frame);
  // not when the scans lie below that floor.
  bool floor = has_floor_ && options_.floor_weight > 0.0 && n > 0;
  if (floor) {
    std::size_t below = 0, total = 0;
    for (const Scan* scan : scans) {
      const Eigen::VectorXd height =
          scan->points * floor_normal_ + Eigen::VectorXd::Constant(scan->size(), floor_offset_);
      below += static_cast<std::size_t>((height.array() < -kFloorBelowMargin).count());
      total += static_cast<std::size_t>(scan->size());
    }
    if (static_cast<double>(below) > kFloorMaxBelowFraction * static_cast<double>(total)) {
      floor = false;
      floor_contradicted_ = true;
    }
  }
  const double floor_weight = floor ? options_.floor_weight / n : 0.0;
  std::vector<double> reverse_count, self_count;
  Eigen::MatrixX3d reverse_sum, self_sum;
  const Eigen::MatrixXd ete = model_.expansion().transpose() * model_.expansion();

  SkinningOptions serial;
  Eigen::MatrixX3d posed, normals, sub_posed(n, 3), sub_normals(n, 3);
  SkinningJacobian jacobian;
  Eigen::MatrixXd shape_jacobian;
  CorrespondenceTargets targets, self_targets;
  // Columns of q that move girths only (held at wide radii).
  std::vector<int> girth_columns;
  for (int p = 0; p < nq; ++p) {
    if (model_.IsGirthParameter(p)) girth_columns.push_back(p);
  }
  // Columns of q the frames do not show (hold_unseen), held throughout.
  summary.held_unseen = UnseenParameters(*poses);
  const Eigen::Vector3d camera_center = depth_camera_.Center();
  // bias_scan_mask: per frame the nearest scan depth at each depth pixel (+inf: none).
  std::vector<std::vector<float>> seen(
      options_.bias_correction && options_.bias_scan_mask && has_depth_camera_ ? nf : 0);
  const int width = depth_camera_.width, height = depth_camera_.height;
  for (size_t f = 0; f < seen.size(); ++f) {
    seen[f].assign(static_cast<std::size_t>(width) * height,
                   std::numeric_limits<float>::infinity());
    for (int i = 0; i < scans[f]->size(); ++i) {
      double z = 0.0;
      const Eigen::Vector2d px = depth_camera_.Project(scans[f]->points.row(i).transpose(), &z);
      const long u = std::lround(px.x()), v = std::lround(px.y());
      if (!(z > 0.0) || u < 0 || v < 0 || u >= width || v >= height) continue;
      float& cell = seen[f][static_cast<std::size_t>(v) * width + u];
      cell = std::min(cell, static_cast<float>(z));
    }
  }
  // The frame's depth image has a point near x (pixel and depth): bias_scan_mask.
  const auto seen_near = [&](int f, const Eigen::Vector3d& x) {
    double z = 0.0;
    const Eigen::Vector2d px = depth_camera_.Project(x, &z);
    if (!(z > 0.0)) return false;
    const long u = std::lround(px.x()), v = std::lround(px.y());
    const int r = options_.bias_mask_radius_px;
    for (long y = std::max(0L, v - r); y <= std::min<long>(height - 1, v + r); ++y) {
      for (long c = std::max(0L, u - r); c <= std::min<long>(width - 1, u + r); ++c) {
        if (std::abs(seen[f][static_cast<std::size_t>(y) * width + c] - z) <=
            options_.bias_mask_tolerance) {
          return true;
        }
      }
    }
    return false;
  };
  RasterBuffers raster;  // the rendered self scans' scratch space
  bool first = true;
  for (double radius : options_.radii) {
    for (int it = 0; it < options_.iterations_per_stage; ++it) {
      const Template shaped = model_.Apply(q_);
      const Skinning skinning(shaped, serial);
      Eigen::MatrixXd h = Eigen::MatrixXd::Zero(dim, dim);
      Eigen::VectorXd g = Eigen::VectorXd::Zero(dim);
      double cost = 0.0;
      for (int f = 0; f < nf; ++f) {
        const Pose& pose = (*poses)[f];
        skinning.ApplyWithJacobian(pose, &posed, &jacobian);
        ComputeVertexNormals(posed, shaped.triangles, &normals);
        for (int i = 0; i < n; ++i) {
          sub_posed.row(i) = posed.row(fit_vertices_[i]);
          sub_normals.row(i) = normals.row(fit_vertices_[i]);
        }
        PosedTemplateView view;
        view.vertices = &sub_posed;
        view.normals = &sub_normals;
        esteps[f]->Compute(view, radius, &targets);
        const double total = targets.total_weight();
        if (!(total > 0.0)) continue;
        // The self scans (bias_correction): the camera-facing template vertices, or the
        // template as the depth camera samples it (bias_rendered_*), where the sensor saw it.
        const auto keep = [&](const Eigen::Vector3d& x) {
          return seen.empty() || seen_near(f, x) || OverFreeSpace(*scans[f], x);
        };
        const auto self_scan = [&](bool rendered, Scan* out) {
          if (rendered && has_depth_camera_) {
            RenderedSelfScan(posed, normals, shaped.triangles, depth_camera_,
                             options_.visibility_min_cos, keep, &raster, out);
          } else {
            VertexSelfScan(posed, normals, options_, has_depth_camera_, camera_center, keep, out);
          }
        };
        // The scan-to-model term's self scan differs from the E-step's (else it is that one).
        Scan self, self_other;
        const bool estep_rendered = radius <= options_.bias_rendered_estep_max_radius;
        const bool separate = has_depth_camera_ && estep_rendered !=
                                                       options_.bias_rendered_scan_to_model;
        if (options_.bias_correction) {
          self_scan(estep_rendered, &self);
          EStep self_estep(self, estep_options);
          self_estep.Compute(view, radius, &self_targets);
          for (int i = 0; i < n; ++i) {
            if (targets.weight[i] > 0.0 && self_targets.weight[i] > 0.0) {
              targets.mean.row(i) -= self_targets.mean.row(i) - sub_posed.row(i);
            }
          }
        }
        // Scan-to-model: each scan sample's nearest fit vertex; per vertex the count and sum.
        reverse_count.assign(n, 0.0);
        reverse_sum.setZero(n, 3);
        double c_reverse = 0.0;
        if (scan_to_model && scan_samples[f].rows() > 0) {
          const PointCloudIndex index(sub_posed);
          const double normal_distance = options_.scan_to_model_normal_distance;
          NearestSums(index, scan_samples[f], max_d2, &reverse_count, &reverse_sum,
                      &scan_sample_normals[f], &sub_normals, normal_distance);
          if (options_.bias_correction) {
            // The same bias as the E-step's: a one-sided scan's samples pull a limb's side
            // vertices towards the camera and inwards. Measured on the template's own
            // camera-facing surface (sampled alike) and subtracted: the truth is a fixed point.
            if (separate) self_scan(options_.bias_rendered_scan_to_model, &self_other);
            const Scan& source = separate ? self_other : self;
            Eigen::MatrixX3d self_normals;
            const Eigen::MatrixX3d self_samples = VoxelMeans(
                source.points, options_.scan_to_model_voxel, &source.normals, &self_normals);
            NearestSums(index, self_samples, max_d2, &self_count, &self_sum, &self_normals,
                        &sub_normals, normal_distance);
            for (int i = 0; i < n; ++i) {
              if (reverse_count[i] > 0.0 && self_count[i] > 0.0) {
                reverse_sum.row(i) -= reverse_count[i] * (self_sum.row(i) / self_count[i] -
                                                          sub_posed.row(i));
              }
            }
          }
          c_reverse = options_.scan_to_model_weight / scan_samples[f].rows();
        }
        const double c = 1.0 / total;
        model_.PosedJacobian(pose, fit_vertices_, &shape_jacobian);
        const int offset = nq + f * np;
        std::vector<int> index;
        Eigen::Matrix<double, 3, Eigen::Dynamic> local;
        for (int i = 0; i < n; ++i) {
          const double w1 = c * targets.weight[i];
          const double w2 = c_reverse * reverse_count[i];
          const double w = (w1 > 0.0 ? w1 : 0.0) + w2;
          // Floor term: the vertex's signed height above the floor, when below it.
          const double height =
              floor ? floor_normal_.dot(sub_posed.row(i).transpose()) + floor_offset_ : 0.0;
          const bool below = height < 0.0;
          if (!(w > 0.0) && !below) continue;
          const int v = fit_vertices_[i];
          const std::vector<int>& cols = jacobian.Columns(v);
          const auto block = jacobian.Block(v);
          const int m = nq + static_cast<int>(cols.size()) - 1;  // the scale column is held
          local.resize(3, m);
          index.resize(m);
          local.leftCols(nq) = shape_jacobian.middleRows<3>(3 * i);
          for (int p = 0; p < nq; ++p) index[p] = p;
          for (size_t k = 1; k < cols.size(); ++k) {
            local.col(nq + k - 1) = block.col(k);
            index[nq + k - 1] = offset + cols[k];
          }
          const Eigen::Vector3d x = posed.row(v).transpose();
          const auto accumulate = [&](double weight, const Eigen::Vector3d& e,
                                      const Eigen::Matrix<double, 3, Eigen::Dynamic>& jac) {
            const Eigen::MatrixXd jtj = weight * jac.transpose() * jac;
            const Eigen::VectorXd jte = weight * jac.transpose() * e;
            for (int a = 0; a < m; ++a) {
              g[index[a]] += jte[a];
              for (int b = 0; b < m; ++b) h(index[a], index[b]) += jtj(a, b);
            }
            cost += weight * e.squaredNorm();
          };
          if (w1 > 0.0) accumulate(w1, x - targets.mean.row(i).transpose(), local);
          if (below) {  // w_f h^2 with h = n . x + offset: the residual n h, the Jacobian n n^T J
            const Eigen::Vector3d& up = floor_normal_;
            accumulate(floor_weight, up * height, up * (up.transpose() * local));
          }
          if (w2 > 0.0) {
            const Eigen::Vector3d b = reverse_sum.row(i).transpose() / reverse_count[i];
            if (options_.scan_to_model_girth) {
              accumulate(w2, x - b, local);
            } else {
              Eigen::Matrix<double, 3, Eigen::Dynamic> held = local;
              for (int p : girth_columns) held.col(p).setZero();
              accumulate(w2, x - b, held);
            }
          }
        }
      }
      const Eigen::VectorXd dq = q_ - q_ref;
      cost += prior_weight * dq.dot(ete * dq);
      h.topLeftCorner(nq, nq) += prior_weight * ete;
      g.head(nq) += prior_weight * ete * dq;
      if (options_.depth_prior_weight > 0.0) {
        // w |q_p|^2 per depth parameter: towards the template's cross-section proportions.
        for (int p = 0; p < nq; ++p) {
          if (!model_.IsDepthParameter(p)) continue;
          cost += options_.depth_prior_weight * q_[p] * q_[p];
          h(p, p) += options_.depth_prior_weight;
          g[p] += options_.depth_prior_weight * q_[p];
        }
      }
      // w |M q|^2 over the shape parameters.
      const auto difference_prior = [&](double w, const Eigen::MatrixXd& m) {
        if (!(w > 0.0) || m.rows() == 0) return;
        const Eigen::VectorXd d = m * q_;
        cost += w * d.squaredNorm();
        h.topLeftCorner(nq, nq) += w * m.transpose() * m;
        g.head(nq) += w * m.transpose() * d;
      };
      // Differences of collinear bones' length factors; of a limb's two segments' girths.
      difference_prior(options_.chain_prior_weight, chain_);
      difference_prior(options_.limb_girth_prior_weight, limb_girth_);
      for (int f = 0; f < nf; ++f) {
        const int offset = nq + f * np;
        if (!pose_priors_.empty()) {
          // The tracker's pose priors at the frame's pose (tangent delta 0).
          FitEvaluation eval;
          PrepareFitEvaluation(nullptr, (*poses)[f], Eigen::VectorXd::Zero(np), false, false,
                               &eval);
          for (const auto& term : pose_priors_) {
            const int rows = term->num_residuals();
            Eigen::VectorXd r(rows);
            Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> j(rows, np);
            if (!term->Evaluate(eval, r.data(), j.data())) continue;
            cost += r.squaredNorm();
            h.block(offset, offset, np, np) += j.transpose() * j;
            g.segment(offset, np) += j.transpose() * r;
          }
        }
        for (int p = 1; p < np; ++p) h(offset + p, offset + p) += options_.pose_damping;
        h(offset + kScaleIndex, offset + kScaleIndex) = 1.0;  // held: no data, no update
        g[offset + kScaleIndex] = 0.0;
      }
      const auto hold = [&](int p) {
        h.row(p).setZero();
        h.col(p).setZero();
        h(p, p) = 1.0;
        g[p] = 0.0;
      };
      if (radius > options_.girth_max_radius) {
        for (int p : girth_columns) hold(p);
      }
      for (int p : summary.held_unseen) hold(p);
      for (int d = 0; d < dim; ++d) h(d, d) += 1e-4 * h(d, d) + 1e-12;  // Marquardt
      if (!std::isfinite(cost) || !g.allFinite()) break;
      const Eigen::VectorXd step = -options_.over_relaxation * h.ldlt().solve(g);
      if (!step.allFinite()) break;
      if (first) summary.initial_cost = cost;
      first = false;
      summary.final_cost = cost;
      ++summary.iterations;
      q_ += step.head(nq);
      ClampToBounds(&q_);
      for (int f = 0; f < nf; ++f) (*poses)[f].Retract(step.segment(nq + f * np, np));
      if (step.cwiseAbs().maxCoeff() < 1e-5) break;
    }
  }
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

Template ShapeEstimator::SubjectTemplate() const {
  Template shaped = model_.Apply(q_);
  if (detail_.size() == 0) return shaped;
  return ApplySurfaceDetail(shaped, detail_);
}

bool ShapeEstimator::DetailPending() const {
  return calibrated_ && options_.detail.enabled && has_depth_camera_ && detail_.size() == 0;
}

bool ShapeEstimator::KeepsNextFrame(bool scale_settled) const {
  if (!enabled()) return false;
  if (!calibrated_) return scale_settled && accepted_ % options_.calibration_stride == 0;
  if (DetailPending()) return accepted_ % options_.calibration_stride == 0;
  return options_.refine_every > 0 && (after_ + 1) % options_.refine_every == 0;
}

bool ShapeEstimator::AddFrame(const Scan& scan, const Pose& pose, bool scale_settled,
                              Pose* refined) {
  if (!enabled()) return false;
  // Which frames are kept is KeepsNextFrame's rule; here the counters it reads advance.
  const bool keep = KeepsNextFrame(scale_settled);
  if (!calibrated_) {
    if (!scale_settled) return false;
    ++accepted_;
    if (!keep) return false;
    scans_.push_back(scan);
    poses_.push_back(pose);
    if (static_cast<int>(scans_.size()) < options_.calibration_frames) return false;
    std::vector<const Scan*> pointers;
    for (const Scan& s : scans_) pointers.push_back(&s);
    const ShapeSolveSummary round =
        Solve(pointers, &poses_, Eigen::VectorXd::Zero(q_.size()), options_.prior_weight);
    unseen_names_.clear();
    for (int p : round.held_unseen) unseen_names_.push_back(model_.parameter_names()[p]);
    if (rounds_done_ == 0) calibration_.initial_cost = round.initial_cost;
    calibration_.final_cost = round.final_cost;
    calibration_.frames += round.frames;
    calibration_.iterations += round.iterations;
    calibration_.seconds += round.seconds;
    calibrated_ = ++rounds_done_ >= options_.calibration_rounds;
    accepted_ = 0;
    if (refined) *refined = poses_.back();
    // The last round's frames, their poses refined with the final shape, are the surface
    // detail's first frames.
    if (DetailPending()) {
      EstimateDetailWhenDue();
    } else {
      scans_.clear();
      poses_.clear();
    }
    return true;
  }
  if (DetailPending()) {
    // Tracked with the final shape: every calibration_stride-th accepted frame is one more.
    ++accepted_;
    if (!keep) return false;
    scans_.push_back(scan);
    poses_.push_back(pose);
    return EstimateDetailWhenDue();
  }
  if (options_.refine_every <= 0) return false;
  ++after_;
  if (!keep) return false;
  std::vector<Pose> one = {pose};
  const Eigen::VectorXd reference = q_;
  const ShapeSolveSummary s = Solve({&scan}, &one, reference, options_.refine_prior_weight);
  ++refinements_;
  refine_seconds_ += s.seconds;
  if (refined) *refined = one[0];
  return true;
}

bool ShapeEstimator::FinishDetail() {
  if (!DetailPending() || scans_.empty()) return false;
  return EstimateDetailWhenDue(/*now=*/true);
}

bool ShapeEstimator::EstimateDetailWhenDue(bool now) {
  if (!now &&
      static_cast<int>(scans_.size()) < options_.calibration_frames + options_.detail.frames) {
    return false;
  }
  std::vector<const Scan*> pointers;
  for (const Scan& s : scans_) pointers.push_back(&s);
  detail_ = EstimateSurfaceDetail(model_.Apply(q_), pointers, poses_, depth_camera_,
                                  options_.detail, &detail_summary_);
  scans_.clear();
  poses_.clear();
  return true;
}

}  // namespace artex
