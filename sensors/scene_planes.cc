// Scene planes and the world frame (sensors/scene_segmentation.h): RANSAC plane detection in
// the depth image (floors and walls labelled against an up prior) and the world frame estimated
// from the floor, gravity or the camera convention. The subject's segmentation:
// subject_segmentation.cc.
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <random>
#include <sstream>

#include "models/error.h"
#include "models/numeric.h"
#include "sensors/scene_segmentation.h"
#include "sensors/scene_segmentation_internal.h"

namespace artex {
namespace {

using scene_internal::CheckDepth;

double Quantile(std::vector<double>* values, double q) {
  if (values->empty()) return 0.0;
  const size_t k = static_cast<size_t>(q * static_cast<double>(values->size() - 1));
  std::nth_element(values->begin(), values->begin() + static_cast<std::ptrdiff_t>(k),
                   values->end());
  return (*values)[k];
}

// Least-squares plane through points (smallest principal axis), normal towards the origin.
bool FitPlane(const std::vector<Eigen::Vector3d>& points, const std::vector<int>& subset,
              Eigen::Vector3d* normal, double* offset) {
  if (subset.size() < 3) return false;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (int i : subset) mean += points[i];
  mean /= static_cast<double>(subset.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (int i : subset) cov += (points[i] - mean) * (points[i] - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  Eigen::Vector3d n = eig.eigenvectors().col(0).normalized();
  double d = -n.dot(mean);
  if (d < 0) {
    n = -n;
    d = -d;
  }
  if (!n.allFinite() || !std::isfinite(d)) return false;
  *normal = n;
  *offset = d;
  return true;
}

// The floor-labelled plane with the most inliers; null when none is labelled a floor.
const ScenePlane* LargestFloor(const std::vector<ScenePlane>& planes) {
  const ScenePlane* floor = nullptr;
  for (const ScenePlane& p : planes) {
    if (p.kind == PlaneKind::kFloor && (!floor || p.inliers > floor->inliers)) floor = &p;
  }
  return floor;
}

}  // namespace

bool PlaneDetectionOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (sample_stride < 1) {
    msg << "sample_stride: expected >= 1, found " << sample_stride;
  } else if (ransac_iterations < 1 || score_points < 3) {
    msg << "ransac_iterations/score_points: expected >= 1 / >= 3, found " << ransac_iterations
        << " / " << score_points;
  } else if (!(inlier_distance > 0) || !(inlier_growth >= 0)) {
    msg << "inlier_distance/inlier_growth: expected > 0 / >= 0, found " << inlier_distance << " / "
        << inlier_growth;
  } else if (!(merge_angle_deg >= 0) || !(merge_distance >= 0)) {
    msg << "merge_angle_deg/merge_distance: expected >= 0";
  } else if (max_planes < 0) {
    msg << "max_planes: expected >= 0, found " << max_planes;
  } else if (!(min_inlier_fraction > 0 && min_inlier_fraction <= 1)) {
    msg << "min_inlier_fraction: expected a value in (0, 1], found " << min_inlier_fraction;
  } else if (!(min_extent >= 0) || !(floor_min_extent >= 0) || !(min_coverage >= 0)) {
    msg << "min_extent/floor_min_extent/min_coverage: expected >= 0, found " << min_extent << " / "
        << floor_min_extent << " / " << min_coverage;
  } else if (!(floor_max_angle_deg >= 0 && floor_max_angle_deg <= 90) ||
             !(wall_max_angle_deg >= 0 && wall_max_angle_deg <= 90)) {
    msg << "floor_max_angle_deg/wall_max_angle_deg: expected degrees in [0, 90]";
  } else if (!(min_depth >= 0) || !(max_depth > min_depth)) {
    msg << "min_depth/max_depth: expected 0 <= min_depth < max_depth, found " << min_depth << " / "
        << max_depth;
  } else {
    return true;
  }
  if (error) *error = "planes." + msg.str();
  return false;
}

const char* PlaneKindName(PlaneKind kind) {
  switch (kind) {
    case PlaneKind::kFloor:
      return "floor";
    case PlaneKind::kWall:
      return "wall";
    case PlaneKind::kOther:
      return "other";
  }
  return "?";
}

std::vector<ScenePlane> DetectScenePlanes(const cv::Mat& depth, const PinholeCamera& intrinsics,
                                          const Distortion& distortion, double depth_scale,
                                          const Eigen::Vector3d& up_prior,
                                          const PlaneDetectionOptions& options) {
  return DetectScenePlanes(depth, DepthBackProjector(intrinsics, distortion), depth_scale, up_prior,
                           options);
}

std::vector<ScenePlane> DetectScenePlanes(const cv::Mat& depth, const DepthBackProjector& projector,
                                          double depth_scale, const Eigen::Vector3d& up_prior,
                                          const PlaneDetectionOptions& options) {
  const PinholeCamera& intrinsics = projector.camera();
  std::string error;
  if (!options.IsValid(&error)) throw Error("plane detection options: " + error);
  CheckDepth(depth, intrinsics, "plane detection");
  if (!(depth_scale > 0)) throw Error("plane detection: expected a positive depth_scale");
  const Eigen::Vector3d up = up_prior.normalized();

  // Sampled points in the depth range.
  std::vector<Eigen::Vector3d> points;
  for (int v = 0; v < depth.rows; v += options.sample_stride) {
    const uint16_t* row = depth.ptr<uint16_t>(v);
    for (int u = 0; u < depth.cols; u += options.sample_stride) {
      if (row[u] == 0) continue;
      const double z = row[u] / depth_scale;
      if (z < options.min_depth || z > options.max_depth) continue;
      points.push_back(projector.CameraPoint(u, v, z));
    }
  }
  std::vector<ScenePlane> planes;
  const int total = static_cast<int>(points.size());
  std::vector<double> tolerance(points.size());
  for (int i = 0; i < total; ++i) {
    const double z = points[i].z();
    tolerance[i] = options.inlier_distance + options.inlier_growth * z * z;
  }
  if (total < 3) return planes;
  std::vector<int> remaining(points.size());
  for (int i = 0; i < total; ++i) remaining[i] = i;
  std::mt19937_64 rng(options.seed);
  const double cos_floor = std::cos(options.floor_max_angle_deg * kDegToRad);
  const double sin_wall = std::sin(options.wall_max_angle_deg * kDegToRad);

  for (int p = 0; p < options.max_planes; ++p) {
    const int n = static_cast<int>(remaining.size());
    if (n < 3 || n < options.min_inlier_fraction * total) break;
    // Hypotheses scored on a fixed random subset of the remaining points.
    std::vector<int> score;
    std::uniform_int_distribution<int> pick(0, n - 1);
    const int score_count = std::min(n, options.score_points);
    score.reserve(score_count);
    for (int i = 0; i < score_count; ++i) score.push_back(remaining[pick(rng)]);
    int best_count = -1;
    Eigen::Vector3d best_n = Eigen::Vector3d::UnitY();
    double best_d = 0;
    for (int it = 0; it < options.ransac_iterations; ++it) {
      const Eigen::Vector3d& a = points[remaining[pick(rng)]];
      const Eigen::Vector3d& b = points[remaining[pick(rng)]];
      const Eigen::Vector3d& c = points[remaining[pick(rng)]];
      Eigen::Vector3d normal = (b - a).cross(c - a);
      const double len = normal.norm();
      if (!(len > 1e-9)) continue;
      normal /= len;
      const double d = -normal.dot(a);
      int count = 0;
      for (int i : score) count += std::abs(normal.dot(points[i]) + d) < tolerance[i];
      if (count > best_count) {
        best_count = count;
        best_n = normal;
        best_d = d;
      }
    }
    if (best_count < 3) break;
    // Inliers among all remaining points, refined by least squares, recounted.
    std::vector<int> inliers, outliers;
    for (int pass = 0; pass < 2; ++pass) {
      inliers.clear();
      outliers.clear();
      for (int i : remaining) {
        (std::abs(best_n.dot(points[i]) + best_d) < tolerance[i] ? inliers : outliers).push_back(i);
      }
      if (pass == 0 && !FitPlane(points, inliers, &best_n, &best_d)) break;
    }
    if (inliers.size() < options.min_inlier_fraction * total) break;
    Eigen::Vector3d oriented = best_d < 0 ? Eigen::Vector3d(-best_n) : best_n;
    bool merged = false;
    for (ScenePlane& earlier : planes) {
      if (earlier.normal.dot(oriented) >= std::cos(options.merge_angle_deg * kDegToRad) &&
          std::abs(earlier.offset - std::abs(best_d)) <= options.merge_distance) {
        earlier.inliers += static_cast<int>(inliers.size());
        earlier.inlier_fraction = static_cast<double>(earlier.inliers) / total;
        merged = true;
        break;
      }
    }
    if (merged) {
      remaining.swap(outliers);
      continue;
    }
    ScenePlane plane;
    plane.normal = best_n;
    plane.offset = best_d;
    if (plane.offset < 0) {
      plane.normal = -plane.normal;
      plane.offset = -plane.offset;
    }
    plane.inliers = static_cast<int>(inliers.size());
    plane.inlier_fraction = static_cast<double>(inliers.size()) / total;
    // In-plane spread along the principal axes of the inliers.
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (int i : inliers) mean += points[i];
    mean /= static_cast<double>(inliers.size());
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (int i : inliers) cov += (points[i] - mean) * (points[i] - mean).transpose();
    const Eigen::Matrix3d project =
        Eigen::Matrix3d::Identity() - plane.normal * plane.normal.transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> axes(project * cov * project);
    const Eigen::Vector3d axis0 = axes.eigenvectors().col(2).normalized();
    const Eigen::Vector3d axis1 = plane.normal.cross(axis0).normalized();
    std::vector<double> c0, c1;
    c0.reserve(inliers.size());
    c1.reserve(inliers.size());
    for (int i : inliers) {
      c0.push_back(axis0.dot(points[i]));
      c1.push_back(axis1.dot(points[i]));
    }
    std::vector<double> copy0 = c0, copy1 = c1;
    const double e0 = Quantile(&copy0, 0.95) - Quantile(&c0, 0.05);
    const double e1 = Quantile(&copy1, 0.95) - Quantile(&c1, 0.05);
    plane.extent[0] = std::max(e0, e1);
    plane.extent[1] = std::min(e0, e1);
    // Area on the plane of the inlier samples: (stride z)^2 / (fx fy) per sample, divided by
    // the cosine between the viewing ray and the normal (bounded at grazing angles).
    double area = 0.0;
    const double pixel =
        options.sample_stride * options.sample_stride / (intrinsics.fx * intrinsics.fy);
    for (int i : inliers) {
      const Eigen::Vector3d& x = points[i];
      const double cosine = std::max(0.2, std::abs(plane.normal.dot(x)) / x.norm());
      area += pixel * x.z() * x.z() / cosine;
    }
    plane.coverage = area / std::max(1e-9, plane.extent[0] * plane.extent[1]);
    const double up_dot = plane.normal.dot(up);
    if (plane.coverage >= options.min_coverage) {
      if (up_dot >= cos_floor && plane.extent[1] >= options.floor_min_extent) {
        plane.kind = PlaneKind::kFloor;
      } else if (std::abs(up_dot) <= sin_wall && plane.extent[1] >= options.min_extent) {
        plane.kind = PlaneKind::kWall;
      }
    }
    planes.push_back(plane);
    remaining.swap(outliers);
  }
  return planes;
}

const std::map<std::string, WorldFrameMode>& WorldFrameModeNames() {
  static const std::map<std::string, WorldFrameMode> names = {
      {"auto", WorldFrameMode::kAuto},
      {"estimate", WorldFrameMode::kEstimate},
      {"calibration", WorldFrameMode::kCalibration}};
  return names;
}

const char* WorldFrameSourceName(WorldFrameSource source) {
  switch (source) {
    case WorldFrameSource::kCalibration:
      return "calibration";
    case WorldFrameSource::kFloor:
      return "floor";
    case WorldFrameSource::kGravity:
      return "gravity";
    case WorldFrameSource::kCameraConvention:
      return "camera_convention";
  }
  return "?";
}

bool WorldFrameOptions::IsValid(std::string* error) const {
  if (!planes.IsValid(error)) return false;
  if (!(assumed_camera_height >= 0 && std::isfinite(assumed_camera_height))) {
    if (error) *error = "assumed_camera_height: expected a finite value >= 0 (m)";
    return false;
  }
  return true;
}

Eigen::Isometry3d WorldFrameFromUp(const Eigen::Vector3d& up_camera, double height) {
  const Eigen::Vector3d y = up_camera.normalized();
  // World -Z: the viewing direction (camera +z) on the floor; +Z points back at the camera.
  Eigen::Vector3d forward = Eigen::Vector3d::UnitZ() - y.z() * y;
  if (forward.norm() < 1e-6) forward = Eigen::Vector3d::UnitY() - y.y() * y;  // looking down
  const Eigen::Vector3d z = -forward.normalized();
  const Eigen::Vector3d x = y.cross(z).normalized();
  Eigen::Matrix3d world_to_camera_rotation;  // columns: world axes in camera coordinates
  world_to_camera_rotation.col(0) = x;
  world_to_camera_rotation.col(1) = y;
  world_to_camera_rotation.col(2) = z;
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = world_to_camera_rotation;
  // Camera centre at (0, height, 0): 0 = R c + t.
  t.translation() = -world_to_camera_rotation * Eigen::Vector3d(0, height, 0);
  return t;
}

std::string WorldFrameEstimate::Describe() const {
  std::ostringstream s;
  s.precision(3);
  s << "world frame from " << WorldFrameSourceName(source) << ": up (camera) = (" << up_camera.x()
    << ", " << up_camera.y() << ", " << up_camera.z() << "), camera height " << camera_height
    << " m, pitch " << camera_pitch_deg << " deg, roll " << camera_roll_deg << " deg";
  return s.str();
}

WorldFrameEstimate EstimateWorldFrame(const cv::Mat& depth, const PinholeCamera& intrinsics,
                                      const Distortion& distortion, double depth_scale,
                                      const std::optional<Eigen::Vector3d>& gravity_up,
                                      const WorldFrameOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw Error("world frame options: " + error);
  WorldFrameEstimate estimate;
  const bool gravity = gravity_up && gravity_up->allFinite() && gravity_up->norm() > 1e-9;
  const Eigen::Vector3d prior = gravity ? gravity_up->normalized() : Eigen::Vector3d(0, -1, 0);
  estimate.planes =
      DetectScenePlanes(depth, intrinsics, distortion, depth_scale, prior, options.planes);
  const ScenePlane* floor = LargestFloor(estimate.planes);
  if (floor) {
    estimate.source = WorldFrameSource::kFloor;
    estimate.up_camera = floor->normal;
    estimate.camera_height = floor->offset;
  } else {
    estimate.source = gravity ? WorldFrameSource::kGravity : WorldFrameSource::kCameraConvention;
    estimate.up_camera = prior;
    estimate.camera_height = options.assumed_camera_height;
  }
  estimate.world_to_camera = WorldFrameFromUp(estimate.up_camera, estimate.camera_height);
  const Eigen::Vector3d& up = estimate.up_camera;
  estimate.camera_pitch_deg = std::asin(std::clamp(up.z(), -1.0, 1.0)) / kDegToRad;
  estimate.camera_roll_deg = std::atan2(up.x(), -up.y()) / kDegToRad;
  return estimate;
}

std::optional<ScenePlane> FindWorldFloor(const cv::Mat& depth, const PinholeCamera& camera,
                                         const Distortion& distortion, double depth_scale,
                                         const PlaneDetectionOptions& options) {
  const Eigen::Matrix3d r = camera.world_to_camera.linear();
  const Eigen::Vector3d t = camera.world_to_camera.translation();
  const std::vector<ScenePlane> planes = DetectScenePlanes(
      depth, camera, distortion, depth_scale, r * Eigen::Vector3d::UnitY(), options);
  const ScenePlane* floor = LargestFloor(planes);
  if (!floor) return std::nullopt;
  // n_c . (R x + t) + d = 0  <=>  (R^T n_c) . x + (n_c . t + d) = 0.
  ScenePlane world = *floor;
  world.normal = r.transpose() * floor->normal;
  world.offset = floor->normal.dot(t) + floor->offset;
  if (world.normal.y() < 0.0) {
    world.normal = -world.normal;
    world.offset = -world.offset;
  }
  return world;
}

}  // namespace artex
