#include "solvers/em_fitter.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include "energies/pose_smoothness_term.h"
#include "models/error.h"
#include "models/normals.h"
#include "models/numeric.h"
#include "solvers/fit_vertex_subset.h"

namespace artex {

namespace {

using Clock = std::chrono::steady_clock;
// sqrt(w) (s - s_ref): holds the global scale near its estimate (ScaleMode::kEstimateThenPrior).
class ScalePriorTerm : public FittingTerm {
 public:
  ScalePriorTerm(double weight, double reference)
      : sqrt_weight_(std::sqrt(weight)), reference_(reference) {}
  std::string name() const override { return "scale_prior"; }
  int num_residuals() const override { return 1; }
  bool Evaluate(const FitEvaluation& eval, double* residuals, double* jacobian) const override {
    residuals[0] = sqrt_weight_ * (eval.pose.scale - reference_);
    if (jacobian != nullptr) {
      Eigen::Map<Eigen::VectorXd>(jacobian, eval.delta.size()).setZero();
      jacobian[kScaleIndex] = sqrt_weight_;
    }
    return std::isfinite(residuals[0]);
  }

 private:
  double sqrt_weight_;
  double reference_;
};

}  // namespace

struct EMFitter::FrameState {
  Clock::time_point start;
  std::unique_ptr<EStep> estep;
  Pose initial_guess;
  Eigen::MatrixX3d initial_posed;
  std::vector<double> radii;  // empty: a single stage without radius
  int iterations_per_stage = 1;
  int max_iterations = 1;
  bool first_frame = false;
  bool scale_free = true;
  int stage = 0;
  int stage_iteration = 0;
  int normals_pose_stage = -1;  // stage of the last normal refresh (-1: none yet)
  int normals_age = 0;          // EM iterations since that refresh
  double stage_last_cost = std::numeric_limits<double>::quiet_NaN();
  bool done = false;
  bool converged = false;
  FitSummary summary;
  // Buffers reused across iterations.
  Eigen::MatrixX3d full_posed, full_normals;  // whole template
  Eigen::MatrixX3d posed, normals, colors;    // fitted vertices
  CorrespondenceTargets targets;
  NearestTargets nearest;
  Pose previous;  // temporal prior reference (valid when has_previous)
  bool has_previous = false;
  std::unique_ptr<PoseSmoothnessTerm> smoothness;
  Eigen::MatrixXd information;  // data-term J^T J of the last M-step
  std::shared_ptr<const SilhouetteMap> silhouette;  // the frame's free space (may be null)
  SilhouetteTargets silhouette_targets;
  std::vector<int> held_parameters;  // tangent indices of the out-of-view joints
};

EMFitter::EMFitter(const Template& tmpl, const EMFitterOptions& options) : options_(options) {
  std::string error;
  if (!options.IsValid(&error)) throw Error("fitting options: " + error);
  options_.joint_limits = ResolveJointLimits(options.joint_limits, tmpl.JointNames());
  if (!options_.joint_limits.IsValid(tmpl.num_joints(), &error)) {
    throw Error("fitting options: joint_limits." + error);
  }
  // The pose priors that need no skinning, in the M-step's order: joint limits, coupled joints
  // (a coupling with no pair on this template is left out).
  if (options_.joint_limits.weight > 0.0) {
    pose_priors_.push_back(
        std::make_shared<JointLimitTerm>(options_.joint_limits, tmpl.num_joints()));
  }
  if (options_.joint_coupling.weight > 0.0) {
    auto coupling = std::make_shared<JointCouplingTerm>(options_.joint_coupling, tmpl.JointNames());
    if (coupling->num_residuals() > 0) pose_priors_.push_back(std::move(coupling));
  }
  skinning_ = std::make_unique<Skinning>(tmpl);
  subsets_[0] = MakeFitSubset(tmpl, options.max_fit_vertices);
  int tracking = options.tracking_max_fit_vertices;
  if (options.max_fit_vertices > 0 && (tracking == 0 || tracking > options.max_fit_vertices)) {
    tracking = options.max_fit_vertices;
  }
  if (tracking != options.max_fit_vertices && tracking < tmpl.num_vertices()) {
    subsets_[1] = MakeFitSubset(tmpl, tracking);
  }
  fit_skinning_ = subsets_[0].skinning ? subsets_[0].skinning.get() : skinning_.get();
  fit_subset_ = &subsets_[0];
  solver_ = FitSolver::Create(options.solver);
  predictor_ = PosePredictor::Create(options.prediction);
  initial_pose_ = Pose::Identity(tmpl.num_joints());
  pose_ = initial_pose_;
}

EMFitter::~EMFitter() = default;

EMFitter::EMFitter(const EMFitter& other)
    : options_(other.options_),
      skinning_(std::make_unique<Skinning>(*other.skinning_)),
      pose_priors_(other.pose_priors_),  // immutable terms, shared
      solver_(FitSolver::Create(other.options_.solver)),
      template_colors_(other.template_colors_),
      initial_pose_(other.initial_pose_),
      next_radii_(other.next_radii_),
      next_iterations_per_stage_(other.next_iterations_per_stage_),
      pose_(other.pose_),
      camera_(other.camera_),
      has_camera_(other.has_camera_),
      history_(other.history_),
      frame_(other.frame_),
      accepted_frames_(other.accepted_frames_),
      scale_estimate_(other.scale_estimate_),
      scale_samples_(other.scale_samples_),
      predictor_(other.predictor_->Clone()),
      frame_information_(other.frame_information_) {
  for (int i = 0; i < 2; ++i) {
    subsets_[i].vertices = other.subsets_[i].vertices;
    subsets_[i].incident = other.subsets_[i].incident;
    if (other.subsets_[i].skinning) {
      subsets_[i].skinning = std::make_unique<Skinning>(*other.subsets_[i].skinning);
    }
  }
  fit_skinning_ = subsets_[0].skinning ? subsets_[0].skinning.get() : skinning_.get();
  fit_subset_ = &subsets_[0];
}

std::unique_ptr<EMFitter> EMFitter::Clone() const {
  if (state_) throw Error("EMFitter::Clone: a frame is in progress (BeginFrame without EndFrame)");
  return std::unique_ptr<EMFitter>(new EMFitter(*this));
}

EMFitter::FitSubset EMFitter::MakeFitSubset(const Template& tmpl, int max_vertices) const {
  FitSubset result;
  const int v = tmpl.num_vertices();
  if (max_vertices <= 0 || v <= max_vertices) {
    for (int i = 0; i < v; ++i) result.vertices.push_back(i);
    return result;
  }
  if (options_.fit_vertex_selection == FitVertexSelection::kStride) {
    const int stride = (v + max_vertices - 1) / max_vertices;
    for (int i = 0; i < v; i += stride) result.vertices.push_back(i);
  } else {
    result.vertices = VoxelVertexSubset(tmpl.vertices, max_vertices);
  }
  Template subset;
  const int n = static_cast<int>(result.vertices.size());
  subset.vertices.resize(n, 3);
  subset.vertex_joint.resize(n);
  subset.lbs_weight.resize(n);
  subset.slerp_tau.resize(n);
  for (int i = 0; i < n; ++i) {
    const int t = result.vertices[i];
    subset.vertices.row(i) = tmpl.vertices.row(t);
    subset.vertex_joint[i] = tmpl.vertex_joint[t];
    subset.lbs_weight[i] = tmpl.lbs_weight[t];
    subset.slerp_tau[i] = tmpl.slerp_tau[t];
  }
  subset.triangles.resize(1, 3);
  subset.triangles << 0, std::min(1, n - 1), std::min(2, n - 1);  // unused placeholder
  subset.joints = tmpl.joints;
  result.skinning = std::make_unique<Skinning>(subset);
  result.incident = FindIncidentTriangles(tmpl.triangles, result.vertices, v);
  return result;
}

void EMFitter::SetInitialPose(const Pose& pose) {
  if (pose.num_joints() != skinning_->model().num_joints() || !pose.AllFinite()) {
    std::ostringstream msg;
    msg << "initial pose: expected a finite pose with " << skinning_->model().num_joints()
        << " joints, found " << pose.num_joints() << " joints";
    throw Error(msg.str());
  }
  initial_pose_ = pose;
}

void EMFitter::SetDepthCamera(const PinholeCamera& camera) {
  camera_ = camera;
  has_camera_ = true;
}

void EMFitter::SetTemplateColors(const Eigen::MatrixX3d& colors) {
  if (colors.rows() != 0 && colors.rows() != skinning_->model().num_vertices()) {
    std::ostringstream msg;
    msg << "template colours: expected 0 or " << skinning_->model().num_vertices()
        << " rows, found " << colors.rows();
    throw Error(msg.str());
  }
  template_colors_ = colors;
}

void EMFitter::SetRestShape(const Template& shaped) {
  Eigen::MatrixX3d centers(shaped.num_joints(), 3);
  for (int j = 0; j < shaped.num_joints(); ++j) centers.row(j) = shaped.joints[j].center.transpose();
  skinning_->SetRestGeometry(shaped.vertices, centers);
  for (FitSubset& fit : subsets_) {
    if (!fit.skinning) continue;
    Eigen::MatrixX3d subset(static_cast<int>(fit.vertices.size()), 3);
    for (size_t i = 0; i < fit.vertices.size(); ++i) {
      subset.row(static_cast<int>(i)) = shaped.vertices.row(fit.vertices[i]);
    }
    fit.skinning->SetRestGeometry(subset, centers);
  }
}

void EMFitter::Reset(bool keep_scale) {
  history_.clear();
  frame_ = 0;
  accepted_frames_ = 0;
  if (!keep_scale) {
    scale_estimate_ = 1.0;
    scale_samples_.clear();
  }
  state_.reset();
  predictor_->Reset();
  pose_ = initial_pose_;
}

bool EMFitter::ScaleIsFree() const {
  switch (options_.scale_mode) {
    case ScaleMode::kFree:
      return true;
    case ScaleMode::kFixed:
      return false;
    case ScaleMode::kEstimateThenFix:
      return scale_samples() < options_.scale_estimation_frames;
    case ScaleMode::kEstimateThenPrior:
      return true;
  }
  return true;
}

Pose EMFitter::PredictNextPose() const {
  const bool estimated = scale_samples() >= options_.scale_estimation_frames;
  if (history_.empty()) {
    // A first frame (again): after Reset(true) it starts at the kept estimate.
    Pose guess = initial_pose_;
    if (estimated && options_.scale_mode != ScaleMode::kFree &&
        options_.scale_mode != ScaleMode::kFixed) {
      guess.scale = scale_estimate_;
    }
    return guess;
  }
  Pose guess = predictor_->Predict();
  if (options_.scale_mode == ScaleMode::kFixed ||
      (estimated && options_.scale_mode != ScaleMode::kFree)) {
    const double scale =
        options_.scale_mode == ScaleMode::kFixed ? history_.back().scale : scale_estimate_;
    // Rescale about the template's centroid (not the template origin at the feet), so the
    // switch to the estimate does not shift the body.
    const Eigen::Vector3d centroid = skinning_->model().vertices.colwise().mean().transpose();
    guess.translation += (guess.scale - scale) * (guess.rotation * centroid);
    guess.scale = scale;
  }
  return guess;
}

void EMFitter::BeginFrame(const Scan& scan, const Pose& initial_guess) {
  if (initial_guess.num_joints() != skinning_->model().num_joints()) {
    std::ostringstream msg;
    msg << "initial guess: expected " << skinning_->model().num_joints() << " joints, found "
        << initial_guess.num_joints();
    throw Error(msg.str());
  }
  state_ = std::make_unique<FrameState>();
  FrameState& st = *state_;
  st.start = Clock::now();
  st.first_frame = history_.empty();
  st.scale_free = ScaleIsFree();
  st.initial_guess = initial_guess;
  st.summary.frame = frame_;
  st.summary.num_scan_points = scan.size();
  st.silhouette = scan.silhouette;
  pose_ = initial_guess;
  if (!initial_guess.AllFinite()) {
    st.summary.non_finite = true;
    st.done = true;
    return;
  }
  const bool finite = scan.points.allFinite() && scan.normals.allFinite() &&
                      (scan.colors.rows() == 0 || scan.colors.allFinite());
  if (!finite) {
    st.summary.non_finite = true;
    st.done = true;
    return;
  }
  if (scan.size() < std::max(options_.min_scan_points, 1)) {
    st.summary.too_few_points = true;
    st.done = true;
    return;
  }
  const auto skin_start = Clock::now();
  skinning_->Apply(initial_guess, &st.initial_posed);
  st.summary.skinning_seconds += SecondsSince(skin_start);
  if (has_camera_ && options_.out_of_view.enabled()) {
    const Template& model = skinning_->model();
    Eigen::MatrixX3d centers;
    skinning_->PosedJointCenters(initial_guess, &centers);
    std::vector<int> parents(model.num_joints());
    for (int j = 0; j < model.num_joints(); ++j) parents[j] = model.joints[j].parent;
    const std::vector<int> held = OutOfViewJoints(st.initial_posed, model.vertex_joint, centers,
                                                  parents, camera_, options_.out_of_view);
    st.summary.out_of_view_joints = static_cast<int>(held.size());
    for (int j : held) {
      for (int k = 0; k < 3; ++k) st.held_parameters.push_back(JointParameterIndex(j) + k);
    }
  }

  const bool radius_mode = options_.correspondence == CorrespondenceModel::kOneToMany &&
                           options_.estep.mode == EStepMode::kRadius;
  if (radius_mode) st.radii = st.first_frame ? options_.first_frame_radii : options_.tracking_radii;
  st.iterations_per_stage = st.first_frame ? options_.first_frame_iterations_per_stage
                                           : options_.tracking_iterations_per_stage;
  const bool scheduled = radius_mode && !next_radii_.empty();
  if (scheduled) {
    st.radii = next_radii_;
    st.iterations_per_stage = next_iterations_per_stage_;
  }
  const bool tracking = !st.first_frame && !scheduled;
  const FitSubset& fit = subsets_[tracking && subsets_[1].skinning ? 1 : 0];
  // Tracking frames: one cloud and one gather for every tracking radius.
  EStepOptions estep_options = options_.estep;
  if (tracking && radius_mode && options_.tracking_shared_cloud && !st.radii.empty()) {
    const double widest = *std::max_element(st.radii.begin(), st.radii.end());
    estep_options.voxel_cell = widest * estep_options.voxel_fraction;
    estep_options.list_radius = widest;
  }
  const auto estep_start = Clock::now();
  st.estep = std::make_unique<EStep>(scan, estep_options);
  st.summary.estep_seconds += SecondsSince(estep_start);
  fit_skinning_ = fit.skinning ? fit.skinning.get() : skinning_.get();
  fit_subset_ = &fit;
  next_radii_.clear();
  st.max_iterations = st.first_frame ? 2 * options_.max_iterations : options_.max_iterations;
  if (!radius_mode) st.iterations_per_stage = st.max_iterations;
  if (!history_.empty()) {
    st.previous =
        options_.prediction.temporal_prior_on_prediction ? PredictNextPose() : history_.back();
    st.has_previous = true;
    if (history_.size() >= 2 && !options_.smoothness.AllZero()) {
      st.smoothness = std::make_unique<PoseSmoothnessTerm>(
          options_.smoothness, history_[history_.size() - 2], history_.back());
    }
  }
}

EMIterationInfo EMFitter::Iterate() {
  if (!state_) throw Error("EM fitter: Iterate() called before BeginFrame()");
  FrameState& st = *state_;
  EMIterationInfo info;
  info.frame = frame_;
  info.iteration = st.summary.iterations;
  info.stage = st.stage;
  if (st.done) {
    info.converged = st.converged;
    return info;
  }
  const Template& model = skinning_->model();

  // Pose the template and its normals (normals need the whole mesh; between refreshes only the
  // fitted vertices are posed and the normals of the last refresh are kept).
  auto start = Clock::now();
  const bool subset = fit_skinning_ != skinning_.get();
  const bool colored = !st.first_frame && template_colors_.rows() == model.num_vertices();
  const bool refresh_normals = st.normals_pose_stage != st.stage ||
                               (options_.normal_refresh_iterations > 0 &&
                                st.normals_age + 1 >= options_.normal_refresh_iterations);
  const std::vector<int>& fit_vertices = fit_subset_->vertices;
  const int n_fit = static_cast<int>(fit_vertices.size());
  if (refresh_normals) {
    if (st.summary.iterations == 0 && st.initial_posed.rows() == model.num_vertices()) {
      st.full_posed = st.initial_posed;  // BeginFrame posed the initial guess, pose_ still is it
    } else {
      skinning_->Apply(pose_, &st.full_posed);
    }
    if (subset) {
      // The fitted vertices' normals from their incident triangles: the whole template's
      // normals at those vertices, bit for bit, for about half the triangles.
      ComputeVertexNormalsOf(st.full_posed, model.triangles, fit_subset_->incident, &st.normals);
      st.posed.resize(n_fit, 3);
      for (int i = 0; i < n_fit; ++i) st.posed.row(i) = st.full_posed.row(fit_vertices[i]);
    } else {
      ComputeVertexNormals(st.full_posed, model.triangles, &st.full_normals);
    }
    st.normals_pose_stage = st.stage;
    st.normals_age = 0;
  } else {
    fit_skinning_->Apply(pose_, subset ? &st.posed : &st.full_posed);
    ++st.normals_age;
  }
  if (subset && colored) {
    st.colors.resize(n_fit, 3);
    for (int i = 0; i < n_fit; ++i) st.colors.row(i) = template_colors_.row(fit_vertices[i]);
  }
  st.summary.skinning_seconds += SecondsSince(start);

  // E-step (colour only once a texture exists and never on the first frame).
  start = Clock::now();
  PosedTemplateView view;
  view.vertices = subset ? &st.posed : &st.full_posed;
  view.normals = subset ? &st.normals : &st.full_normals;
  if (colored) view.colors = subset ? &st.colors : &template_colors_;
  const double radius = st.radii.empty() ? 0.0 : st.radii[st.stage];
  info.radius = radius;
  double total_weight = 0.0, constant = 0.0;
  std::unique_ptr<FittingTerm> data_term;
  if (options_.correspondence == CorrespondenceModel::kOneToMany) {
    st.estep->Compute(view, radius, &st.targets);
    total_weight = st.targets.total_weight();
    info.num_pairs = st.targets.num_pairs;
  } else {
    st.estep->FindNearest(view, options_.one_to_one, &st.nearest);
    total_weight = st.nearest.num_matched;
    info.num_pairs = st.nearest.num_matched;
  }
  st.summary.estep_seconds += SecondsSince(start);
  info.total_weight = total_weight;
  if (!(total_weight > 0.0) || !std::isfinite(total_weight)) {
    // No correspondences at all: nothing to fit.
    if (std::isfinite(total_weight)) {
      st.summary.too_few_points = true;
    } else {
      st.summary.non_finite = true;
    }
    st.done = true;
    return info;
  }
  const double data_weight = options_.normalize_data_term ? 1.0 / total_weight : 1.0;
  if (options_.correspondence == CorrespondenceModel::kOneToMany) {
    data_term = std::make_unique<OneToManyCorrespondenceTerm>(&st.targets, data_weight);
    constant = data_weight * st.targets.constant;
  } else {
    data_term = std::make_unique<OneToOneCorrespondenceTerm>(
        &st.nearest, options_.one_to_one.metric, data_weight);
  }

  std::unique_ptr<SilhouetteTerm> silhouette_term;
  st.silhouette_targets.violations = 0;
  if (st.silhouette && options_.silhouette.weight > 0.0 && view.vertices->rows() > 0 &&
      (st.radii.empty() || radius <= options_.silhouette.max_radius)) {
    FindSilhouetteViolations(*st.silhouette, *view.vertices, options_.silhouette,
                             &st.silhouette_targets);
    if (st.silhouette_targets.violations > 0) {
      silhouette_term = std::make_unique<SilhouetteTerm>(
          &st.silhouette_targets,
          options_.silhouette.weight / static_cast<double>(view.vertices->rows()));
    }
  }
  info.silhouette_violations = st.silhouette_targets.violations;
  // Joints without data hold the frame's initial guess (first frame) or the previous pose.
  std::unique_ptr<UnobservedJointTerm> unobserved_term;
  if (options_.unobserved_joints.weight > 0.0 &&
      options_.correspondence == CorrespondenceModel::kOneToMany) {
    const std::vector<int> joints = UnobservedJoints(
        fit_skinning_->model().vertex_joint, st.targets.weight, model.num_joints(),
        options_.unobserved_joints.min_observed_fraction);
    info.unobserved_joints = static_cast<int>(joints.size());
    if (!joints.empty()) {
      unobserved_term = std::make_unique<UnobservedJointTerm>(
          st.has_previous ? &st.previous : &st.initial_guess, joints,
          options_.unobserved_joints.weight);
    }
  }

  // M-step problem.
  TikhonovOptions tikhonov_options = options_.tikhonov;
  if (!st.first_frame) {
    tikhonov_options.update.scale += options_.tracking_update.scale;
    tikhonov_options.update.translation += options_.tracking_update.translation;
    tikhonov_options.update.rotation += options_.tracking_update.rotation;
    tikhonov_options.update.joints += options_.tracking_update.joints;
  }
  TikhonovTerm tikhonov(tikhonov_options, model.num_joints(),
                        st.has_previous ? &st.previous : nullptr);
  UprightTerm upright(options_.upright, 0);  // joint 0: the root joint (the pelvis)
  const bool prior_scale = options_.scale_mode == ScaleMode::kEstimateThenPrior &&
                           scale_samples() >= options_.scale_estimation_frames;
  ScalePriorTerm scale_prior(options_.scale_prior_weight, scale_estimate_);
  FitProblem problem;
  problem.skinning = fit_skinning_;
  problem.anchor = pose_;
  problem.information_terms = 1;  // the data term's J^T J: the frame's information
  problem.terms.push_back(data_term.get());
  problem.terms.push_back(&tikhonov);
  if (silhouette_term) problem.terms.push_back(silhouette_term.get());
  if (unobserved_term) problem.terms.push_back(unobserved_term.get());
  for (const auto& prior : pose_priors_) problem.terms.push_back(prior.get());
  if (options_.upright.weight > 0.0 &&
      (!options_.upright.only_out_of_view || !st.held_parameters.empty())) {
    problem.terms.push_back(&upright);
  }
  if (st.smoothness) problem.terms.push_back(st.smoothness.get());
  if (prior_scale) problem.terms.push_back(&scale_prior);
  const bool em_scale = options_.scale_mode == ScaleMode::kFree ||
                        options_.scale_estimator == ScaleEstimator::kEm || prior_scale;
  const bool scale_free = st.scale_free && em_scale &&
                          (st.radii.empty() || radius <= options_.scale_max_radius);
  if (!scale_free) problem.constant_parameters.push_back(kScaleIndex);
  problem.constant_parameters.insert(problem.constant_parameters.end(),
                                     st.held_parameters.begin(), st.held_parameters.end());

  const FitSolverSummary m = solver_->Solve(problem, &pose_);
  if (options_.over_relaxation != 1.0 && m.termination != FitTermination::kFailure) {
    pose_ = problem.anchor.Retracted(options_.over_relaxation * m.delta);
  }
  st.summary.mstep_seconds += m.seconds;
  st.information = m.information;
  st.summary.skinning_seconds += m.skinning_seconds;

  info.cost = m.final_cost + constant;
  info.max_update = m.delta.size() > 0 ? m.delta.cwiseAbs().maxCoeff() : 0.0;
  info.scale = pose_.scale;
  if (st.summary.iterations == 0) st.summary.initial_cost = m.initial_cost + constant;
  ++st.summary.iterations;
  st.summary.final_cost = info.cost;
  if (m.termination == FitTermination::kFailure || !pose_.AllFinite() ||
      !std::isfinite(info.cost)) {
    st.summary.non_finite = true;
    st.done = true;
    st.summary.trace.push_back(info);
    if (callback_) callback_(info);
    return info;
  }

  // Convergence of the stage and of the frame.
  ++st.stage_iteration;
  const double relative_change =
      std::isnan(st.stage_last_cost)
          ? std::numeric_limits<double>::infinity()
          : std::abs(info.cost - st.stage_last_cost) / std::max(std::abs(info.cost), 1e-300);
  st.stage_last_cost = info.cost;
  info.stage_converged = info.max_update < options_.parameter_tolerance ||
                         relative_change < options_.relative_cost_tolerance;
  const int num_stages = std::max<int>(1, static_cast<int>(st.radii.size()));
  const bool last_stage = st.stage + 1 >= num_stages;
  if (info.stage_converged || st.stage_iteration >= st.iterations_per_stage) {
    if (last_stage) {
      st.done = true;
      st.converged = info.stage_converged;
      info.converged = info.stage_converged;
    } else {
      ++st.stage;
      st.stage_iteration = 0;
      st.stage_last_cost = std::numeric_limits<double>::quiet_NaN();
    }
  }
  if (st.summary.iterations >= st.max_iterations) st.done = true;
  st.summary.trace.push_back(info);
  if (callback_) callback_(info);
  return info;
}

bool EMFitter::frame_done() const { return !state_ || state_->done; }

FitSummary EMFitter::FinishFrame(bool* ok_out) {
  if (!state_) throw Error("EM fitter: EndFrame()/DiscardFrame() called before BeginFrame()");
  FrameState& st = *state_;
  FitSummary summary = std::move(st.summary);
  summary.scale = pose_.scale;
  if (st.estep) {
    summary.neighbor_queries = st.estep->neighbor_queries();
    summary.candidates_visited = st.estep->candidates_visited();
  }
  bool ok = !summary.too_few_points && !summary.non_finite;
  if (ok && st.initial_posed.rows() > 0) {
    // Over the fitted vertices: only they are posed (the fit's subset, evenly spread over the
    // surface; the whole template without one).
    Eigen::MatrixX3d posed;
    const auto start = Clock::now();
    fit_skinning_->Apply(pose_, &posed);
    summary.skinning_seconds += SecondsSince(start);
    const bool subset = fit_skinning_ != skinning_.get();  // row i is fit_subset_->vertices[i]
    double sum = 0.0;
    for (int i = 0; i < static_cast<int>(posed.rows()); ++i) {
      sum += (posed.row(i) - st.initial_posed.row(subset ? fit_subset_->vertices[i] : i)).norm();
    }
    summary.mean_motion = sum / std::max<Eigen::Index>(posed.rows(), 1);
    const double scale_change = std::abs(pose_.scale / st.initial_guess.scale - 1.0);
    if (!std::isfinite(summary.mean_motion) || summary.mean_motion > options_.max_mean_motion ||
        !(scale_change <= options_.max_scale_change)) {
      summary.diverged = true;
      ok = false;
    }
  }
  summary.termination = !ok           ? FrameTermination::kFailed
                        : st.converged ? FrameTermination::kConverged
                                       : FrameTermination::kMaxIterations;
  summary.total_seconds = SecondsSince(st.start) + summary.icp_seconds;
  frame_information_ = ok ? st.information : Eigen::MatrixXd();
  *ok_out = ok;
  return summary;
}

void EMFitter::Commit(const Scan& scan, const Pose& pose, bool scale_was_free,
                      const Eigen::MatrixXd& information) {
  pose_ = pose;
  if (scale_was_free && options_.scale_mode != ScaleMode::kFree &&
      scale_samples() < options_.scale_estimation_frames) {
    bool sample = true;
    if (options_.scale_estimator == ScaleEstimator::kIcp) {
      sample = false;
      if (scan.size() >= std::max(options_.min_scan_points, 3)) {
        IcpInitOptions icp = options_.icp;
        icp.coarse_alignment = false;
        icp.estimate_scale = true;
        icp.max_distance = options_.scale_sample_max_distance;
        if (options_.scale_sample_max_scan_points > 0) {
          icp.max_scan_points = options_.scale_sample_max_scan_points;
        }
        if (options_.scale_sample_tolerance > 0.0) icp.tolerance = options_.scale_sample_tolerance;
        if (options_.scale_sample_grid_cell > 0.0) icp.grid_cell = options_.scale_sample_grid_cell;
        const IcpInitResult aligned = AlignByIcp(*skinning_, pose, scan, icp);
        sample = aligned.pose.AllFinite() &&
                 aligned.num_pairs >= std::min(options_.min_scan_points, aligned.num_samples) &&
                 aligned.num_pairs >=
                     options_.scale_sample_min_pair_fraction * aligned.num_samples;
        if (sample) pose_ = aligned.pose;
      }
    }
    // Median of the estimation frames' scales.
    if (sample) scale_samples_.push_back(pose_.scale);
    std::vector<double> sorted = scale_samples_;
    std::sort(sorted.begin(), sorted.end());
    const size_t n = sorted.size();
    if (n > 0) {
      scale_estimate_ = n % 2 == 1 ? sorted[n / 2] : 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]);
    }
  }
  history_.push_back(pose_);
  predictor_->Observe(pose_, information);
  ++accepted_frames_;
  if (history_.size() > 2) history_.erase(history_.begin(), history_.end() - 2);
  ++frame_;
}

