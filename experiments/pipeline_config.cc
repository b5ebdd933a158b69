// Configuration keys of the pipeline (docs/configuration.md lists them with their defaults).
#include <cmath>
#include <map>
#include <sstream>
#include <string>

#include "experiments/pipeline.h"
#include "models/error.h"

namespace artex {
namespace {

void BindWeights(const Config& c, PoseGroupWeights* w) {
  c.CheckKeys({"scale", "translation", "rotation", "joints"});
  c.Get("scale", &w->scale);
  c.Get("translation", &w->translation);
  c.Get("rotation", &w->rotation);
  c.Get("joints", &w->joints);
}

// fitting.prediction and its sections (solvers/prediction.h); the older
// constant_velocity_prediction: true|false means prediction: constant_velocity|previous.
void BindPrediction(const Config& c, PredictionOptions* o) {
  if (c.Has("constant_velocity_prediction")) {
    bool cv = true;
    c.Get("constant_velocity_prediction", &cv);
    o->model = cv ? PredictionModel::kConstantVelocity : PredictionModel::kPrevious;
    if (c.Has("prediction")) {
      PredictionModel model = o->model;
      c.GetEnum("prediction", PredictionModelNames(), &model);
      if (model != o->model) {
        throw Error(c.Path("constant_velocity_prediction") + ": expected no value or one that " +
                    "agrees with prediction: " + PredictionModelName(model) + ", found " +
                    (cv ? "true" : "false"));
      }
    }
  }
  c.GetEnum("prediction", PredictionModelNames(), &o->model);
  c.Get("temporal_prior_on_prediction", &o->temporal_prior_on_prediction);
  const Config k = c.Section("kalman");
  k.CheckKeys({"acceleration", "process_noise", "information_scale", "measurement_noise",
               "initial_velocity_std", "initial_acceleration_std"});
  k.Get("acceleration", &o->kalman.acceleration);
  BindWeights(k.Section("process_noise"), &o->kalman.process_noise);
  k.Get("information_scale", &o->kalman.information_scale);
  BindWeights(k.Section("measurement_noise"), &o->kalman.measurement_noise);
  BindWeights(k.Section("initial_velocity_std"), &o->kalman.initial_velocity_std);
  BindWeights(k.Section("initial_acceleration_std"), &o->kalman.initial_acceleration_std);
  const Config p = c.Section("particle");
  p.CheckKeys({"base", "trigger", "trigger_score", "step_scales", "hypotheses",
               "hypothesis_iterations", "accept_margin", "limb_rotation_std",
               "child_rotation_factor", "max_limb_joints", "translation_std", "global_rotation_std",
               "seed"});
  p.GetEnum("base", PredictionModelNames(), &o->particle.base);
  p.GetEnum("trigger", ParticleTriggerNames(), &o->particle.trigger);
  p.Get("trigger_score", &o->particle.trigger_score);
  p.Get("step_scales", &o->particle.step_scales);
  p.Get("hypotheses", &o->particle.hypotheses);
  p.Get("hypothesis_iterations", &o->particle.hypothesis_iterations);
  p.Get("accept_margin", &o->particle.accept_margin);
  p.Get("limb_rotation_std", &o->particle.limb_rotation_std);
  p.Get("child_rotation_factor", &o->particle.child_rotation_factor);
  p.Get("max_limb_joints", &o->particle.max_limb_joints);
  p.Get("translation_std", &o->particle.translation_std);
  p.Get("global_rotation_std", &o->particle.global_rotation_std);
  int seed = static_cast<int>(o->particle.seed);
  p.Get("seed", &seed);
  if (seed < 0) throw Error(p.Path("seed") + ": expected >= 0, found " + std::to_string(seed));
  o->particle.seed = static_cast<uint64_t>(seed);
}

void BindPlanes(const Config& c, PlaneDetectionOptions* o) {
  c.CheckKeys({"sample_stride", "ransac_iterations", "score_points", "inlier_distance",
               "inlier_growth", "merge_angle_deg", "merge_distance", "max_planes",
               "min_inlier_fraction", "min_extent", "floor_min_extent", "min_coverage",
               "floor_max_angle_deg", "wall_max_angle_deg", "min_depth", "max_depth", "seed"});
  c.Get("sample_stride", &o->sample_stride);
  c.Get("ransac_iterations", &o->ransac_iterations);
  c.Get("score_points", &o->score_points);
  c.Get("inlier_distance", &o->inlier_distance);
  c.Get("inlier_growth", &o->inlier_growth);
  c.Get("merge_angle_deg", &o->merge_angle_deg);
  c.Get("merge_distance", &o->merge_distance);
  c.Get("max_planes", &o->max_planes);
  c.Get("min_inlier_fraction", &o->min_inlier_fraction);
  c.Get("min_extent", &o->min_extent);
  c.Get("floor_min_extent", &o->floor_min_extent);
  c.Get("min_coverage", &o->min_coverage);
  c.Get("floor_max_angle_deg", &o->floor_max_angle_deg);
  c.Get("wall_max_angle_deg", &o->wall_max_angle_deg);
  c.Get("min_depth", &o->min_depth);
  c.Get("max_depth", &o->max_depth);
  int seed = static_cast<int>(o->seed);
  c.Get("seed", &seed);
  o->seed = static_cast<uint64_t>(seed);
}

void BindSegmentation(const Config& c, SubjectSegmentationOptions* o) {
  c.CheckKeys({"min_depth", "max_depth", "plane_margin", "plane_margin_growth", "connect_distance",
               "connect_growth", "merge_relative", "fragment_height", "stacked_max_overlap", "stacked_max_gap", "split_people", "head_bin", "head_top_range", "head_depth", "max_head_width", "shoulder_drop", "min_shoulder_width", "min_head_separation", "min_valley", "min_pixels", "min_height",
               "max_height", "max_width", "subject", "pixel", "track_max_distance"});
  c.Get("min_depth", &o->min_depth);
  c.Get("max_depth", &o->max_depth);
  c.Get("plane_margin", &o->plane_margin);
  c.Get("plane_margin_growth", &o->plane_margin_growth);
  c.Get("connect_distance", &o->connect_distance);
  c.Get("connect_growth", &o->connect_growth);
  c.Get("merge_relative", &o->merge_relative);
  c.Get("fragment_height", &o->fragment_height);
  c.Get("stacked_max_overlap", &o->stacked_max_overlap);
  c.Get("stacked_max_gap", &o->stacked_max_gap);
  c.Get("split_people", &o->split_people);
  c.Get("head_bin", &o->head_bin);
  c.Get("head_top_range", &o->head_top_range);
  c.Get("head_depth", &o->head_depth);
  c.Get("max_head_width", &o->max_head_width);
  c.Get("shoulder_drop", &o->shoulder_drop);
  c.Get("min_shoulder_width", &o->min_shoulder_width);
  c.Get("min_head_separation", &o->min_head_separation);
  c.Get("min_valley", &o->min_valley);
  c.Get("min_pixels", &o->min_pixels);
  c.Get("min_height", &o->min_height);
  c.Get("max_height", &o->max_height);
  c.Get("max_width", &o->max_width);
  c.GetEnum("subject", SubjectChoiceNames(), &o->choice);
  if (c.Has("pixel")) {
    std::vector<double> pixel;
    c.Get("pixel", &pixel);
    if (pixel.size() != 2 || pixel[0] < 0 || pixel[1] < 0)
      throw Error("preprocess.segmentation.pixel: expected [column, row] >= 0");
    o->pixel = Eigen::Vector2i(static_cast<int>(pixel[0]), static_cast<int>(pixel[1]));
  }
  c.Get("track_max_distance", &o->track_max_distance);
}

void BindPreprocess(const Config& c, PreprocessOptions* o) {
  c.CheckKeys({"foreground", "world_frame", "assumed_camera_height", "planes", "segmentation",
               "background", "mesh", "silhouette"});
  c.GetEnum("foreground", ForegroundModeNames(), &o->foreground);
  c.GetEnum("world_frame", WorldFrameModeNames(), &o->world_frame);
  c.Get("assumed_camera_height", &o->assumed_camera_height);
  BindPlanes(c.Section("planes"), &o->segmentation.planes);
  BindSegmentation(c.Section("segmentation"), &o->segmentation);
  const Config b = c.Section("background");
  b.CheckKeys({"min_valid_samples", "noise_sigma_at_1m", "use_mad", "threshold_sigmas",
               "min_foreground_distance", "min_depth", "max_depth", "opening_radius",
               "closing_radius", "keep_largest_component"});
  b.Get("min_valid_samples", &o->background.min_valid_samples);
  b.Get("noise_sigma_at_1m", &o->background.noise_sigma_at_1m);
  b.Get("use_mad", &o->background.use_mad);
  b.Get("threshold_sigmas", &o->background.threshold_sigmas);
  b.Get("min_foreground_distance", &o->background.min_foreground_distance);
  b.Get("min_depth", &o->background.min_depth);
  b.Get("max_depth", &o->background.max_depth);
  b.Get("opening_radius", &o->background.opening_radius);
  b.Get("closing_radius", &o->background.closing_radius);
  b.Get("keep_largest_component", &o->background.keep_largest_component);
  const Config sil = c.Section("silhouette");
  sil.CheckKeys({"enabled", "raster_width", "edge_margin_px", "zero_depth", "presegmented_fraction"});
  sil.Get("enabled", &o->silhouette.enabled);
  sil.Get("raster_width", &o->silhouette.raster_width);
  sil.Get("edge_margin_px", &o->silhouette.edge_margin_px);
  sil.GetEnum("zero_depth", ZeroDepthMeaningNames(), &o->silhouette.zero_depth);
  sil.Get("presegmented_fraction", &o->silhouette.presegmented_fraction);
  const Config m = c.Section("mesh");
  m.CheckKeys({"step", "max_relative_jump", "drop_isolated_points"});
  m.Get("step", &o->mesh.step);
  m.Get("max_relative_jump", &o->mesh.max_relative_jump);
  m.Get("drop_isolated_points", &o->mesh.drop_isolated_points);
}

void BindIcpInit(const Config& c, IcpInitOptions* o) {
  c.CheckKeys({"coarse_alignment", "facing_camera", "estimate_scale", "scale_from_extent",
               "max_iterations", "max_distance", "min_normal_dot", "max_scan_points", "tolerance",
               "extent_quantile", "kd_leaf_size", "grid_cell"});
  c.Get("coarse_alignment", &o->coarse_alignment);
  c.Get("facing_camera", &o->facing_camera);
  c.Get("estimate_scale", &o->estimate_scale);
  c.Get("scale_from_extent", &o->scale_from_extent);
  c.Get("max_iterations", &o->max_iterations);
  c.Get("max_distance", &o->max_distance);
  c.Get("min_normal_dot", &o->min_normal_dot);
  c.Get("max_scan_points", &o->max_scan_points);
  c.Get("tolerance", &o->tolerance);
  c.Get("extent_quantile", &o->extent_quantile);
  c.Get("kd_leaf_size", &o->kd_leaf_size);
  c.Get("grid_cell", &o->grid_cell);
}

void BindQuality(const Config& c, FitQualityOptions* o) {
  c.CheckKeys({"inlier_distance", "max_scan_points", "raster_width", "support_tolerance",
               "layer_gap", "depth_truncation", "good_min_inlier_fraction",
               "good_min_support_fraction", "good_max_depth_residual", "lost_min_inlier_fraction",
               "lost_min_support_fraction", "lost_max_depth_residual", "part_min_visible",
               "part_min_support", "part_ignore"});
  c.Get("inlier_distance", &o->inlier_distance);
  c.Get("max_scan_points", &o->max_scan_points);
  c.Get("raster_width", &o->raster_width);
  c.Get("support_tolerance", &o->support_tolerance);
  c.Get("layer_gap", &o->layer_gap);
  c.Get("depth_truncation", &o->depth_truncation);
  c.Get("good_min_inlier_fraction", &o->good_min_inlier_fraction);
  c.Get("good_min_support_fraction", &o->good_min_support_fraction);
  c.Get("good_max_depth_residual", &o->good_max_depth_residual);
  c.Get("lost_min_inlier_fraction", &o->lost_min_inlier_fraction);
  c.Get("lost_min_support_fraction", &o->lost_min_support_fraction);
  c.Get("lost_max_depth_residual", &o->lost_max_depth_residual);
  c.Get("part_min_visible", &o->part_min_visible);
  c.Get("part_min_support", &o->part_min_support);
  c.Get("part_ignore", &o->part_ignore);
}

void BindInitializer(const Config& c, InitializerOptions* o) {
  c.CheckKeys({"yaws_deg", "world_up", "arm_angles_deg", "coarse_iterations", "em_candidates",
               "em_one_per_yaw", "max_knee_hyperextension_deg", "ranking_iterations",
               "refine_arms", "refine_side_angles_deg",
               "refine_front_angles_deg", "refine_forearm_bends", "icp"});
  c.Get("yaws_deg", &o->yaws_deg);
  if (c.Has("world_up")) {
    std::vector<double> up;
    c.Get("world_up", &up);
    if (up.size() != 3) {
      std::ostringstream msg;
      msg << c.Path("world_up") << ": expected 3 values (x, y, z), found " << up.size();
      throw Error(msg.str());
    }
    o->world_up = Eigen::Vector3d(up[0], up[1], up[2]);
  }
  c.Get("arm_angles_deg", &o->arm_angles_deg);
  c.Get("coarse_iterations", &o->coarse_iterations);
  c.Get("em_candidates", &o->em_candidates);
  c.Get("em_one_per_yaw", &o->em_one_per_yaw);
  c.Get("max_knee_hyperextension_deg", &o->max_knee_hyperextension_deg);
  c.Get("ranking_iterations", &o->ranking_iterations);
  c.Get("refine_arms", &o->refine_arms);
  c.Get("refine_side_angles_deg", &o->refine_side_angles_deg);
  c.Get("refine_front_angles_deg", &o->refine_front_angles_deg);
  c.GetEnumList("refine_forearm_bends", ForearmBendNames(), &o->refine_forearm_bends);
  BindIcpInit(c.Section("icp"), &o->icp);
}

// fitting.joint_limits: {weight, preset, joints: {NAME: {min_deg: [x, y, z], max_deg: [...]}}}.
void BindJointLimits(const Config& c, JointLimitOptions* o) {
  c.CheckKeys({"weight", "preset", "joints"});
  c.Get("weight", &o->weight);
  c.GetEnum("preset", JointLimitPresetNames(), &o->preset);
  const Config joints = c.Section("joints");
  for (const std::string& name : joints.Keys()) {
    const Config j = joints.Section(name);
    j.CheckKeys({"min_deg", "max_deg"});
    JointBox box;
    for (const auto& [key, out] : {std::pair{"min_deg", &box.min}, std::pair{"max_deg", &box.max}}) {
      std::vector<double> deg;
      j.Get(key, &deg);
      if (deg.size() != 3) {
        throw Error(j.Path(key) + ": expected 3 angles in degrees (x, y, z), found " +
                    std::to_string(deg.size()) + " values");
      }
      *out = Eigen::Vector3d(deg[0], deg[1], deg[2]) * (M_PI / 180.0);
    }
    o->joints[name] = box;
  }
}

// fitting.joint_coupling: {weight, pairs: [A, B, C, D, ...]}: the pairs (A, B), (C, D), ...
void BindJointCoupling(const Config& c, JointCouplingOptions* o) {
  c.CheckKeys({"weight", "pairs"});
  c.Get("weight", &o->weight);
  if (!c.Has("pairs")) return;
  std::vector<std::string> names;
  c.Get("pairs", &names);
  if (names.size() % 2 != 0) {
    throw Error(c.Path("pairs") + ": expected joint names two by two (pairs), found " +
                std::to_string(names.size()) + " names");
  }
  o->pairs.clear();
  for (std::size_t i = 0; i < names.size(); i += 2) o->pairs.emplace_back(names[i], names[i + 1]);
}

void BindFitting(const Config& c, EMFitterOptions* o) {
  c.CheckKeys({"correspondence", "solver", "estep", "k", "voxel_fraction", "epsilon",
               "lambda_color", "use_color", "normalize_per_scan_point", "icp_metric",
               "icp_max_distance", "icp_min_normal_dot", "first_frame_radii", "tracking_radii",
               "first_frame_iterations_per_stage", "tracking_iterations_per_stage",
               "max_iterations", "over_relaxation", "relative_cost_tolerance",
               "parameter_tolerance", "normalize_data_term", "tikhonov", "temporal",
               "smoothness", "joint_limits", "joint_coupling", "scale_mode",
               "scale_estimation_frames", "scale_max_radius", "scale_prior_weight",
               "icp_first_frame", "constant_velocity_prediction", "max_fit_vertices",
               "tracking_max_fit_vertices", "tracking_shared_cloud",
               "min_scan_points", "max_mean_motion", "max_scale_change", "ceres_max_iterations",
               "solver_threads", "candidate_margin", "normal_refresh_iterations",
               "tracking_tikhonov",
               "fit_vertex_selection", "scale_estimator", "scale_sample_max_distance",
               "scale_sample_min_pair_fraction", "scale_sample_max_scan_points",
               "scale_sample_tolerance", "scale_sample_grid_cell", "icp_init",
               "init", "quality", "prediction", "kalman", "particle",
               "temporal_prior_on_prediction", "silhouette", "unobserved_joints", "upright",
               "out_of_view"});
  c.GetEnum("correspondence", CorrespondenceModelNames(), &o->correspondence);
  c.GetEnum("solver", FitSolverTypeNames(), &o->solver.type);
  c.GetEnum("estep",
            std::map<std::string, EStepMode>{{"dense", EStepMode::kDense},
                                             {"truncated", EStepMode::kRadius},
                                             {"radius", EStepMode::kRadius},
                                             {"knn", EStepMode::kKNearest}},
            &o->estep.mode);
  c.Get("k", &o->estep.k);
  c.Get("voxel_fraction", &o->estep.voxel_fraction);
  c.Get("epsilon", &o->estep.weights.epsilon);
  c.Get("lambda_color", &o->estep.weights.lambda_color);
  c.Get("use_color", &o->estep.weights.use_color);
  c.Get("normalize_per_scan_point", &o->estep.weights.normalize_per_scan_point);
  c.GetEnum("icp_metric",
            std::map<std::string, IcpMetric>{{"point_to_point", IcpMetric::kPointToPoint},
                                             {"point_to_plane", IcpMetric::kPointToPlane}},
            &o->one_to_one.metric);
  c.Get("icp_max_distance", &o->one_to_one.max_distance);
  c.Get("icp_min_normal_dot", &o->one_to_one.min_normal_dot);
  c.Get("first_frame_radii", &o->first_frame_radii);
  c.Get("tracking_radii", &o->tracking_radii);
  c.Get("first_frame_iterations_per_stage", &o->first_frame_iterations_per_stage);
  c.Get("tracking_iterations_per_stage", &o->tracking_iterations_per_stage);
  c.Get("max_iterations", &o->max_iterations);
  c.Get("over_relaxation", &o->over_relaxation);
  c.Get("relative_cost_tolerance", &o->relative_cost_tolerance);
  c.Get("parameter_tolerance", &o->parameter_tolerance);
  c.Get("normalize_data_term", &o->normalize_data_term);
  BindWeights(c.Section("tikhonov"), &o->tikhonov.update);
  BindWeights(c.Section("temporal"), &o->tikhonov.temporal);
  BindWeights(c.Section("smoothness"), &o->smoothness);
  BindJointLimits(c.Section("joint_limits"), &o->joint_limits);
  BindJointCoupling(c.Section("joint_coupling"), &o->joint_coupling);
  const Config sil = c.Section("silhouette");
  sil.CheckKeys({"weight", "depth_margin", "front_weight", "max_radius"});
  sil.Get("max_radius", &o->silhouette.max_radius);
  sil.Get("front_weight", &o->silhouette.front_weight);
  sil.Get("weight", &o->silhouette.weight);
  sil.Get("depth_margin", &o->silhouette.depth_margin);
  const Config upright = c.Section("upright");
  upright.CheckKeys({"weight", "max_tilt_deg", "only_out_of_view"});
  upright.Get("weight", &o->upright.weight);
  upright.Get("max_tilt_deg", &o->upright.max_tilt_deg);
  upright.Get("only_out_of_view", &o->upright.only_out_of_view);
  const Config unobserved = c.Section("unobserved_joints");
  unobserved.CheckKeys({"weight", "min_observed_fraction"});
  unobserved.Get("weight", &o->unobserved_joints.weight);
  unobserved.Get("min_observed_fraction", &o->unobserved_joints.min_observed_fraction);
  const Config out_of_view = c.Section("out_of_view");
  out_of_view.CheckKeys({"min_in_view_fraction", "hold_cut_bones", "border_px", "min_vertices"});
  out_of_view.Get("min_in_view_fraction", &o->out_of_view.min_in_view_fraction);
  out_of_view.Get("hold_cut_bones", &o->out_of_view.hold_cut_bones);
  out_of_view.Get("border_px", &o->out_of_view.border_px);
  out_of_view.Get("min_vertices", &o->out_of_view.min_vertices);
  c.GetEnum("scale_mode", ScaleModeNames(), &o->scale_mode);
  c.Get("scale_estimation_frames", &o->scale_estimation_frames);
  c.Get("scale_max_radius", &o->scale_max_radius);
  c.Get("scale_prior_weight", &o->scale_prior_weight);
  c.Get("icp_first_frame", &o->icp_first_frame);
  BindPrediction(c, &o->prediction);
  c.Get("max_fit_vertices", &o->max_fit_vertices);
  c.Get("tracking_max_fit_vertices", &o->tracking_max_fit_vertices);
  c.Get("tracking_shared_cloud", &o->tracking_shared_cloud);
  c.Get("min_scan_points", &o->min_scan_points);
  c.Get("max_mean_motion", &o->max_mean_motion);
  c.Get("max_scale_change", &o->max_scale_change);
  c.Get("ceres_max_iterations", &o->solver.max_iterations);
  c.Get("solver_threads", &o->solver.num_threads);
  c.Get("candidate_margin", &o->estep.candidate_margin);
  c.Get("normal_refresh_iterations", &o->normal_refresh_iterations);
  BindWeights(c.Section("tracking_tikhonov"), &o->tracking_update);
  c.GetEnum("fit_vertex_selection", FitVertexSelectionNames(), &o->fit_vertex_selection);
  c.GetEnum("scale_estimator", ScaleEstimatorNames(), &o->scale_estimator);
  c.Get("scale_sample_max_distance", &o->scale_sample_max_distance);
  c.Get("scale_sample_min_pair_fraction", &o->scale_sample_min_pair_fraction);
  c.Get("scale_sample_max_scan_points", &o->scale_sample_max_scan_points);
  c.Get("scale_sample_tolerance", &o->scale_sample_tolerance);
  c.Get("scale_sample_grid_cell", &o->scale_sample_grid_cell);
  BindIcpInit(c.Section("icp_init"), &o->icp);
}

void BindTexture(const Config& c, TexturingOptions* o) {
  c.CheckKeys({"beta",
               "t_max",
               "alpha",
               "lambda",
               "seam_distance_scale",
               "min_quality",
               "untextured_cost",
               "max_candidates",
               "solver",
               "mrf_max_iterations",
               "mrf_parallel_min_nodes",
               "trws_max_iterations",
               "warm_start",
               "max_images",
               "hard_max_images",
               "histogram_bins",
               "edge_samples",
               "atlas_size",
               "padding_texels",
               "seam_levelling",
               "levelling_every_frame",
               "levelling_smoothness",
               "add_every",
               "depth_tolerance",
               "switch_cost",
               "raster_scale",
               "surface_aware_sampling",
               "vertex_colors_need_full_ring"});
  TextureTermOptions& t = o->selection.terms;
  c.Get("beta", &t.beta);
  c.Get("t_max", &t.t_max);
  c.Get("alpha", &t.alpha);
  c.Get("lambda", &t.lambda);
  c.Get("seam_distance_scale", &t.seam_distance_scale);
  c.Get("min_quality", &t.min_quality);
  c.Get("untextured_cost", &o->selection.untextured_cost);
  c.Get("max_candidates", &o->selection.max_candidates);
  if (c.Has("solver")) {
    std::string name;
    c.Get("solver", &name);
    try {
      o->mrf.type = ParseMrfSolverType(name);
    } catch (const Error& e) {
      throw Error(c.Path("solver") + ": " + e.what());
    }
  }
  c.Get("mrf_max_iterations", &o->mrf.max_iterations);
  c.Get("mrf_parallel_min_nodes", &o->mrf.expansion_parallel_min_nodes);
  c.Get("trws_max_iterations", &o->mrf.trws_max_iterations);
  c.Get("warm_start", &o->mrf.warm_start);
  c.Get("max_images", &o->pool.max_images);
  c.Get("hard_max_images", &o->pool.hard_max_images);
  c.Get("histogram_bins", &o->pool.histogram_bins);
  c.Get("edge_samples", &o->pool.edge_samples);
  c.Get("atlas_size", &o->atlas_size);
  c.Get("padding_texels", &o->padding_texels);
  c.Get("seam_levelling", &o->seam_levelling);
  c.Get("levelling_every_frame", &o->levelling_every_frame);
  c.Get("levelling_smoothness", &o->levelling.smoothness);
  c.Get("add_every", &o->add_every);
  c.Get("depth_tolerance", &o->visibility.depth_tolerance);
  c.Get("switch_cost", &t.switch_cost);
  c.Get("raster_scale", &o->visibility.raster_scale);
  c.Get("surface_aware_sampling", &o->pool.surface_aware_sampling);
  c.Get("vertex_colors_need_full_ring", &o->pool.vertex_colors_need_full_ring);
}

void BindInput(const Config& c, FrameSourceOptions* o) {
  c.CheckKeys({"intrinsics", "max_time_difference", "time_offset", "accelerometer",
               "min_gravity_norm", "calibration"});
  if (c.Has("intrinsics")) {
    std::string intrinsics;
    c.Get("intrinsics", &intrinsics);
    o->tum.SetIntrinsics(intrinsics);
  }
  c.Get("max_time_difference", &o->tum.max_time_difference);
  o->mkv.max_time_difference = o->tum.max_time_difference;
  c.Get("calibration", &o->mkv.calibration_path);
  c.Get("time_offset", &o->tum.time_offset);
  c.Get("accelerometer", &o->tum.read_accelerometer);
  c.Get("min_gravity_norm", &o->tum.min_gravity_norm);
}

void BindPipeline(const Config& c, PipelineOptions* o) {
  c.CheckKeys({"texture", "colour_term", "first_frame", "max_frames", "export_meshes",
               "export_foreground", "export_glb", "glb_exact", "glb_exact_max_frames", "export_bvh",
               "export_textured_mesh", "mesh_up_axis", "lost_threshold_mm",
               "texture_doubtful_frames", "texture_every", "reinitialise_on", "reinitialise_after_doubtful",
               "reinitialise_auto_wins", "reinitialise_auto_window", "gap_refit_frames",
               "gap_refit_radii", "gap_refit_iterations_per_stage", "gap_refit_leg_stride_deg",
               "gap_refit_stride_frames",
               "texture_quality_every", "texture_quality_yaws_deg", "texture_quality_height",
               "export_atlases", "stream", "stream_estimate", "concurrency", "queue_depth",
               "max_frames_in_flight", "live",
               "live_queue_depth", "live_init_queue_depth", "live_init_drain_every", "live_rate_hz",
               "evaluate_in_background", "evaluation_queue_depth",
               "colour_delay_frames", "live_texture_skip",
               "threads", "blas_threads", "heap_retain_mb", "heap_arenas", "huge_pages",
               "template_cache", "template_cache_dir", "template_cache_keep"});
  c.Get("texture", &o->texture);
  c.Get("colour_term", &o->colour_term);
  c.Get("first_frame", &o->first_frame);
  c.Get("max_frames", &o->max_frames);
  c.Get("export_meshes", &o->export_meshes);
  c.Get("export_foreground", &o->export_foreground);
  c.Get("export_glb", &o->export_glb);
  c.Get("glb_exact", &o->glb_exact);
  c.Get("glb_exact_max_frames", &o->glb_exact_max_frames);
  c.Get("export_bvh", &o->export_bvh);
  c.Get("export_textured_mesh", &o->export_textured_mesh);
  c.GetEnum("mesh_up_axis", UpAxisNames(), &o->mesh_up_axis);
  c.Get("lost_threshold_mm", &o->lost_threshold_mm);
  c.Get("texture_doubtful_frames", &o->texture_doubtful_frames);
  c.Get("texture_every", &o->texture_every);
  c.GetEnum("reinitialise_on", ReinitialiseOnNames(), &o->reinitialise_on);
  c.Get("reinitialise_after_doubtful", &o->reinitialise_after_doubtful);
  c.Get("reinitialise_auto_wins", &o->reinitialise_auto_wins);
  c.Get("reinitialise_auto_window", &o->reinitialise_auto_window);
  c.Get("gap_refit_frames", &o->gap_refit_frames);
  c.Get("gap_refit_radii", &o->gap_refit.radii);
  c.Get("gap_refit_iterations_per_stage", &o->gap_refit.iterations_per_stage);
  c.Get("gap_refit_leg_stride_deg", &o->gap_refit.leg_stride_deg);
  c.Get("gap_refit_stride_frames", &o->gap_refit_stride_frames);
  c.Get("texture_quality_every", &o->texture_quality_every);
  c.Get("texture_quality_yaws_deg", &o->held_out.yaws_deg);
  c.Get("texture_quality_height", &o->held_out.height);
  c.Get("export_atlases", &o->export_atlases);
  c.Get("stream", &o->stream_path);
  c.Get("stream_estimate", &o->stream_estimate);
  c.GetEnum("concurrency", PipelineConcurrencyNames(), &o->realtime.concurrency);
  c.Get("queue_depth", &o->realtime.queue_depth);
  c.Get("max_frames_in_flight", &o->realtime.max_frames_in_flight);
  c.Get("live", &o->realtime.live);
  c.Get("live_queue_depth", &o->realtime.live_queue_depth);
  c.Get("live_init_queue_depth", &o->realtime.live_init_queue_depth);
  c.Get("live_init_drain_every", &o->realtime.live_init_drain_every);
  c.Get("evaluate_in_background", &o->realtime.evaluate_in_background);
  c.Get("evaluation_queue_depth", &o->realtime.evaluation_queue_depth);
  c.Get("live_texture_skip", &o->realtime.live_texture_skip);
  c.Get("live_rate_hz", &o->realtime.live_rate_hz);
  c.Get("colour_delay_frames", &o->realtime.colour_delay_frames);
  c.Get("threads", &o->realtime.threads);
  c.Get("heap_retain_mb", &o->realtime.heap_retain_mb);
  c.Get("heap_arenas", &o->realtime.heap_arenas);
  c.Get("huge_pages", &o->realtime.huge_pages);
  c.Get("blas_threads", &o->realtime.blas_threads);
  c.Get("template_cache", &o->template_cache.enabled);
  c.Get("template_cache_dir", &o->template_cache.directory);
  c.Get("template_cache_keep", &o->template_cache.keep_files);
}

void BindStream(const Config& c, StreamOptions* o) {
  c.CheckKeys({"codec", "texture_kbps", "buffer_ms", "speed", "threads", "min_quantizer",
               "keyframe_interval", "video_size", "pose_scale_step", "pose_translation_step",
               "pose_rotation_step", "pose_prediction", "measure_pose_error"});
  if (c.Has("codec")) {
    std::string name;
    c.Get("codec", &name);
    try {
      o->video.codec = ParseVideoCodec(name);
    } catch (const Error& e) {
      throw Error(c.Path("codec") + ": " + e.what());
    }
  }
  c.Get("texture_kbps", &o->video.bitrate_kbps);
  c.Get("buffer_ms", &o->video.buffer_ms);
  c.Get("speed", &o->video.speed);
  c.Get("threads", &o->video.threads);
  c.Get("min_quantizer", &o->video.min_quantizer);
  c.Get("keyframe_interval", &o->keyframe_interval);
  c.Get("video_size", &o->video_size);
  c.Get("pose_scale_step", &o->pose.scale_step);
  c.Get("pose_translation_step", &o->pose.translation_step);
  c.Get("pose_rotation_step", &o->pose.rotation_step);
  if (c.Has("pose_prediction")) {
    std::string name;
    c.Get("pose_prediction", &name);
    try {
      o->pose.prediction = ParsePosePrediction(name);
    } catch (const Error& e) {
      throw Error(c.Path("pose_prediction") + ": " + e.what());
    }
  }
  c.Get("measure_pose_error", &o->measure_pose_error);
}

}  // namespace

const std::map<std::string, ReinitialiseOn>& ReinitialiseOnNames() {
  static const std::map<std::string, ReinitialiseOn> names = {
      {"lost", ReinitialiseOn::kLost},
      {"doubtful", ReinitialiseOn::kDoubtful},
      {"auto", ReinitialiseOn::kAuto}};
  return names;
}

bool PipelineOptions::IsValid(std::string* error) const {
  if (!input.IsValid(error) || !preprocess.IsValid(error) || !fitting.IsValid(error)) return false;
  std::string inner;
  if (!initializer.IsValid(&inner)) {
    if (error) *error = "fitting.init." + inner;
    return false;
  }
  if (!quality.IsValid(&inner)) {
    if (error) *error = "fitting.quality." + inner;
    return false;
  }
  if (texture && !texturing.IsValid(error)) return false;
  if (!shape.IsValid(error)) return false;
  if (shape.retrack && realtime.live) {
    if (error) *error = "shape.retrack: expected a recorded run, found pipeline.live: true (a live "
                        "run cannot be tracked twice)";
    return false;
  }
  if (!held_out.IsValid(&inner)) {
    if (error) *error = "pipeline.texture_quality_*: " + inner;
    return false;
  }
  if (!stream.IsValid(error)) return false;
  if (!realtime.IsValid(error)) return false;
  if (!template_cache.IsValid(&inner)) {
    if (error) *error = "pipeline." + inner;
    return false;
  }
  std::ostringstream msg;
  if (first_frame < 0)
    msg << "pipeline.first_frame: expected >= 0, found " << first_frame;
  else if (max_frames < 0)
    msg << "pipeline.max_frames: expected >= 0, found " << max_frames;
  else if (reinitialise_after_doubtful < 0)
    msg << "pipeline.reinitialise_after_doubtful: expected >= 0 (0: never), found "
        << reinitialise_after_doubtful;
  else if (gap_refit_frames < 0)
    msg << "pipeline.gap_refit_frames: expected >= 0 (0: off), found " << gap_refit_frames;
  else if (gap_refit_stride_frames < 0)
    msg << "pipeline.gap_refit_stride_frames: expected >= 0, found " << gap_refit_stride_frames;
  else if (!gap_refit.IsValid(&inner))
    msg << "pipeline.gap_refit_" << inner;
  else if (reinitialise_auto_wins < 1 || reinitialise_auto_window < reinitialise_auto_wins)
    msg << "pipeline.reinitialise_auto_wins/window: expected 1 <= wins <= window, found "
        << reinitialise_auto_wins << " / " << reinitialise_auto_window;
  else if (!(lost_threshold_mm > 0))
    msg << "pipeline.lost_threshold_mm: expected > 0, found " << lost_threshold_mm;
  else if (glb_exact_max_frames < 0)
    msg << "pipeline.glb_exact_max_frames: expected >= 0, found " << glb_exact_max_frames;
  else if (texture_every < 1)
    msg << "pipeline.texture_every: expected >= 1, found " << texture_every;
  else if (texture_quality_every < 0)
    msg << "pipeline.texture_quality_every: expected >= 0, found " << texture_quality_every;
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

// Section shape (solvers/shape_estimator.h).
void BindShape(const Config& c, ShapeOptions* o) {
  c.CheckKeys({"mode", "retrack", "symmetric", "seed_pose", "leaf_lengths", "fork_widths",
               "girth_depth", "depth_prior_weight",
               "calibration_frames", "calibration_stride", "calibration_rounds", "radii",
               "iterations_per_stage", "over_relaxation", "bias_correction",
               "visibility_min_cos", "bias_density", "bias_scan_mask", "bias_mask_tolerance",
               "bias_rendered_scan_to_model", "bias_rendered_estep_max_radius",
               "bias_mask_radius_px", "floor_weight", "girth_max_radius", "scan_to_model_weight",
               "scan_to_model_voxel", "scan_to_model_max_distance",
               "scan_to_model_normal_distance", "scan_to_model_girth", "hold_unseen",
               "chain_prior_weight", "limb_girth_prior_weight", "prior_weight", "pose_damping",
               "bone_min", "bone_max", "girth_min", "girth_max", "refine_every",
               "refine_prior_weight", "max_fit_vertices", "joint_limits", "detail"});
  c.GetEnum("mode", ShapeModeNames(), &o->mode);
  c.Get("retrack", &o->retrack);
  c.Get("symmetric", &o->symmetric);
  c.Get("seed_pose", &o->seed_pose);
  c.Get("leaf_lengths", &o->leaf_lengths);
  c.Get("fork_widths", &o->fork_widths);
  c.Get("girth_depth", &o->girth_depth);
  c.Get("depth_prior_weight", &o->depth_prior_weight);
  c.Get("calibration_frames", &o->calibration_frames);
  c.Get("calibration_stride", &o->calibration_stride);
  c.Get("calibration_rounds", &o->calibration_rounds);
  c.Get("radii", &o->radii);
  c.Get("iterations_per_stage", &o->iterations_per_stage);
  c.Get("over_relaxation", &o->over_relaxation);
  c.Get("bias_correction", &o->bias_correction);
  c.Get("visibility_min_cos", &o->visibility_min_cos);
  c.Get("bias_density", &o->bias_density);
  c.Get("bias_scan_mask", &o->bias_scan_mask);
  c.Get("bias_rendered_scan_to_model", &o->bias_rendered_scan_to_model);
  c.Get("bias_rendered_estep_max_radius", &o->bias_rendered_estep_max_radius);
  c.Get("bias_mask_tolerance", &o->bias_mask_tolerance);
  c.Get("bias_mask_radius_px", &o->bias_mask_radius_px);
  c.Get("floor_weight", &o->floor_weight);
  c.Get("girth_max_radius", &o->girth_max_radius);
  c.Get("scan_to_model_weight", &o->scan_to_model_weight);
  c.Get("scan_to_model_voxel", &o->scan_to_model_voxel);
  c.Get("scan_to_model_max_distance", &o->scan_to_model_max_distance);
  c.Get("scan_to_model_normal_distance", &o->scan_to_model_normal_distance);
  c.Get("hold_unseen", &o->hold_unseen);
  c.Get("scan_to_model_girth", &o->scan_to_model_girth);
  c.Get("chain_prior_weight", &o->chain_prior_weight);
  c.Get("limb_girth_prior_weight", &o->limb_girth_prior_weight);
  c.Get("prior_weight", &o->prior_weight);
  c.Get("pose_damping", &o->pose_damping);
  c.Get("bone_min", &o->bone_min);
  c.Get("bone_max", &o->bone_max);
  c.Get("girth_min", &o->girth_min);
  c.Get("girth_max", &o->girth_max);
  c.Get("refine_every", &o->refine_every);
  c.Get("refine_prior_weight", &o->refine_prior_weight);
  c.Get("max_fit_vertices", &o->max_fit_vertices);
  const Config d = c.Section("detail");
  d.CheckKeys({"enabled", "frames", "iterations", "max_distance", "max_tangential",
               "normal_min_cos", "visibility_min_cos", "occlusion_tolerance", "smoothness",
               "prior_weight", "max_offset", "bias_bins", "bias_per_segment"});
  d.Get("enabled", &o->detail.enabled);
  d.Get("frames", &o->detail.frames);
  d.Get("iterations", &o->detail.iterations);
  d.Get("max_distance", &o->detail.max_distance);
  d.Get("max_tangential", &o->detail.max_tangential);
  d.Get("normal_min_cos", &o->detail.normal_min_cos);
  d.Get("visibility_min_cos", &o->detail.visibility_min_cos);
  d.Get("occlusion_tolerance", &o->detail.occlusion_tolerance);
  d.Get("smoothness", &o->detail.smoothness);
  d.Get("prior_weight", &o->detail.prior_weight);
  d.Get("max_offset", &o->detail.max_offset);
  d.Get("bias_bins", &o->detail.bias_bins);
  d.Get("bias_per_segment", &o->detail.bias_per_segment);
  std::string why;
  if (!o->IsValid(&why)) throw Error(c.Path("") + " " + why);
}

PipelineOptions LoadPipelineOptions(const Config& config) {
  config.CheckKeys({"input", "preprocess", "fitting", "texture", "pipeline", "stream", "shape"});
  PipelineOptions o;
  BindInput(config.Section("input"), &o.input);
  BindPreprocess(config.Section("preprocess"), &o.preprocess);
  BindFitting(config.Section("fitting"), &o.fitting);
  BindInitializer(config.Section("fitting").Section("init"), &o.initializer);
  BindQuality(config.Section("fitting").Section("quality"), &o.quality);
  o.initializer.quality = o.quality;  // the initialiser ranks and labels with the same options
  o.gap_refit.coarse_iterations = o.initializer.coarse_iterations;  // and the gap refit too
  o.gap_refit.quality = o.quality;
  BindTexture(config.Section("texture"), &o.texturing);
  BindPipeline(config.Section("pipeline"), &o);
  BindStream(config.Section("stream"), &o.stream);
  BindShape(config.Section("shape"), &o.shape);
  // The silhouette term needs the preprocessing's free-space maps; build them unless told not
  // to. (The shape's scan mask builds its own on the frames it keeps: TrackStage::FeedShape.)
  if (o.fitting.silhouette.weight > 0.0 &&
      !config.Section("preprocess").Section("silhouette").Has("enabled")) {
    o.preprocess.silhouette.enabled = true;
  }
  BindJointLimits(config.Section("shape").Section("joint_limits"), &o.shape_joint_limits);
  o.shape.estep = o.fitting.estep;  // the tracker's correspondence weights
  std::string why;
  if (!o.IsValid(&why)) throw Error(config.Path("") + " " + why);
  return o;
}

}  // namespace artex
