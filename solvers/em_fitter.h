// EM fitting of the template to one scan per frame (paper sec. 3, eq. 3-5; docs/design.md
// "Fitting energy"). Per EM iteration: pose the template (S(v; theta), normals), E-step
// (P_t, mu_t; solvers/estep.h) or nearest-neighbour pairs (ICP baseline), then an M-step
// (FitSolver: Gauss-Newton or Ceres LM) over the data term plus priors (Tikhonov update,
// temporal, joint limits, constant-velocity smoothness, scale prior).
// Radius E-steps follow a coarse-to-fine schedule of stages; the first frame uses its own
// (wider) schedule. The first frame starts from a predefined pose pre-aligned by similarity
// ICP (solvers/icp_init.h); later frames from the previous pose, optionally extrapolated at
// constant velocity. The global scale is estimated over the first frames (by default from
// similarity-ICP samples of the fitted template, median of 5 frames) and then fixed or held by
// a prior (the literal energy is degenerate with a free scale). Bad frames (too few points,
// non-finite values, divergence) are flagged and keep the previous pose. Several hypotheses of
// one frame can be fitted with BeginFrame/Iterate/DiscardFrame and the chosen one recorded by
// AcceptPose (solvers/initializer.h).
#pragma once

#include <Eigen/Core>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "energies/joint_coupling_term.h"
#include "energies/joint_limit_term.h"
#include "energies/upright_term.h"
#include "energies/one_to_many_correspondence.h"
#include "energies/one_to_one_correspondence.h"
#include "energies/silhouette_term.h"
#include "energies/unobserved_joint_term.h"
#include "energies/tikhonov_term.h"
#include "models/normals.h"
#include "models/pose.h"
#include "models/skinning.h"
#include "models/template.h"
#include "render/camera.h"
#include "sensors/scan.h"
#include "solvers/estep.h"
#include "solvers/fit_solver.h"
#include "solvers/icp_init.h"
#include "solvers/out_of_view.h"
#include "solvers/prediction.h"

namespace artex {

// kOneToMany: the paper's probabilistic correspondences; kOneToOne: articulated ICP baseline.
enum class CorrespondenceModel { kOneToMany, kOneToOne };
const std::map<std::string, CorrespondenceModel>& CorrespondenceModelNames();

// kFree: optimised on every frame (literal paper). kEstimateThenFix: free during the first
// `scale_estimation_frames` frames, then fixed. kEstimateThenPrior: afterwards held by a prior
// of weight scale_prior_weight towards the estimate. kFixed: never optimised (the initial or
// ICP value).
enum class ScaleMode { kFree, kEstimateThenFix, kEstimateThenPrior, kFixed };
const std::map<std::string, ScaleMode>& ScaleModeNames();

// How an estimation frame's scale sample is measured (ScaleMode kEstimateThen*):
// kIcp: the EM fit holds the scale (at the pre-alignment's or the previous frame's value);
// after the frame the fitted template is aligned to the scan by similarity ICP (pairs within
// scale_sample_max_distance, so only points the template explains) and its scale is the
// sample (the frame's accepted pose takes the ICP similarity). kEm: the EM's free scale (biased
// low by the radius E-step's chord means: -4 % on a full body, -11 % on an upper body on the
// virtual Kinect, drifting further while tracking).
enum class ScaleEstimator { kIcp, kEm };
const std::map<std::string, ScaleEstimator>& ScaleEstimatorNames();  // "icp", "em"

// Which template vertices the fit uses when max_fit_vertices subsamples the template:
// kStride: every n-th vertex index; kVoxel: one vertex per cell of a cubic grid over the rest
// pose (even over the surface, whatever the vertex order), cells in Z-curve order.
enum class FitVertexSelection { kStride, kVoxel };
const std::map<std::string, FitVertexSelection>& FitVertexSelectionNames();  // "stride", "voxel"

struct EMFitterOptions {
  CorrespondenceModel correspondence = CorrespondenceModel::kOneToMany;
  EStepOptions estep;          // one-to-many E-step (mode, weights, k, voxel subsampling)
  OneToOneOptions one_to_one;  // ICP baseline pairing
  FitSolverOptions solver;     // M-step backend