FitSummary EMFitter::EndFrame() {
  bool ok = false;
  FitSummary summary = FinishFrame(&ok);
  const bool scale_free = state_->scale_free;
  const Pose initial_guess = std::move(state_->initial_guess);
  if (ok) {
    Commit(state_->estep->scan(), pose_, scale_free, frame_information_);
    state_.reset();
    summary.scale = pose_.scale;
    return summary;
  }
  state_.reset();
  // Keep the previous pose (zero velocity for the next prediction).
  if (!history_.empty()) {
    pose_ = history_.back();
    history_.push_back(pose_);
    predictor_->ObserveMissing(pose_);
  } else {
    pose_ = initial_guess;
  }
  summary.scale = pose_.scale;
  if (history_.size() > 2) history_.erase(history_.begin(), history_.end() - 2);
  ++frame_;
  return summary;
}

FitSummary EMFitter::DiscardFrame(Pose* result) {
  bool ok = false;
  FitSummary summary = FinishFrame(&ok);
  if (result != nullptr) *result = pose_;
  state_.reset();
  pose_ = history_.empty() ? initial_pose_ : history_.back();
  return summary;
}

void EMFitter::AcceptPose(const Scan& scan, const Pose& pose, const Eigen::MatrixXd& information) {
  if (pose.num_joints() != skinning_->model().num_joints() || !pose.AllFinite()) {
    std::ostringstream msg;
    msg << "accepted pose: expected a finite pose with " << skinning_->model().num_joints()
        << " joints, found " << pose.num_joints() << " joints";
    throw Error(msg.str());
  }
  state_.reset();
  Commit(scan, pose, ScaleIsFree(), information);
}

