// Subject shape estimation while tracking (docs/shape.md): the template's
// shape parameters (models/shape.h) are estimated jointly with the poses of a calibration
// phase, the first `calibration_frames` accepted frames (every `calibration_stride`-th, for
// several poses), by Gauss-Newton over the same one-to-many correspondence energy the tracker
// minimises (solvers/estep.h E-steps, radius schedule, data term normalised per frame):
//   E(q, delta_1..N) = sum_f (1 / sum_t P_ft) sum_t P_ft |S(v_t; q, theta_f (+) delta_f) - mu_ft|^2
//                      + prior_weight |E (q - q_ref)|^2 + pose_damping sum_f |delta_f|^2
//                      (+ the scan-to-model, floor and prior terms of ShapeOptions),
// q clamped to the bounds after every step. The global scale s0 of each pose is held (it is the
// tracker's estimate; the shape is relative to it). Afterwards the shape is frozen, or refined
// every `refine_every` frames by the same solve on that one frame with a strong prior
// (refine_prior_weight) towards the current estimate.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "energies/fitting_term.h"
#include "models/pose.h"
#include "models/shape.h"
#include "models/template.h"
#include "render/camera.h"
#include "sensors/scan.h"
#include "solvers/estep.h"
#include "solvers/out_of_view.h"
#include "solvers/shape_detail.h"