  // Radius schedule (m) of the kRadius E-step, one stage per entry, coarse to fine.
  std::vector<double> first_frame_radii = {0.15, 0.10, 0.05, 0.03};
  // Tracking frames start from the (predicted) previous pose, within a few cm of the truth at
  // 30 Hz: a short 4 cm stage then the fine one (a single 3 cm stage is cheaper still, but
  // ends in worse optima on thin limbs).
  std::vector<double> tracking_radii = {0.04, 0.03};
  int first_frame_iterations_per_stage = 10;  // max EM iterations per stage, first frame
  int tracking_iterations_per_stage = 4;      // max EM iterations per stage, later frames
  int max_iterations = 30;                    // per frame, over all stages (first frame: 2x)

  // Over-relaxed EM: the M-step update is scaled by this factor before it is applied
  // (1: plain EM; values in (1, 2) accelerate the slow linear convergence of EM).
  double over_relaxation = 1.5;

  // Convergence (per stage; the frame converges when its last stage does):
  double relative_cost_tolerance = 1e-3;  // |cost change| / cost between EM iterations
  double parameter_tolerance = 2e-4;      // max |M-step update| component (m, rad)

  // Data term weight 1 / sum_t P_t (cost = weighted mean squared distance, m^2) when true;
  // the literal unnormalised sum when false. Prior weights are relative to this choice.
  bool normalize_data_term = true;
  TikhonovOptions tikhonov;  // Gamma on the update, temporal prior to frame f-1
  // Added to tikhonov.update (Gamma) in tracking frames (the first frame has to move far from
  // the rest pose). A stronger joint weight damps the updates along the weakly observable
  // directions (twist about limb axes, small joints), which otherwise drift from iteration to
  // iteration and frame to frame since the cost barely changes along them.
  PoseGroupWeights tracking_update = {0.0, 0.0, 0.0, 3e-3};
  JointLimitOptions joint_limits;  // soft joint boxes (weight 0: off)
  // Pairs of joints held to turn alike (energies/joint_coupling_term.h): the neck and the head
  // by default. weight 0: off (the paper's energy).
  JointCouplingOptions joint_coupling;
  UprightOptions upright;          // the pelvis's tilt from world up (weight 0: off)
  // Free space (energies/silhouette_term.h): fitted vertices that project where the camera saw
  // something else behind them are pulled towards the subject's silhouette; used when the scan
  // carries a SilhouetteMap (preprocessing builds one unless preprocess.silhouette.enabled is
  // false). weight 0: off (the paper's energy).
  SilhouetteTermOptions silhouette;
  // Joints whose fitted vertices the E-step leaves unmatched are pulled towards the initial
  // guess (first frame) or the previous pose (energies/unobserved_joint_term.h). weight 0: off.
  UnobservedJointOptions unobserved_joints;
  // Joints out of the depth camera's view at a frame's initial guess hold their rotation in that
  // frame (solvers/out_of_view.h); needs SetDepthCamera (the pipeline and the initialiser set
  // it), without a camera every joint is fitted.
  OutOfViewOptions out_of_view;
  PoseGroupWeights smoothness;     // constant-velocity prior (all 0: off)

  ScaleMode scale_mode = ScaleMode::kEstimateThenFix;
  // The scale estimate is the median of the fitted scales of the first this many accepted
  // frames (the scale is free in them); one frame's scale depends on its view (a person cropped
  // by the image border, the arms against the body), the median over a few is steadier.
  int scale_estimation_frames = 5;
  ScaleEstimator scale_estimator = ScaleEstimator::kIcp;
  double scale_sample_max_distance = 0.05;  // kIcp: ICP pair rejection distance (m)
  // kIcp: a frame whose fitted template explains (pairs within scale_sample_max_distance) fewer
  // than this fraction of the scan is no scale sample (the scale stays being estimated).
  double scale_sample_min_pair_fraction = 0.7;
  // kIcp: the scale sample's ICP pairs a fixed-stride subsample of at most this many scan
  // points (0: icp.max_scan_points, the first frame's pre-alignment budget).
  int scale_sample_max_scan_points = 1500;
  // kIcp: the scale sample's ICP stops when the similarity changes less than this (relative;
  // 0: icp.tolerance, the first frame's pre-alignment tolerance). It starts from the fitted
  // pose, so its last iterations only refine the scale in the fourth digit.
  double scale_sample_tolerance = 0.0;
  // kIcp: > 0: the scale sample's ICP finds the nearest template vertex on a uniform grid of
  // cubic cells of this side (m; NearestGrid) instead of a kd-tree built anew for each
  // sample: the same vertex, so the same sample bit for bit, about 2.5 ms less of one core per
  // sample (docs/fitting-speed.md). 0: icp.grid_cell (the kd-tree by default).
  double scale_sample_grid_cell = 0.03;
  // Radius E-step: the scale is held during stages with a radius above this (m); at wide radii
  // mu_t lies inside curved surfaces (chord means), which biases a free scale downwards.
  double scale_max_radius = 0.05;
  double scale_prior_weight = 1.0;  // kEstimateThenPrior (cost units per unit^2)

