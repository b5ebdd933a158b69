// EMFitterOptions (names of its enumerations, validation) and FitSummary's report
// (solvers/em_fitter.h); the fitter itself is solvers/em_fitter.cc.
#include "solvers/em_fitter.h"

#include <cmath>
#include <sstream>

namespace artex {

const std::map<std::string, CorrespondenceModel>& CorrespondenceModelNames() {
  static const std::map<std::string, CorrespondenceModel> kNames = {
      {"one_to_many", CorrespondenceModel::kOneToMany},
      {"one_to_one", CorrespondenceModel::kOneToOne}};
  return kNames;
}

const std::map<std::string, FitVertexSelection>& FitVertexSelectionNames() {
  static const std::map<std::string, FitVertexSelection> kNames = {
      {"stride", FitVertexSelection::kStride}, {"voxel", FitVertexSelection::kVoxel}};
  return kNames;
}

const std::map<std::string, ScaleMode>& ScaleModeNames() {
  static const std::map<std::string, ScaleMode> kNames = {
      {"free", ScaleMode::kFree},
      {"estimate_then_fix", ScaleMode::kEstimateThenFix},
      {"estimate_then_prior", ScaleMode::kEstimateThenPrior},
      {"fixed", ScaleMode::kFixed}};
  return kNames;
}

const std::map<std::string, ScaleEstimator>& ScaleEstimatorNames() {
  static const std::map<std::string, ScaleEstimator> kNames = {{"icp", ScaleEstimator::kIcp},
                                                               {"em", ScaleEstimator::kEm}};
  return kNames;
}

const char* FrameTerminationName(FrameTermination termination) {
  switch (termination) {
    case FrameTermination::kConverged:
      return "converged";
    case FrameTermination::kMaxIterations:
      return "max_iterations";
    case FrameTermination::kFailed:
      return "failed";
  }
  return "unknown";
}

bool EMFitterOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  std::string inner;
  auto radii_ok = [](const std::vector<double>& radii) {
    for (double r : radii) {
      if (!(std::isfinite(r) && r > 0.0)) return false;
    }
    return true;
  };
  if (!estep.IsValid(&inner)) {
    msg << "estep." << inner;
  } else if (!one_to_one.IsValid(&inner)) {
    msg << "one_to_one." << inner;
  } else if (!solver.IsValid(&inner)) {
    msg << "solver." << inner;
  } else if (!tikhonov.IsValid(&inner)) {
    msg << "tikhonov." << inner;
  } else if (!tracking_update.IsValid(&inner)) {
    msg << "tracking_update." << inner;
  } else if (!smoothness.IsValid(&inner)) {
    msg << "smoothness." << inner;
  } else if (!icp.IsValid(&inner)) {
    msg << "icp." << inner;
  } else if (!unobserved_joints.IsValid(&inner)) {
    msg << "unobserved_joints." << inner;
  } else if (!joint_coupling.IsValid(&inner)) {
    msg << "joint_coupling." << inner;
  } else if (!upright.IsValid(&inner)) {
    msg << "upright." << inner;
  } else if (!silhouette.IsValid(&inner)) {
    msg << "silhouette." << inner;
  } else if (!out_of_view.IsValid(&inner)) {
    msg << "out_of_view." << inner;
  } else if (!prediction.IsValid(&inner)) {
    msg << "prediction." << inner;
  } else if (estep.mode == EStepMode::kRadius &&
             (first_frame_radii.empty() || tracking_radii.empty())) {
    msg << "first_frame_radii/tracking_radii: expected at least one radius for the radius "
           "E-step, found an empty schedule";
  } else if (!radii_ok(first_frame_radii) || !radii_ok(tracking_radii)) {
    msg << "first_frame_radii/tracking_radii: expected finite radii > 0 (m)";
  } else if (first_frame_iterations_per_stage < 1 || tracking_iterations_per_stage < 1) {
    msg << "iterations_per_stage: expected >= 1, found " << first_frame_iterations_per_stage
        << " / " << tracking_iterations_per_stage;
  } else if (max_iterations < 1) {
    msg << "max_iterations: expected >= 1, found " << max_iterations;
  } else if (!(relative_cost_tolerance >= 0.0) || !(parameter_tolerance >= 0.0)) {
    msg << "relative_cost_tolerance/parameter_tolerance: expected values >= 0";
  } else if (!(over_relaxation > 0.0 && over_relaxation < 2.0)) {
    msg << "over_relaxation: expected a value in (0, 2), found " << over_relaxation;
  } else if (scale_estimation_frames < 1) {
    msg << "scale_estimation_frames: expected >= 1, found " << scale_estimation_frames;
  } else if (!(std::isfinite(scale_prior_weight) && scale_prior_weight >= 0.0)) {
    msg << "scale_prior_weight: expected a finite value >= 0, found " << scale_prior_weight;
  } else if (!(std::isfinite(scale_sample_max_distance) && scale_sample_max_distance > 0.0)) {
    msg << "scale_sample_max_distance: expected a finite value > 0 (m), found "
        << scale_sample_max_distance;
  } else if (!(scale_sample_min_pair_fraction >= 0.0 && scale_sample_min_pair_fraction <= 1.0)) {
    msg << "scale_sample_min_pair_fraction: expected a value in [0, 1], found "
        << scale_sample_min_pair_fraction;
  } else if (!(std::isfinite(scale_max_radius) && scale_max_radius > 0.0)) {
    msg << "scale_max_radius: expected a finite value > 0 (m), found " << scale_max_radius;
  } else if (normal_refresh_iterations < 0) {
    msg << "normal_refresh_iterations: expected >= 0 (0: once per stage), found "
        << normal_refresh_iterations;
  } else if (max_fit_vertices < 0) {
    msg << "max_fit_vertices: expected >= 0 (0: all), found " << max_fit_vertices;
  } else if (scale_sample_max_scan_points != 0 && scale_sample_max_scan_points < 3) {
    msg << "scale_sample_max_scan_points: expected 0 (icp_init.max_scan_points) or >= 3, found "
        << scale_sample_max_scan_points;
  } else if (!(std::isfinite(scale_sample_tolerance) && scale_sample_tolerance >= 0.0)) {
    msg << "scale_sample_tolerance: expected a finite value >= 0 (0: icp_init.tolerance), found "
        << scale_sample_tolerance;
  } else if (!(std::isfinite(scale_sample_grid_cell) && scale_sample_grid_cell >= 0.0)) {
    msg << "scale_sample_grid_cell: expected a finite value >= 0 (m; 0: icp_init.grid_cell), "
           "found "
        << scale_sample_grid_cell;
  } else if (tracking_max_fit_vertices < 0) {
    msg << "tracking_max_fit_vertices: expected >= 0 (0: max_fit_vertices), found "
        << tracking_max_fit_vertices;
  } else if (min_scan_points < 0) {
    msg << "min_scan_points: expected >= 0, found " << min_scan_points;
  } else if (!(max_mean_motion > 0.0) || !(max_scale_change > 0.0)) {
    msg << "max_mean_motion/max_scale_change: expected values > 0";
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

std::string FitSummary::BriefReport() const {
  std::ostringstream out;
  out << "frame " << frame << ": " << FrameTerminationName(termination) << " after " << iterations
      << " iterations, cost " << initial_cost << " -> " << final_cost << ", scale " << scale << ", "
      << total_seconds * 1e3 << " ms (E " << estep_seconds * 1e3 << ", M " << mstep_seconds * 1e3
      << ", skinning " << skinning_seconds * 1e3 << ")";
  if (too_few_points) out << " [too few points]";
  if (non_finite) out << " [non-finite]";
  if (diverged) out << " [diverged]";
  return out.str();
}

}  // namespace artex