namespace artex {

struct ShapeOptions {
  // fixed: the template as given (the paper; no estimation); scale: one uniform factor;
  // bones: per-bone lengths; bones_girth: per-bone lengths and per-segment girth.
  ShapeMode mode = ShapeMode::kFixed;
  // Offline recordings: after the run that calibrates the shape (fitting only, into
  // OUT/shape_pass/), track the whole sequence again with the subject's template (shape fixed).
  // The first frames, fitted before the calibration, then use the subject's shape too; costs a
  // second fitting pass. Not with pipeline.live.
  bool retrack = false;
  bool symmetric = true;       // l_/r_ joints share their parameters
  // After a calibration solve the tracker continues from the current frame's pose as the solve
  // refined it with the new shape (false: from its own pose, fitted with the previous shape).
  bool seed_pose = true;
  // bones, bones_girth: leaf segments (head, hands, feet) get their own length parameter
  // instead of stretching with their bone (models/shape.h).
  bool leaf_lengths = true;
  // bones, bones_girth: the shoulders' and hips' offsets get a width factor across the parent's
  // axis besides their length along it (models/shape.h).
  bool fork_widths = true;
  // bones_girth: each girth segment also gets a depth factor (its cross-section's front-back
  // extent against its width, models/shape.h), bounded like the girths. A subject's trunk and
  // limbs differ from the template in proportion, not only in size.
  bool girth_depth = false;
  // girth_depth: depth_prior_weight |q_d|^2 per depth parameter (the depth factor's departure
  // from the segment's girth), cost m^2 per unit^2 as prior_weight. A one-sided view sees a
  // cross-section's depth only where the segment turns; this keeps it near the template's
  // proportions where the data say little. 0: off.
  double depth_prior_weight = 0.0;
  int calibration_frames = 5;  // accepted frames per calibration round (>= 1)
  // Every n-th accepted frame (with a settled global scale) is a calibration frame: poses
  // further apart constrain the bone lengths better. >= 1.
  int calibration_stride = 2;
  // Calibration rounds: after a round's solve the tracker continues with the new shape and the
  // next round collects fresh frames (tracked closer to the truth, so the solve starts nearer
  // its optimum) and solves again from the current shape. >= 1.
  int calibration_rounds = 3;
  // Radius E-step schedule (m) of the joint solve, coarse to fine, and GN iterations per stage.
  std::vector<double> radii = {0.06, 0.04, 0.03};
  int iterations_per_stage = 12;
  // Over-relaxed EM (as EMFitterOptions::over_relaxation): the GN step is scaled by this
  // factor; the correspondences pull tangentially (along the limbs, where the bone lengths act)
  // only weakly per E-step, plain EM (1) creeps there. In [1, 2).
  double over_relaxation = 1.7;
  // The radius E-step's mean mu_t of a curved surface lies inside it (chord means: ~5 mm on a
  // 3 cm limb at radius 3 cm), which biases girths and lengths low. With this on, the bias is
  // measured on the posed shaped template itself (its E-step against its own vertices, zero
  // for a perfect fit without the correction) and subtracted from mu_t.
  bool bias_correction = true;
  // The camera sees one side of the body and loses points at grazing angles: the self E-step
  // uses only the template vertices facing the camera (cosine of the normal with the direction
  // to the camera above this) when the depth camera is known (SetDepthCamera), else all.
  double visibility_min_cos = 0.3;
  // ... and keeps each of them with probability cos(angle to the view ray), the depth camera's
  // sampling density (the template's vertices are uniform over the surface; a scan thins out
  // towards the silhouette, which moves its E-step means further inwards).
  bool bias_density = true;
  // ... and keeps only those the frame's depth image saw: a scan point projects within
  // bias_mask_radius_px pixels of the vertex's pixel at a camera depth within
  // bias_mask_tolerance (m) of the vertex's, or the frame's free-space map (scan.silhouette,
  // built for it by the pipeline) shows another surface behind the vertex there (a misfit, no
  // hole). The sensor's drop-outs (depth discontinuities and grazing angles together make the
  // legs come out long) and the body's self-occlusion then leave the same holes in both
  // E-steps. Needs the depth camera. With the floor term (floor_weight) it lowered the vertex
  // error of nine of eleven subjects and the joint error of all four tall ones, and costs the
  // MakeHuman body 1.2-1.5 mm (docs/shape-measurements.md, "The self E-step with the sensor's
  // holes"). The pipeline builds the free-space maps of the frames the estimator keeps.
  bool bias_scan_mask = true;
  double bias_mask_tolerance = 0.03;
  int bias_mask_radius_px = 1;
  // The self scans as the depth camera samples the posed template (needs SetDepthCamera):
  // every pixel of its z-buffer, back-projected, its normal interpolated from the triangle's
  // vertex normals, kept by the same facing test and scan mask; instead of its vertices thinned
  // by bias_density. A scan is a pixel grid several times denser than the template's vertices,
  // so the self scan then has the scan's sampling, its voxel subsampling and its occlusions:
  // for a noise-free camera the truth is a fixed point only with both self scans rendered
  // (tests/solvers/shape_estimator_test.cc). The scan-to-model term's is rendered by default
  // (bias_rendered_scan_to_model): on the virtual Kinect it lowered the joint error of eight of
  // eleven subjects. The E-step's is rendered in the radius stages up to
  // bias_rendered_estep_max_radius (m; 0, the default: never). In every stage it gets the
  // default subject's legs right but sends the tall subjects' hips 5 cm low; in the last stage
  // (0.03 with the default radii) it lowers the tall subjects' vertex error further, but the
  // default subject's shank comes out 2.2 cm long (docs/shape-measurements.md, "The self scans
  // on the depth camera's pixel grid").
  bool bias_rendered_scan_to_model = true;
  double bias_rendered_estep_max_radius = 0.0;
  // Floor term: a posed template vertex below the floor (SetFloor: the plane the pipeline finds
  // in the first frame) is pushed up onto it, floor_weight / (fit vertices) per vertex and
  // frame, relative to the data term (normalised per frame). The preprocessing removes the floor
  // and with it the feet's underside; nothing else keeps the legs from growing into it (with
  // bias_scan_mask a short subject's legs ran 76 mm long, its feet 12-19 cm under the floor:
  // docs/shape-measurements.md, "The floor term"). 0, or no floor set: off.
  double floor_weight = 1.0;
  // Girths are held at stages with a radius above this (m): wide radii bias them most.
  double girth_max_radius = 0.04;
  // Scan-to-model term: every scan point (voxel-subsampled, cell `scan_to_model_voxel` m)
  // pulls its nearest posed template vertex (within `scan_to_model_max_distance` m), weight
  // `scan_to_model_weight` relative to the data term (both normalised per frame). The
  // template-to-scan E-step alone sees no scan beyond its radius: where the template's limbs
  // are short (its feet on the subject's shins) the scan's feet pull nothing and the bone
  // lengths stay short; this term makes the template cover the scan. 0: off.
  double scan_to_model_weight = 0.3;
  double scan_to_model_voxel = 0.01;
  double scan_to_model_max_distance = 0.3;
  // A scan point's "nearest" vertex also weighs the normals: of its 8 nearest vertices the one
  // minimising |p - x|^2 + d^2 |n_p - n_x|^2, d this distance (m; 0: the nearest alone). A
  // hand hanging beside a thigh then pulls the hand's vertices, not the thigh's side, which
  // faces another way (docs/shape-measurements.md, "B's remaining error").
  double scan_to_model_normal_distance = 0.0;
  // Parameters the solve's frames do not show are held at their current value: a bone whose
  // parent or own joint the tracker's out-of-view test (fitting.out_of_view, needs
  // SetDepthCamera) holds in every frame, a girth, leaf length or depth factor whose joint it
  // holds in every frame. Without it a person framed from the waist up got legs at the bound
  // (0.7): the thighs' stubs at the image border pull the template's legs up into view.
  bool hold_unseen = true;
  // The term also moves the girths (false: bone lengths and poses only).
  bool scan_to_model_girth = true;
  // Chain prior: chain_prior_weight |b_j - b_c|^2 per pair of collinear bones (a bone and the
  // one continuing it: thigh/shank, upper arm/forearm, spine/chest/neck/head). Their split is
  // seen only through the bends (the knee in a walk; the elbow and the spine hardly bend), so
  // without it the split drifts (the generator and real bodies keep it within a few per cent).
  // Cost m^2 per unit^2 of a factor difference, as prior_weight. 0: off.
  double chain_prior_weight = 1e-3;
  // Limb girth chain prior: limb_girth_prior_weight |g_a - g_b|^2 for the two segments of a
  // limb between its fork and its leaf (thigh/shank, upper arm/forearm; not the feet, hands or
  // trunk). Cost m^2 per unit^2 of a factor difference, as prior_weight. 0: off.
  double limb_girth_prior_weight = 0.0;
  double prior_weight = 1e-5;             // towards the template (cost m^2 per unit^2 of a factor)
  double pose_damping = 1e-5;             // per frame on the pose update (per unit^2 / rad^2 / m^2)
  double bone_min = 0.7, bone_max = 1.4;  // bone length factor bounds
  double girth_min = 0.6, girth_max = 1.6;  // girth factor bounds
  // After calibration: refine the shape on every n-th accepted frame (0: frozen).
  int refine_every = 0;
  double refine_prior_weight = 1e-2;  // towards the current estimate
  int max_fit_vertices = 3000;        // template vertices in the solve (voxel subset; 0: all)
  EStepOptions estep;                 // the correspondence weights (colour term unused)
  // Per-vertex offsets along the normals after the last calibration round (solvers/
  // shape_detail.h; on by default). Needs the depth camera (SetDepthCamera).
  ShapeDetailOptions detail;