  bool icp_first_frame = true;  // pre-align the first frame's pose by similarity ICP
  IcpInitOptions icp;
  // Initial guess of a tracking frame (solvers/prediction.h): previous pose, constant
  // velocity (the default), Kalman filter, or particle (multi-hypothesis, TrackFrame).
  PredictionOptions prediction;

  // Fit on a subset (fit_vertex_selection) of at most this many template vertices (0: all).
  // E-step, Jacobians and normal equations scale with it; normals use the full mesh.
  int max_fit_vertices = 3000;
  // Tracking frames (the tracking schedule after an accepted pose) fit on a subset of at most
  // this many (and at most max_fit_vertices; 0: max_fit_vertices alone). First frames, the
  // initialiser's hypotheses and refits after a gap (SetNextFrameSchedule) keep
  // max_fit_vertices: on the real recordings the initialisation needs the denser subset, the
  // tracking does not (docs/fitting-speed.md, "Tracking frames on a smaller subset").
  int tracking_max_fit_vertices = 2000;
  // Radius E-step, tracking frames (as tracking_max_fit_vertices): one voxel cloud (cell
  // voxel_fraction x the widest tracking radius) and one candidate gather at that radius serve
  // every tracking radius (EStepOptions::voxel_cell, list_radius), instead of a cloud and a
  // gather per radius: a fifth less CPU per tracking frame at the same accuracy
  // (docs/fitting-speed.md, "One cloud per tracking frame"). false: per radius (before).
  bool tracking_shared_cloud = true;
  FitVertexSelection fit_vertex_selection = FitVertexSelection::kVoxel;
  // Template normals (for n_s . n'_t of eq. 4) are recomputed on the whole posed mesh at the
  // first EM iteration of every stage and, when > 0, every this many iterations (1: every
  // iteration; 0: once per stage); in between only the fitted vertices are posed. Within a
  // tracking frame the template turns by a few degrees, which changes the weights by well
  // under 1 %; long single-stage fits (dense, k-nearest, first frame) still need refreshes.
  int normal_refresh_iterations = 4;

  // Robustness.
  int min_scan_points = 100;      // fewer: frame flagged too_few_points, pose kept
                                  // (also when no correspondence is found)
                                  // non-finite scan values flag non_finite
  double max_mean_motion = 0.5;   // mean displacement (m) of the fitted vertices from the
                                  // frame's initial guess beyond which it is flagged diverged
  double max_scale_change = 0.5;  // relative scale change within a frame: diverged

  bool IsValid(std::string* error) const;
};

struct EMIterationInfo {
  int frame = 0;
  int iteration = 0;  // 0-based within the frame
  int stage = 0;
  double radius = 0.0;  // E-step radius of the stage (kRadius), else 0
  double cost = 0.0;    // after the M-step: data (incl. the E-step constant) + priors
  double max_update = 0.0;
  double total_weight = 0.0;  // sum_t P_t (or matched vertices, one-to-one)
  long long num_pairs = 0;
  int silhouette_violations = 0;  // fitted vertices outside the silhouette (before the M-step)
  int unobserved_joints = 0;      // joints held by the unobserved-joint prior
  double scale = 1.0;
  bool stage_converged = false;
  bool converged = false;  // last stage converged: the frame is done
};

enum class FrameTermination { kConverged, kMaxIterations, kFailed };
const char* FrameTerminationName(FrameTermination termination);

struct FitSummary {
  int frame = 0;
  int iterations = 0;
  double initial_cost = 0.0;  // of the first EM iteration (before its M-step)
  double final_cost = 0.0;
  FrameTermination termination = FrameTermination::kFailed;
  bool too_few_points = false;
  bool non_finite = false;
  bool diverged = false;
  int num_scan_points = 0;
  int out_of_view_joints = 0;  // joints held at the initial guess (solvers/out_of_view.h)
  double scale = 1.0;
  double mean_motion = 0.0;  // mean fitted-vertex displacement from the initial guess (m)
  // E-step work: neighbour queries and candidate scan points visited (solvers/estep.h).
  long long neighbor_queries = 0;
  long long candidates_visited = 0;
  // Timings (s).
  double icp_seconds = 0.0;
  double estep_seconds = 0.0;
  double mstep_seconds = 0.0;     // includes the skinning done inside the solver
  double skinning_seconds = 0.0;  // all posing (E-step posing + inside the M-step)
  double total_seconds = 0.0;
  std::vector<EMIterationInfo> trace;