void EMFitter::SetNextFrameSchedule(const std::vector<double>& radii, int iterations_per_stage) {
  const bool radii_ok = !radii.empty() && std::all_of(radii.begin(), radii.end(), [](double r) {
    return std::isfinite(r) && r > 0.0;
  });
  if (!radii_ok || iterations_per_stage < 1) {
    throw Error("EMFitter::SetNextFrameSchedule: expected finite radii > 0 (m) and >= 1 "
                "iterations per stage, found " + std::to_string(radii.size()) +
                " radii and " + std::to_string(iterations_per_stage) + " iterations");
  }
  next_radii_ = radii;
  next_iterations_per_stage_ = iterations_per_stage;
}

FitSummary EMFitter::FitFrame(const Scan& scan) {
  Pose guess = PredictNextPose();
  double icp_seconds = 0.0;
  if (history_.empty() && options_.icp_first_frame &&
      scan.size() >= std::max(options_.min_scan_points, 3)) {
    const auto start = Clock::now();
    guess = AlignByIcp(*skinning_, guess, scan, options_.icp).pose;
    icp_seconds = SecondsSince(start);
  }
  BeginFrame(scan, guess);
  while (!state_->done) Iterate();
  state_->summary.icp_seconds = icp_seconds;
  return EndFrame();
}

}  // namespace artex
