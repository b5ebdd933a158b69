#include "solvers/shape_detail.h"

#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <utility>

#include "models/error.h"
#include "models/normals.h"
#include "models/numeric.h"
#include "models/skinning.h"
#include "render/rasterizer.h"
#include "solvers/estep.h"

namespace artex {

bool ShapeDetailOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  const auto positive = [](double x) { return std::isfinite(x) && x > 0.0; };
  if (frames < 0) {
    msg << "shape.detail.frames: expected >= 0, found " << frames;
  } else if (iterations < 1) {
    msg << "shape.detail.iterations: expected >= 1, found " << iterations;
  } else if (!positive(max_distance)) {
    msg << "shape.detail.max_distance: expected a finite value > 0 (m), found " << max_distance;
  } else if (!positive(max_tangential)) {
    msg << "shape.detail.max_tangential: expected a finite value > 0 (m), found "
        << max_tangential;
  } else if (!(normal_min_cos >= -1.0 && normal_min_cos < 1.0)) {
    msg << "shape.detail.normal_min_cos: expected a value in [-1, 1), found " << normal_min_cos;
  } else if (!(visibility_min_cos >= -1.0 && visibility_min_cos < 1.0)) {
    msg << "shape.detail.visibility_min_cos: expected a value in [-1, 1), found "
        << visibility_min_cos;
  } else if (!positive(occlusion_tolerance)) {
    msg << "shape.detail.occlusion_tolerance: expected a finite value > 0 (m), found "
        << occlusion_tolerance;
  } else if (!(std::isfinite(smoothness) && smoothness >= 0.0)) {
    msg << "shape.detail.smoothness: expected a finite value >= 0, found " << smoothness;
  } else if (!positive(prior_weight)) {
    msg << "shape.detail.prior_weight: expected a finite value > 0, found " << prior_weight;
  } else if (bias_bins < 0 || bias_bins > 100) {
    msg << "shape.detail.bias_bins: expected 0 ... 100, found " << bias_bins;
  } else if (!positive(max_offset)) {
    msg << "shape.detail.max_offset: expected a finite value > 0 (m), found " << max_offset;
  }
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

Template ApplySurfaceDetail(const Template& shaped, const Eigen::VectorXd& offsets) {
  if (offsets.size() != shaped.num_vertices()) {
    std::ostringstream msg;
    msg << "surface detail: expected one offset per template vertex (" << shaped.num_vertices()
        << "), found " << offsets.size();
    throw Error(msg.str());
  }
  Template out = shaped;
  Eigen::MatrixX3d normals;
  ComputeVertexNormals(shaped.vertices, shaped.triangles, &normals);
  out.vertices += (normals.array().colwise() * offsets.array()).matrix();
  return out;
}

namespace {

// Per vertex: observations and the sum of their residuals (rest units).
struct Observations {
  Eigen::VectorXd count, sum;
  double abs_sum = 0.0;  // of the posed residuals (m)
  double frame_mean_sum = 0.0;  // of the frames' mean residuals (m)
  int total = 0;
};

// The residuals of `tmpl` posed as each frame's pose against its scan (see the header).
Observations Observe(const Template& tmpl, const std::vector<const Scan*>& scans,
                     const std::vector<Pose>& poses,
                     const std::vector<std::unique_ptr<PointCloudIndex>>& indices,
                     const PinholeCamera& camera, const ShapeDetailOptions& options) {
  const int nv = tmpl.num_vertices();
  Observations obs;
  obs.count = Eigen::VectorXd::Zero(nv);
  obs.sum = Eigen::VectorXd::Zero(nv);
  const Skinning skinning(tmpl);
  const Eigen::Vector3d center = camera.Center();
  std::vector<std::pair<int, double>> near;
  const double max_t2 = options.max_tangential * options.max_tangential;
  Eigen::MatrixX3d posed, normals;
  std::vector<float> zbuffer;
  // Facing cosines (visibility_min_cos, 1] in bias_bins equal bins (one when 0, unused).
  const int bins = options.bias_bins;
  const int groups = options.bias_per_segment ? tmpl.num_joints() : 1;
  const auto Bin = [&](double facing, int v) {
    const double t = (facing - options.visibility_min_cos) / (1.0 - options.visibility_min_cos);
    const int b = std::clamp(static_cast<int>(t * std::max(bins, 1)), 0, std::max(bins, 1) - 1);
    return (groups > 1 ? tmpl.vertex_joint[v] : 0) * std::max(bins, 1) + b;
  };
  struct Residual {
    int v;
    double r;
    int bin;
  };
  std::vector<Residual> frame;  // of one frame
  std::vector<double> bin_sum(std::max(bins, 1) * groups);
  std::vector<int> bin_count(std::max(bins, 1) * groups);
  std::vector<double> offsets;
  for (size_t f = 0; f < scans.size(); ++f) {
    frame.clear();
    const Scan& scan = *scans[f];
    skinning.Apply(poses[f], &posed);
    ComputeVertexNormals(posed, tmpl.triangles, &normals);
    RasterizeDepth(posed, tmpl.triangles, camera, RasterOptions(), &zbuffer);
    const double scale = poses[f].scale;
    for (int v = 0; v < nv; ++v) {
      const Eigen::Vector3d x = posed.row(v).transpose();
      const Eigen::Vector3d n = normals.row(v).transpose();
      const double facing = n.dot((center - x).normalized());
      if (facing <= options.visibility_min_cos) continue;
      double depth = 0.0;
      const Eigen::Vector2d pixel = camera.Project(x, &depth);
      const long u = std::lround(pixel.x()), w = std::lround(pixel.y());
      if (!(depth > 0.0) || u < 0 || w < 0 || u >= camera.width || w >= camera.height) continue;
      if (depth > zbuffer[static_cast<size_t>(w) * camera.width + u] +
                      options.occlusion_tolerance) {
        continue;
      }
      // The median normal offset of the frame's scan points on the vertex's normal line (a
      // mean took in another surface behind it, e.g. the torso behind an arm).
      indices[f]->Radius(x, options.max_distance, &near);
      offsets.clear();
      for (const auto& [p, d2] : near) {
        const Eigen::Vector3d to = scan.points.row(p).transpose() - x;
        const double r = n.dot(to);
        if (d2 - r * r > max_t2) continue;
        if (scan.normals.row(p).dot(n.transpose()) < options.normal_min_cos) continue;
        offsets.push_back(r);
      }
      if (offsets.empty()) continue;
      const auto middle = offsets.begin() + offsets.size() / 2;
      std::nth_element(offsets.begin(), middle, offsets.end());
      frame.push_back({v, *middle, Bin(facing, v)});
    }
    // Each bin's mean residual is the sensor's and the pose's, not the shape's (bias_bins).
    std::fill(bin_sum.begin(), bin_sum.end(), 0.0);
    std::fill(bin_count.begin(), bin_count.end(), 0);
    double all = 0.0;
    for (const Residual& e : frame) {
      bin_sum[e.bin] += e.r;
      ++bin_count[e.bin];
      all += e.r;
    }
    obs.frame_mean_sum += frame.empty() ? 0.0 : all / static_cast<double>(frame.size());
    for (const Residual& e : frame) {
      const double bias = bins > 0 ? bin_sum[e.bin] / bin_count[e.bin] : 0.0;
      obs.count[e.v] += 1.0;
      obs.sum[e.v] += (e.r - bias) / scale;
      obs.abs_sum += std::abs(e.r - bias);
      ++obs.total;
    }
  }
  return obs;
}

// The mesh's edges as the graph Laplacian L (V x V, unit weight per edge).
Eigen::SparseMatrix<double> EdgeLaplacian(const Eigen::MatrixX3i& triangles, int nv) {
  std::vector<std::pair<int, int>> edges;
  edges.reserve(3 * triangles.rows());
  for (Eigen::Index t = 0; t < triangles.rows(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const int a = triangles(t, k), b = triangles(t, (k + 1) % 3);
      if (a != b) edges.emplace_back(std::min(a, b), std::max(a, b));
    }
  }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  std::vector<Eigen::Triplet<double>> entries;
  entries.reserve(4 * edges.size());
  for (const auto& [a, b] : edges) {
    entries.emplace_back(a, a, 1.0);
    entries.emplace_back(b, b, 1.0);
    entries.emplace_back(a, b, -1.0);
    entries.emplace_back(b, a, -1.0);
  }
  Eigen::SparseMatrix<double> laplacian(nv, nv);
  laplacian.setFromTriplets(entries.begin(), entries.end());
  return laplacian;
}

}  // namespace

Eigen::VectorXd EstimateSurfaceDetail(const Template& shaped, const std::vector<const Scan*>& scans,
                                      const std::vector<Pose>& poses,
                                      const PinholeCamera& depth_camera,
                                      const ShapeDetailOptions& options,
                                      ShapeDetailSummary* summary) {
  const auto start = std::chrono::steady_clock::now();
  std::string why;
  if (!options.IsValid(&why)) throw Error(why);
  if (scans.size() != poses.size()) {
    std::ostringstream msg;
    msg << "surface detail: expected one pose per scan (" << scans.size() << " scans), found "
        << poses.size();
    throw Error(msg.str());
  }
  for (const Pose& pose : poses) {
    if (pose.num_joints() != shaped.num_joints()) {
      std::ostringstream msg;
      msg << "surface detail: expected poses of " << shaped.num_joints() << " joints, found "
          << pose.num_joints();
      throw Error(msg.str());
    }
  }
  const int nv = shaped.num_vertices();
  Eigen::VectorXd offsets = Eigen::VectorXd::Zero(nv);
  ShapeDetailSummary s;
  s.frames = static_cast<int>(scans.size());
  if (!scans.empty()) {
    std::vector<std::unique_ptr<PointCloudIndex>> indices;
    for (const Scan* scan : scans) {
      indices.push_back(std::make_unique<PointCloudIndex>(scan->points));
    }
    const Eigen::SparseMatrix<double> laplacian = EdgeLaplacian(shaped.triangles, nv);
    Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver;
    for (int it = 0; it < options.iterations; ++it) {
      const Template current = ApplySurfaceDetail(shaped, offsets);
      const Observations obs = Observe(current, scans, poses, indices, depth_camera, options);
      if (it == 0) {
        s.residual_before = obs.total > 0 ? obs.abs_sum / obs.total : 0.0;
        s.frame_mean_residual = obs.frame_mean_sum / static_cast<double>(scans.size());
      }
      s.observed_vertices = static_cast<int>((obs.count.array() > 0.0).count());
      s.observations = obs.total;
      // (C + smoothness L + prior I) d = C d' + sum of residuals.
      Eigen::SparseMatrix<double> system = options.smoothness * laplacian;
      Eigen::VectorXd diagonal = obs.count.array() + options.prior_weight;
      for (int v = 0; v < nv; ++v) system.coeffRef(v, v) += diagonal[v];
      const Eigen::VectorXd rhs = obs.count.cwiseProduct(offsets) + obs.sum;
      if (it == 0) solver.analyzePattern(system);
      solver.factorize(system);
      if (solver.info() != Eigen::Success) throw Error("surface detail: the solve failed");
      offsets = solver.solve(rhs).cwiseMax(-options.max_offset).cwiseMin(options.max_offset);
      ++s.iterations;
    }
    const Observations after =
        Observe(ApplySurfaceDetail(shaped, offsets), scans, poses, indices, depth_camera, options);
    s.residual_after = after.total > 0 ? after.abs_sum / after.total : 0.0;
    s.mean_offset = offsets.mean();
    s.rms_offset = std::sqrt(offsets.squaredNorm() / std::max(nv, 1));
    s.max_offset = offsets.cwiseAbs().maxCoeff();
    s.at_bound = static_cast<int>((offsets.cwiseAbs().array() >= options.max_offset).count());
  }
  s.seconds = SecondsSince(start);
  if (summary) *summary = s;
  return offsets;
}

}  // namespace artex