  bool ok() const { return !too_few_points && !non_finite && !diverged; }
  std::string BriefReport() const;
};

class EMFitter {
 public:
  // Throws artex::Error on an invalid template or options.
  EMFitter(const Template& tmpl, const EMFitterOptions& options);
  ~EMFitter();

  const EMFitterOptions& options() const { return options_; }
  const Skinning& skinning() const { return *skinning_; }
  // The enabled pose priors that need no skinning (joint limits, coupled joints), built once:
  // every M-step adds them, and the shape estimator's joint solve applies them to its frames.
  const std::vector<std::shared_ptr<const FittingTerm>>& pose_priors() const {
    return pose_priors_;
  }
  // Template vertex indices the fit uses (all, or the max_fit_vertices subset); tracking: those
  // of tracking frames (the tracking_max_fit_vertices subset).
  const std::vector<int>& fit_vertices(bool tracking = false) const {
    return subsets_[tracking && subsets_[1].skinning ? 1 : 0].vertices;
  }

  // Fits the next frame and returns its summary; pose() is the result (the previous pose when
  // the frame failed). The first frame starts from initial_pose() (rest pose unless set),
  // pre-aligned by ICP when options.icp_first_frame.
  FitSummary FitFrame(const Scan& scan);

  // Lower level (GTSAM style): BeginFrame prepares the frame (kd-tree, initial guess, priors);
  // Iterate runs one EM iteration (E-step + M-step) and advances the radius schedule.
  void BeginFrame(const Scan& scan, const Pose& initial_guess);
  EMIterationInfo Iterate();
  // True once the frame begun by BeginFrame has converged, hit its limits or failed.
  bool frame_done() const;
  // Completes the frame begun by BeginFrame: robustness checks, history update.
  FitSummary EndFrame();

  const Pose& pose() const { return pose_; }
  int frames_fitted() const { return frame_; }
  void SetInitialPose(const Pose& pose);  // pose for the first frame (before ICP)
  // The depth camera of the scans (intrinsics, world_to_camera) for the out-of-view joints
  // (EMFitterOptions::out_of_view); without one every joint is fitted.
  void SetDepthCamera(const PinholeCamera& camera);
  const PinholeCamera* depth_camera() const { return has_camera_ ? &camera_ : nullptr; }
  const Pose& initial_pose() const { return initial_pose_; }
  // Per-vertex template colours (T x 3, [0,1]) for the colour term; empty disables it.
  void SetTemplateColors(const Eigen::MatrixX3d& colors);
  // Replaces the template's rest geometry (vertices, joint centres) by a subject shape's with
  // the same rig and vertex count (models/shape.h); history, scale estimate and the fitted
  // vertex subset are kept, skinning() stays the same object. Throws artex::Error on a
  // mismatched template (vertex or joint count).
  void SetRestShape(const Template& shaped);
  // The guess FitFrame would start the next frame from (options.prediction).
  Pose PredictNextPose() const;
  // True when the next frame is a tracking frame (an accepted or kept pose exists).
  bool tracking() const { return !history_.empty(); }
  // Information of the data term, J^T J (P x P, in the pose tangent at the fitted pose) of the
  // last M-step of the frame last finished by EndFrame/DiscardFrame; the Kalman measurement
  // (solvers/kalman_predictor.h). Empty when the frame failed or the M-step backend does not
  // build normal equations (Ceres).
  const Eigen::MatrixXd& frame_information() const { return frame_information_; }
  // Forgets the history: the next frame is a first frame again. keep_scale: the scale
  // estimate (and the frames counted towards it) survives, e.g. a re-initialisation after a
  // lost frame of the same person.
  void Reset(bool keep_scale = false);