  bool IsValid(std::string* error) const;
};

// The scan-to-model term's correspondences: per vertex of `vertices`, how many of `samples`
// (within `max_distance` m) take it as their nearest, and their sum. `normal_distance` as
// ShapeOptions::scan_to_model_normal_distance (normals unit, one per row; 0: distance alone).
void ScanToModelSums(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3d& vertex_normals,
                     const Eigen::MatrixX3d& samples, const Eigen::MatrixX3d& sample_normals,
                     double max_distance, double normal_distance, std::vector<double>* count,
                     Eigen::MatrixX3d* sum);

struct ShapeSolveSummary {
  int frames = 0;
  int iterations = 0;
  double initial_cost = 0.0;  // data + priors at the start (per frame mean of m^2)
  double final_cost = 0.0;
  double seconds = 0.0;
  std::vector<int> held_unseen;  // columns of q held as unseen (hold_unseen), ascending
};

class ShapeEstimator {
 public:
  // Throws artex::Error on invalid options or template.
  ShapeEstimator(const Template& base, const ShapeOptions& options);
  ~ShapeEstimator();

  const ShapeOptions& options() const { return options_; }
  const ShapeModel& model() const { return model_; }
  bool enabled() const { return options_.mode != ShapeMode::kFixed; }
  // True once every calibration round has been solved.
  bool calibrated() const { return calibrated_; }
  // The rounds are solved and the surface detail (detail.enabled, a depth camera set) is
  // still to come.
  bool DetailPending() const;
  // Estimates a pending detail from the frames kept so far (the last round's, and fewer than
  // detail.frames more): the sequence ended first. Returns true when it did.
  bool FinishDetail();
  int rounds_done() const { return rounds_done_; }
  const Eigen::VectorXd& parameters() const { return q_; }  // Q entries
  BodyShape shape() const { return model_.Expand(q_); }
  // The shape model applied, with the surface detail (detail.enabled) once estimated.
  Template SubjectTemplate() const;
  // The surface detail's offsets (V, rest units; empty until estimated) and its summary.
  const Eigen::VectorXd& detail() const { return detail_; }
  const ShapeDetailSummary& detail_summary() const { return detail_summary_; }

