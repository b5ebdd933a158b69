#include "solvers/fit_quality.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>
#include <vector>

#include "models/error.h"
#include "render/rasterizer.h"

namespace artex {

const char* FitQualityLabelName(FitQualityLabel label) {
  switch (label) {
    case FitQualityLabel::kGood:
      return "good";
    case FitQualityLabel::kDoubtful:
      return "doubtful";
    case FitQualityLabel::kLost:
      return "lost";
  }
  return "unknown";
}

bool FitQualityOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  const auto fraction = [](double f) { return f >= 0.0 && f <= 1.0; };
  if (!(std::isfinite(inlier_distance) && inlier_distance > 0.0)) {
    msg << "inlier_distance: expected a finite value > 0 (m), found " << inlier_distance;
  } else if (max_scan_points < 1) {
    msg << "max_scan_points: expected >= 1, found " << max_scan_points;
  } else if (raster_width < 8) {
    msg << "raster_width: expected >= 8 pixels, found " << raster_width;
  } else if (!(std::isfinite(support_tolerance) && support_tolerance > 0.0)) {
    msg << "support_tolerance: expected a finite value > 0 (m), found " << support_tolerance;
  } else if (!(std::isfinite(layer_gap) && layer_gap > 0.0)) {
    msg << "layer_gap: expected a finite value > 0 (m), found " << layer_gap;
  } else if (!(std::isfinite(depth_truncation) && depth_truncation > 0.0)) {
    msg << "depth_truncation: expected a finite value > 0 (m), found " << depth_truncation;
  } else if (!fraction(good_min_inlier_fraction) || !fraction(good_min_support_fraction) ||
             !fraction(lost_min_inlier_fraction) || !fraction(lost_min_support_fraction)) {
    msg << "good_min_*/lost_min_* fractions: expected values in [0, 1]";
  } else if (part_min_visible < 1) {
    msg << "part_min_visible: expected >= 1 vertices, found " << part_min_visible;
  } else if (!(part_min_support >= 0.0 && part_min_support <= 1.0)) {
    msg << "part_min_support: expected a fraction in [0, 1], found " << part_min_support;
  } else if (!(good_max_depth_residual >= 0.0) || !(lost_max_depth_residual >= 0.0)) {
    msg << "good_max_depth_residual/lost_max_depth_residual: expected values >= 0 (m)";
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

std::string FitQuality::BriefReport() const {
  std::ostringstream out;
  out << FitQualityLabelName(label) << ": inliers " << inlier_fraction << ", support "
      << support_fraction << ", depth residual " << depth_residual_m * 1e3 << " mm, score "
      << score;
  if (unsupported_parts > 0) out << ", " << unsupported_parts << " unsupported part(s)";
  out << " (" << seconds * 1e3 << " ms)";
  return out.str();
}

namespace {

// The depth camera at 1 / subsample of its resolution (same field of view; pixel centres at
// integer coordinates in both).
PinholeCamera Subsampled(const PinholeCamera& camera, int subsample) {
  PinholeCamera small = camera;
  const double f = static_cast<double>(subsample);
  small.width = std::max(1, camera.width / subsample);
  small.height = std::max(1, camera.height / subsample);
  small.fx = camera.fx / f;
  small.fy = camera.fy / f;
  small.cx = (camera.cx + 0.5) / f - 0.5;
  small.cy = (camera.cy + 0.5) / f - 0.5;
  return small;
}

// The scan's depth on the raster of `camera`: per pixel the median depth of the front layer of
// the scan points that project into it (sorted front to back, up to the first gap wider than
// layer_gap; the lower median of an even count; infinity where no point does). A raster pixel
// gathers about subsample^2 points. Their minimum, used before, sits about 1.5-1.8 noise sigmas
// in front of the surface (the expected minimum of 10-16 samples), which at high sensor noise
// took every correct fit out of the support tolerance (docs/fitting.md, "Initialisation and fit
// quality"); the front layer keeps the minimum's view of an arm in front of the torso.
std::vector<float> ObservedDepth(const Scan& scan, const PinholeCamera& camera, double layer_gap) {
  const int w = camera.width, h = camera.height;
  const size_t pixels = static_cast<size_t>(w) * h;
  std::vector<int> pixel_of(scan.size(), -1);
  std::vector<float> depth(scan.size());
  std::vector<int> start(pixels + 1, 0);
  for (int s = 0; s < scan.size(); ++s) {
    double z = 0.0;
    const Eigen::Vector2d uv = camera.Project(scan.points.row(s).transpose(), &z);
    if (!(z > 0.0)) continue;
    const int u = static_cast<int>(std::lround(uv.x())), v = static_cast<int>(std::lround(uv.y()));
    if (u < 0 || v < 0 || u >= w || v >= h) continue;
    pixel_of[s] = v * w + u;
    depth[s] = static_cast<float>(z);
    ++start[pixel_of[s] + 1];
  }
  for (size_t i = 1; i <= pixels; ++i) start[i] += start[i - 1];
  std::vector<float> sorted(start[pixels]);
  std::vector<int> fill(start.begin(), start.end() - 1);
  for (int s = 0; s < scan.size(); ++s)
    if (pixel_of[s] >= 0) sorted[fill[pixel_of[s]]++] = depth[s];
  std::vector<float> observed(pixels, std::numeric_limits<float>::infinity());
  for (size_t i = 0; i < pixels; ++i) {
    const int n = start[i + 1] - start[i];
    if (n == 0) continue;
    float* first = sorted.data() + start[i];
    // Insertion sort: a pixel holds a few dozen points at most.
    for (int a = 1; a < n; ++a) {
      const float z = first[a];
      int b = a;
      for (; b > 0 && first[b - 1] > z; --b) first[b] = first[b - 1];
      first[b] = z;
    }
    int layer = 1;
    while (layer < n && first[layer] - first[layer - 1] <= layer_gap) ++layer;
    observed[i] = first[(layer - 1) / 2];
  }
  return observed;
}

}  // namespace

Eigen::VectorXi FitQualityParts(const Eigen::VectorXi& vertex_joint,
                                const std::vector<std::string>& joint_names,
                                const FitQualityOptions& options) {
  // Which joints are ignored, by name once per joint; then the vertices by their joint.
  std::vector<bool> ignored(joint_names.size(), false);
  for (size_t j = 0; j < joint_names.size(); ++j) {
    for (const std::string& name : options.part_ignore) {
      ignored[j] = ignored[j] || joint_names[j] == name;
    }
  }
  Eigen::VectorXi parts = vertex_joint;
  for (Eigen::Index v = 0; v < parts.size(); ++v) {
    const int j = parts[v];
    if (j >= 0 && j < static_cast<int>(ignored.size()) && ignored[j]) parts[v] = -1;
  }
  return parts;
}

FitQuality EvaluateFitQuality(const Eigen::MatrixX3d& posed_vertices,
                              const Eigen::MatrixX3i& triangles, const Scan& scan,
                              const PinholeCamera& depth_camera, const FitQualityOptions& options,
                              const Eigen::VectorXi* vertex_part) {
  const auto start = std::chrono::steady_clock::now();
  std::string error;
  if (!options.IsValid(&error)) throw Error("fit quality options: " + error);
  if (triangles.size() > 0 &&
      (triangles.minCoeff() < 0 || triangles.maxCoeff() >= posed_vertices.rows())) {
    std::ostringstream msg;
    msg << "fit quality: triangles: expected vertex indices in [0, " << posed_vertices.rows()
        << "), found [" << triangles.minCoeff() << ", " << triangles.maxCoeff() << "]";
    throw Error(msg.str());
  }
  if (vertex_part != nullptr && (vertex_part->size() != posed_vertices.rows() ||
                                 (vertex_part->size() > 0 && vertex_part->minCoeff() < -1))) {
    std::ostringstream msg;
    msg << "fit quality: vertex_part: expected " << posed_vertices.rows()
        << " part indices >= -1, found " << vertex_part->size();
    throw Error(msg.str());
  }
  FitQuality q;

  // Inliers: subsampled scan points against the posed vertices, on a uniform grid of cell
  // >= inlier_distance over the vertices' bounding box (counting sort; a query visits the 27
  // cells around its own and stops at the first vertex within the distance).
  if (scan.size() > 0 && posed_vertices.rows() > 0) {
    const Eigen::Vector3d low =
        posed_vertices.colwise().minCoeff().transpose().array() - options.inlier_distance;
    const Eigen::Vector3d high =
        posed_vertices.colwise().maxCoeff().transpose().array() + options.inlier_distance;
    // At most kMaxCellsPerAxis cells per axis (a far-flung vertex must not blow up the grid).
    constexpr double kMaxCellsPerAxis = 256.0;
    const double cell =
        std::max(options.inlier_distance, (high - low).maxCoeff() / kMaxCellsPerAxis);
    int dims[3];
    for (int d = 0; d < 3; ++d)
      dims[d] = std::max(1, static_cast<int>((high[d] - low[d]) / cell) + 1);
    const auto cell_of = [&](const Eigen::Vector3d& p, int* c) {
      for (int d = 0; d < 3; ++d) c[d] = static_cast<int>(std::floor((p[d] - low[d]) / cell));
    };
    const auto flat = [&](const int* c) {
      return (static_cast<size_t>(c[2]) * dims[1] + c[1]) * dims[0] + c[0];
    };
    std::vector<int> start(static_cast<size_t>(dims[0]) * dims[1] * dims[2] + 1, 0);
    std::vector<size_t> vertex_cell(posed_vertices.rows());
    for (Eigen::Index v = 0; v < posed_vertices.rows(); ++v) {
      int c[3];
      cell_of(posed_vertices.row(v).transpose(), c);
      vertex_cell[v] = flat(c);
      ++start[vertex_cell[v] + 1];
    }
    for (size_t i = 1; i < start.size(); ++i) start[i] += start[i - 1];
    std::vector<int> fill(start.begin(), start.end() - 1);
    std::vector<int> members(posed_vertices.rows());
    for (Eigen::Index v = 0; v < posed_vertices.rows(); ++v) {
      members[fill[vertex_cell[v]]++] = static_cast<int>(v);
    }
    const int stride =
        std::max(1, (scan.size() + options.max_scan_points - 1) / options.max_scan_points);
    const double max_d2 = options.inlier_distance * options.inlier_distance;
    int inliers = 0;
    for (int s = 0; s < scan.size(); s += stride) {
      ++q.scan_samples;
      const Eigen::Vector3d p = scan.points.row(s).transpose();
      if (!p.allFinite()) continue;
      int c[3];
      cell_of(p, c);
      bool found = false;
      for (int dz = -1; dz <= 1 && !found; ++dz) {
        for (int dy = -1; dy <= 1 && !found; ++dy) {
          for (int dx = -1; dx <= 1 && !found; ++dx) {
            const int n[3] = {c[0] + dx, c[1] + dy, c[2] + dz};
            if (n[0] < 0 || n[1] < 0 || n[2] < 0 || n[0] >= dims[0] || n[1] >= dims[1] ||
                n[2] >= dims[2]) {
              continue;
            }
            const size_t f = flat(n);
            for (int k = start[f]; k < start[f + 1]; ++k) {
              if ((posed_vertices.row(members[k]).transpose() - p).squaredNorm() <= max_d2) {
                found = true;
                break;
              }
            }
          }
        }
      }
      inliers += found;
    }
    q.inlier_fraction = static_cast<double>(inliers) / q.scan_samples;
  }

  // Rendered template and observed depth on the subsampled raster.
  const int subsample =
      std::max(1, static_cast<int>(
                      std::lround(static_cast<double>(depth_camera.width) / options.raster_width)));
  const PinholeCamera camera = Subsampled(depth_camera, subsample);
  std::vector<float> model;
  RasterizeDepth(posed_vertices, triangles, camera, RasterOptions(), &model);
  const int w = camera.width, h = camera.height;
  const std::vector<float> observed = ObservedDepth(scan, camera, options.layer_gap);
  int supported = 0;
  double residual_sum = 0.0;
  for (size_t i = 0; i < model.size(); ++i) {
    const bool has_model = std::isfinite(model[i]);
    const bool has_observed = std::isfinite(observed[i]);
    if (!has_model && !has_observed) continue;
    ++q.union_pixels;
    if (has_model) ++q.model_pixels;
    if (has_model && has_observed) {
      const double dz = std::abs(static_cast<double>(model[i]) - observed[i]);
      if (dz <= options.support_tolerance) ++supported;
      residual_sum += std::min(dz, options.depth_truncation);
    } else {
      residual_sum += options.depth_truncation;
    }
  }
  q.support_fraction = q.model_pixels > 0 ? static_cast<double>(supported) / q.model_pixels : 0.0;
  q.depth_residual_m =
      q.union_pixels > 0 ? residual_sum / q.union_pixels : options.depth_truncation;

  // Per-part support: each posed vertex visible in the raster (not behind the rendered surface)
  // counts for its part, supported when the observed depth there is within the tolerance.
  if (vertex_part != nullptr && options.part_min_support > 0.0 && vertex_part->size() > 0 &&
      vertex_part->maxCoeff() >= 0) {
    const int parts = vertex_part->maxCoeff() + 1;
    std::vector<int> visible(parts, 0), supported_part(parts, 0);
    for (Eigen::Index v = 0; v < posed_vertices.rows(); ++v) {
      double z = 0.0;
      const Eigen::Vector2d uv = camera.Project(posed_vertices.row(v).transpose(), &z);
      if (!(z > 0.0)) continue;
      const int u = static_cast<int>(std::lround(uv.x())),
                r = static_cast<int>(std::lround(uv.y()));
      if (u < 0 || r < 0 || u >= w || r >= h) continue;
      const size_t i = static_cast<size_t>(r) * w + u;
      if (!std::isfinite(model[i]) || z > model[i] + options.support_tolerance) continue;
      const int part = (*vertex_part)[v];
      if (part < 0) continue;  // not checked
      ++visible[part];
      supported_part[part] +=
          std::isfinite(observed[i]) && std::abs(z - observed[i]) <= options.support_tolerance;
    }
    for (int k = 0; k < parts; ++k) {
      q.unsupported_parts += visible[k] >= options.part_min_visible &&
                             supported_part[k] < options.part_min_support * visible[k];
    }
  }

  q.score = (q.inlier_fraction + q.support_fraction +
             (1.0 - q.depth_residual_m / options.depth_truncation)) /
            3.0;
  if (q.inlier_fraction < options.lost_min_inlier_fraction ||
      q.support_fraction < options.lost_min_support_fraction ||
      q.depth_residual_m > options.lost_max_depth_residual) {
    q.label = FitQualityLabel::kLost;
  } else if (q.inlier_fraction >= options.good_min_inlier_fraction &&
             q.support_fraction >= options.good_min_support_fraction &&
             q.depth_residual_m <= options.good_max_depth_residual && q.unsupported_parts == 0) {
    q.label = FitQualityLabel::kGood;
  } else {
    q.label = FitQualityLabel::kDoubtful;
  }
  q.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return q;
}

}  // namespace artex