  // Ends the frame begun by BeginFrame like EndFrame (robustness checks, summary) but records
  // nothing: history, frame counter and scale estimate are unchanged and pose() returns to the
  // last accepted pose (the initial pose before the first). *result (optional) receives the
  // fitted pose. Lets a caller fit several hypotheses of one frame (solvers/initializer.h).
  FitSummary DiscardFrame(Pose* result = nullptr);
  // Records `pose` as the accepted result of the next frame, as EndFrame does for a fitted
  // frame (history, frame counter, scale estimate when the scale is still being estimated);
  // pose() becomes it. Throws artex::Error for a wrong joint count or a non-finite pose.
  // With ScaleEstimator::kIcp the scale sample is measured on `scan` (the frame's).
  // information: the pose's data-term information for the predictor (empty: none).
  void AcceptPose(const Scan& scan, const Pose& pose,
                  const Eigen::MatrixXd& information = Eigen::MatrixXd());

  // True when the scale is optimised in the next frame (ScaleMode, frames estimated so far).
  bool ScaleIsFree() const;
  // Median of the accepted estimation frames' scales (1 before the first).
  double scale_estimate() const { return scale_estimate_; }
  // Frames counted towards the scale estimate (at most scale_estimation_frames).
  int scale_samples() const { return static_cast<int>(scale_samples_.size()); }

  // The E-step radius schedule of the next frame begun (BeginFrame, FitFrame) instead of the
  // first-frame or tracking one (EStepMode::kRadius only; one frame, e.g. RefitFromPose in
  // solvers/initializer.h). Throws artex::Error for an empty list, a radius <= 0 or
  // iterations_per_stage < 1.
  void SetNextFrameSchedule(const std::vector<double>& radii, int iterations_per_stage);

  // An independent copy of this fitter between frames: options, template and rest shape, fitted
  // vertex subsets, depth camera, template colours, history, scale estimate, predictor state and
  // a pending SetNextFrameSchedule. A frame begun on the copy fits exactly as on this fitter, so
  // several hypotheses of one frame can be fitted concurrently, one copy each
  // (solvers/initializer.h). The iteration callback is not copied. Thread-safe as long as this
  // fitter is not modified meanwhile. Throws artex::Error while a frame is in progress (after
  // BeginFrame, before EndFrame or DiscardFrame).
  std::unique_ptr<EMFitter> Clone() const;

  // Progress hook, called after every EM iteration (never prints).
  void SetIterationCallback(std::function<void(const EMIterationInfo&)> callback) {
    callback_ = std::move(callback);
  }

 private:
  struct FrameState;
  EMFitter(const EMFitter& other);  // Clone
  EMFitter& operator=(const EMFitter&) = delete;
  // Robustness checks and summary of the frame begun by BeginFrame; sets *ok.
  FitSummary FinishFrame(bool* ok);
  // History, scale estimate and frame counter for an accepted pose (scan: of its frame).
  void Commit(const Scan& scan, const Pose& pose, bool scale_was_free,
              const Eigen::MatrixXd& information);

  // The template vertices a frame fits: their indices and, when a proper subset, their own
  // skinning (skinning constants are per vertex, so the subset skins exactly like the template)
  // and incident triangles (their normals without the rest of the template's).
  struct FitSubset {
    std::vector<int> vertices;
    std::unique_ptr<Skinning> skinning;  // null: the whole template (skinning_)
    IncidentTriangles incident;          // of a proper subset
  };
  FitSubset MakeFitSubset(const Template& tmpl, int max_vertices) const;

  EMFitterOptions options_;
  std::unique_ptr<Skinning> skinning_;
  std::vector<std::shared_ptr<const FittingTerm>> pose_priors_;
  FitSubset subsets_[2];  // [0]: max_fit_vertices; [1]: tracking frames (null skinning: use [0])
  // The frame's subset (BeginFrame) and its skinning: skinning_ or the subset's.
  const Skinning* fit_skinning_ = nullptr;
  const FitSubset* fit_subset_ = nullptr;
  std::unique_ptr<FitSolver> solver_;
  Eigen::MatrixX3d template_colors_;
  Pose initial_pose_;
  std::vector<double> next_radii_;  // SetNextFrameSchedule (empty: none)
  int next_iterations_per_stage_ = 0;
  Pose pose_;
  PinholeCamera camera_;
  bool has_camera_ = false;
  std::vector<Pose> history_;  // accepted poses of previous frames (last two kept)
  int frame_ = 0;
  int accepted_frames_ = 0;  // frames that passed the robustness checks
  double scale_estimate_ = 1.0;
  std::vector<double> scale_samples_;  // scales of the estimation frames
  std::unique_ptr<FrameState> state_;
  std::unique_ptr<PosePredictor> predictor_;
  Eigen::MatrixXd frame_information_;
  std::function<void(const EMIterationInfo&)> callback_;
};

}  // namespace artex