  // The depth camera (intrinsics, world_to_camera; its centre for the bias correction's
  // visibility) and the tracker's out-of-view test, for hold_unseen.
  void SetDepthCamera(const PinholeCamera& camera, const OutOfViewOptions& out_of_view);
  // The floor plane (world frame): normal . x + offset = 0 on it, the normal (unit) pointing up
  // into the room. For the floor term (floor_weight). A solve whose scans have more than
  // kFloorMaxBelowFraction of their points further than kFloorBelowMargin below it does not
  // apply it (a plane mistaken for the floor, e.g. a table top): floor_contradicted().
  void SetFloor(const Eigen::Vector3d& normal, double offset);
  static constexpr double kFloorBelowMargin = 0.05;        // m
  static constexpr double kFloorMaxBelowFraction = 0.01;  // of a solve's scan points
  bool has_floor() const { return has_floor_; }
  // Some solve left the floor term out: its scans lay below the floor.
  bool floor_contradicted() const { return floor_contradicted_; }
  const Eigen::Vector3d& floor_normal() const { return floor_normal_; }
  double floor_offset() const { return floor_offset_; }
  // Names of the parameters the last calibration round held as unseen (hold_unseen), sorted as
  // the parameters.
  const std::vector<std::string>& unseen_parameters() const { return unseen_names_; }
  // Names of the parameters at a bound (bone_min/bone_max, girth_min/girth_max): the solve
  // would have moved them further.
  std::vector<std::string> ParametersAtBounds() const;
  // The parameters hold_unseen holds for frames posed as `poses` on their depth images (the
  // camera of SetDepthCamera; empty without one or with hold_unseen off). Public for tests.
  std::vector<int> UnseenParameters(const std::vector<Pose>& poses) const;

  // Pose priors of the tracker (terms that need no skinning: joint limits, coupled joints)
  // added to every calibration frame's pose in the joint solve, so that it minimises the
  // tracker's energy, not the data alone. Kept by shared ownership.
  void SetPosePriors(std::vector<std::shared_ptr<const FittingTerm>> priors) {
    pose_priors_ = std::move(priors);
  }

  // AddFrame keeps the next accepted frame (a calibration or surface detail frame, or a
  // refinement's): the caller builds what it needs only then (its free-space map, NeedsFreeSpace).
  bool KeepsNextFrame(bool scale_settled) const;
  // bias_scan_mask: the frames AddFrame keeps need their free-space maps (scan.silhouette).
  bool NeedsFreeSpace() const {
    return enabled() && options_.bias_correction && options_.bias_scan_mask;
  }

  // Feeds an accepted frame (scan and fitted pose, world frame). scale_settled: the tracker's
  // global scale is final (frames before are no calibration frames). Returns true when the
  // shape changed (calibration solved, or refined): the caller swaps SubjectTemplate() in.
  // *pose (optional) receives the frame's pose refined with the new shape.
  bool AddFrame(const Scan& scan, const Pose& pose, bool scale_settled, Pose* refined = nullptr);

  // The joint solve over the given frames from the current shape, prior towards q_ref with
  // `prior_weight`; updates parameters() and *poses. Public for tests.
  ShapeSolveSummary Solve(const std::vector<const Scan*>& scans, std::vector<Pose>* poses,
                          const Eigen::VectorXd& q_ref, double prior_weight);

  // Of all rounds: frames and iterations summed, the first round's initial and the last
  // round's final cost, seconds summed.
  const ShapeSolveSummary& calibration_summary() const { return calibration_; }
  int refinements() const { return refinements_; }
  double refine_seconds() const { return refine_seconds_; }

 private:
  // Estimates the detail once the last round's and detail.frames more frames are kept.
  bool EstimateDetailWhenDue(bool now = false);
  void ClampToBounds(Eigen::VectorXd* q) const;
  void Bounds(int p, double* lo, double* hi) const;  // of q_p (factor - 1)

  ShapeOptions options_;
  ShapeModel model_;
  std::vector<std::shared_ptr<const FittingTerm>> pose_priors_;
  PinholeCamera depth_camera_;
  OutOfViewOptions out_of_view_;
  bool has_depth_camera_ = false;
  Eigen::Vector3d floor_normal_ = Eigen::Vector3d::UnitY();
  double floor_offset_ = 0.0;
  bool has_floor_ = false;
  bool floor_contradicted_ = false;
  std::vector<std::string> unseen_names_;
  std::vector<int> fit_vertices_;
  Eigen::MatrixXd chain_;  // collinear bone pairs x Q: difference of their length factors
  Eigen::MatrixXd limb_girth_;  // limb segment pairs x Q: difference of their girth factors
  Eigen::VectorXd q_;
  std::vector<Scan> scans_;
  std::vector<Pose> poses_;
  int accepted_ = 0;  // frames seen with a settled scale
  int after_ = 0;     // frames seen after calibration
  bool calibrated_ = false;
  int rounds_done_ = 0;
  ShapeSolveSummary calibration_;
  int refinements_ = 0;
  double refine_seconds_ = 0.0;
  Eigen::VectorXd detail_;
  ShapeDetailSummary detail_summary_;
};

}  // namespace artex
