#include "solvers/icp_init.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <sstream>
#include <vector>

#include "models/error.h"
#include "models/normals.h"
#include "solvers/estep.h"
#include "solvers/nearest_grid.h"

namespace artex {

bool IcpInitOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (max_iterations < 0) {
    msg << "max_iterations: expected >= 0, found " << max_iterations;
  } else if (!(std::isfinite(max_distance) && max_distance > 0.0)) {
    msg << "max_distance: expected a finite value > 0 (m), found " << max_distance;
  } else if (!(min_normal_dot >= -1.0 && min_normal_dot <= 1.0)) {
    msg << "min_normal_dot: expected a cosine in [-1, 1], found " << min_normal_dot;
  } else if (max_scan_points < 3) {
    msg << "max_scan_points: expected >= 3, found " << max_scan_points;
  } else if (!(std::isfinite(tolerance) && tolerance >= 0.0)) {
    msg << "tolerance: expected a finite value >= 0, found " << tolerance;
  } else if (!(extent_quantile >= 0.0 && extent_quantile < 0.5)) {
    msg << "extent_quantile: expected a value in [0, 0.5), found " << extent_quantile;
  } else if (kd_leaf_size < 1) {
    msg << "kd_leaf_size: expected >= 1, found " << kd_leaf_size;
  } else if (!(std::isfinite(grid_cell) && grid_cell >= 0.0)) {
    msg << "grid_cell: expected a finite value >= 0 (m; 0: the kd-tree), found " << grid_cell;
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

namespace {

double Quantile(std::vector<double> values, double q) {
  if (values.empty()) return 0.0;
  const size_t k = static_cast<size_t>(q * static_cast<double>(values.size() - 1));
  std::nth_element(values.begin(), values.begin() + k, values.end());
  return values[k];
}

double VerticalExtent(const Eigen::MatrixX3d& points, double q) {
  std::vector<double> y(points.rows());
  for (Eigen::Index i = 0; i < points.rows(); ++i) y[i] = points(i, 1);
  return Quantile(y, 1.0 - q) - Quantile(y, q);
}

// Options, scan and the pose's joint count, in this order (the errors name the first fault).
void CheckInputs(const Pose& initial, int num_joints, const Scan& scan,
                 const IcpInitOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw Error("ICP initialisation options: " + error);
  if (scan.size() < 3) {
    std::ostringstream msg;
    msg << "ICP initialisation: expected a scan with >= 3 points, found " << scan.size();
    throw Error(msg.str());
  }
  if (scan.normals.rows() != scan.points.rows()) {
    throw Error("ICP initialisation: scan.normals: expected one normal per point");
  }
  if (initial.num_joints() != num_joints) {
    std::ostringstream msg;
    msg << "ICP initialisation: initial pose: expected " << num_joints << " joints, found "
        << initial.num_joints();
    throw Error(msg.str());
  }
}

}  // namespace

IcpTemplate::IcpTemplate(const Skinning& skinning, const Pose& articulation, int kd_leaf_size,
                         double grid_cell) {
  const Template& model = skinning.model();
  num_joints_ = model.num_joints();
  if (articulation.num_joints() != num_joints_) {
    std::ostringstream msg;
    msg << "ICP template: pose: expected " << num_joints_ << " joints, found "
        << articulation.num_joints();
    throw Error(msg.str());
  }
  Pose local = articulation;
  local.scale = 1.0;
  local.translation.setZero();
  local.rotation.setIdentity();
  skinning.Apply(local, &vertices_);
  ComputeVertexNormals(vertices_, model.triangles, &normals_);
  if (grid_cell > 0.0) {
    grid_ = std::make_unique<NearestGrid>(vertices_, grid_cell);
  } else {
    index_ = std::make_unique<PointCloudIndex>(vertices_, kd_leaf_size);
  }
}

IcpTemplate::~IcpTemplate() = default;

int IcpTemplate::NearestWithin(const Eigen::Vector3d& query, double bound2,
                               double* distance2) const {
  return grid_ ? grid_->NearestWithin(query, bound2, distance2)
               : index_->NearestWithin(query, bound2, distance2);
}

IcpInitResult AlignByIcp(const Skinning& skinning, const Pose& initial, const Scan& scan,
                         const IcpInitOptions& options) {
  CheckInputs(initial, skinning.model().num_joints(), scan, options);
  return AlignByIcp(IcpTemplate(skinning, initial, options.kd_leaf_size, options.grid_cell),
                   initial, scan, options);
}

IcpInitResult AlignByIcp(const IcpTemplate& target, const Pose& initial, const Scan& scan,
                         const IcpInitOptions& options) {
  CheckInputs(initial, target.num_joints(), scan, options);
  // Articulated template without its global similarity: x_t, n_t.
  const Eigen::MatrixX3d& x = target.vertices();
  const Eigen::MatrixX3d& xn = target.normals();

  // Subsampled scan.
  const int stride =
      std::max(1, (scan.size() + options.max_scan_points - 1) / options.max_scan_points);
  std::vector<int> sample;
  for (int s = 0; s < scan.size(); s += stride) sample.push_back(s);

  double scale = initial.scale;
  Eigen::Matrix3d rotation = initial.rotation;
  Eigen::Vector3d translation = initial.translation;
  if (options.coarse_alignment) {
    if (options.facing_camera) {
      const Eigen::Vector3d mean_normal = scan.normals.colwise().sum().transpose();
      const Eigen::Vector2d horizontal(mean_normal.x(), mean_normal.z());
      if (horizontal.norm() > 1e-9) {
        // Template front (+Z) to the horizontal mean normal: yaw about +Y.
        const double yaw = std::atan2(horizontal.x(), horizontal.y());
        rotation = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()).toRotationMatrix();
      }
    }
    if (options.estimate_scale && options.scale_from_extent) {
      const double template_extent = VerticalExtent(x, options.extent_quantile);
      const double scan_extent = VerticalExtent(scan.points, options.extent_quantile);
      if (template_extent > 0.0 && scan_extent > 0.0) scale = scan_extent / template_extent;
    }
    // Centroid of the template vertices facing the camera direction vs the scan centroid.
    const Eigen::Vector3d view = scan.normals.colwise().mean().transpose();
    Eigen::Vector3d facing_sum = Eigen::Vector3d::Zero();
    int facing = 0;
    for (int t = 0; t < x.rows(); ++t) {
      if ((rotation * xn.row(t).transpose()).dot(view) > 0.0) {
        facing_sum += x.row(t).transpose();
        ++facing;
      }
    }
    const Eigen::Vector3d template_centroid =
        facing > 0 ? Eigen::Vector3d(facing_sum / facing) : Eigen::Vector3d(x.colwise().mean());
    const Eigen::Vector3d scan_centroid = scan.points.colwise().mean().transpose();
    translation = scan_centroid - scale * rotation * template_centroid;
  }

  IcpInitResult result;
  result.num_samples = static_cast<int>(sample.size());
  const double max_d2 = options.max_distance * options.max_distance;
  // Each sample's nearest template vertex of the previous iteration (-1: none in range).
  std::vector<int> previous(sample.size(), -1);
  for (int it = 0; it < options.max_iterations; ++it) {
    // Scan points into the template frame: q = R^T (v - t) / s.
    Eigen::Matrix3Xd src(3, sample.size()), dst(3, sample.size());
    int pairs = 0;
    double sum_d2 = 0.0;
    for (std::size_t k = 0; k < sample.size(); ++k) {
      const int s = sample[k];
      const Eigen::Vector3d v = scan.points.row(s).transpose();
      const Eigen::Vector3d q = rotation.transpose() * (v - translation) / scale;
      // The nearest vertex, searched no farther than a pair is accepted (a hair more, for
      // rounding: the test below decides) nor than the previous iteration's nearest vertex,
      // which has moved little: the same vertex as an unbounded search, found sooner.
      double bound2 = max_d2 / (scale * scale) * (1.0 + 1e-9);
      if (previous[k] >= 0) {
        bound2 = std::min(bound2, BoundKeeping(q, x.row(previous[k]).transpose()));
      }
      double d2 = 0.0;
      const int t = target.NearestWithin(q, bound2, &d2);
      previous[k] = t;
      const double world_d2 = d2 * scale * scale;
      if (t < 0 || world_d2 > max_d2) continue;
      if ((rotation * xn.row(t).transpose()).dot(scan.normals.row(s).transpose()) <
          options.min_normal_dot) {
        continue;
      }
      // Without scale estimation Umeyama fits a rigid motion: feed it the scaled template.
      src.col(pairs) = (options.estimate_scale ? 1.0 : scale) * x.row(t).transpose();
      dst.col(pairs) = v;
      sum_d2 += world_d2;
      ++pairs;
    }
    result.iterations = it + 1;
    result.num_pairs = pairs;
    result.rms = pairs > 0 ? std::sqrt(sum_d2 / pairs) : 0.0;
    if (pairs < 3) break;
    const Eigen::Matrix4d t_mat =
        Eigen::umeyama(src.leftCols(pairs), dst.leftCols(pairs), options.estimate_scale);
    const Eigen::Matrix3d sr = t_mat.topLeftCorner<3, 3>();
    const double new_scale = options.estimate_scale ? std::cbrt(sr.determinant()) : scale;
    const Eigen::Matrix3d new_rotation = sr / (options.estimate_scale ? new_scale : 1.0);
    const Eigen::Vector3d new_translation = t_mat.topRightCorner<3, 1>();
    if (!std::isfinite(new_scale) || !(new_scale > 0.0) || !new_rotation.allFinite() ||
        !new_translation.allFinite()) {
      break;
    }
    const double change = std::max(
        {std::abs(new_scale - scale), (new_translation - translation).cwiseAbs().maxCoeff(),
         Eigen::AngleAxisd(new_rotation * rotation.transpose()).angle()});
    scale = new_scale;
    rotation = new_rotation;
    translation = new_translation;
    if (change < options.tolerance) {
      result.converged = true;
      break;
    }
  }
  result.pose = initial;
  result.pose.scale = scale;
  result.pose.rotation = rotation;
  result.pose.translation = translation;
  return result;
}

}  // namespace artex
