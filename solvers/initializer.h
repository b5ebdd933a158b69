// Multi-hypothesis initialisation of the fit (docs/fitting.md "Initialisation"): for a first
// frame (or a re-initialisation) the template is tried in several global orientations (yaw
// about world +Y relative to facing the depth camera: facing it, facing away, both sides) and
// arm poses (arms down, A-pose, T-pose), each placed by a camera-aware coarse step (nominal
// scale; translation that matches the centroid of the template's camera-facing vertices inside
// the depth image to the scan centroid, so a person cut by the image border is placed by the
// part that is seen), pre-aligned by similarity ICP (solvers/icp_init.h) and ranked by the fit
// quality (solvers/fit_quality.h); the best few are fitted by the EMFitter's first-frame
// schedule (the best of each yaw by default) and the best fit by quality score is accepted,
// fits that bend a knee forwards (a body turned round) ranking last.
#pragma once

#include <limits>
#include <map>
#include <string>
#include <vector>

#include "models/pose.h"
#include "render/camera.h"
#include "sensors/scan.h"
#include "solvers/em_fitter.h"
#include "solvers/fit_quality.h"
#include "solvers/icp_init.h"

namespace artex {

// Elbow variants of the arm refinement (InitializerOptions::refine_forearm_bends).
enum class ForearmBend { kStraight, kUp, kForward, kAcross };
const std::map<std::string, ForearmBend>& ForearmBendNames();  // straight, up, forward, across

struct InitializerOptions {
  // Yaw hypotheses (degrees) about world +Y relative to facing the camera: 0 turns the
  // template's front (+Z) towards the depth camera centre, 180 away from it, +-90 sideways.
  std::vector<double> yaws_deg = {0.0, 180.0, 90.0, -90.0};
  // World direction of "up" (the template's +Y): +Y for artex sequences; e.g. (0, -1, 0) for a
  // recording whose world frame is the depth camera's (OpenCV, y down; TUM RGB-D). Yaws are
  // rotations about it.
  Eigen::Vector3d world_up = Eigen::Vector3d::UnitY();
  // Arm hypotheses: elevation of both upper arms below the horizontal (degrees), set by a
  // shoulder rotation about the axis that raises the arm in the frontal plane: 80 ~ arms down,
  // 40 A-pose (the default template's rest), 0 T-pose. Needs joints named l_shoulder,
  // l_elbow, r_shoulder, r_elbow; without them the initial pose's arms are the only variant.
  std::vector<double> arm_angles_deg = {80.0, 40.0, 0.0};
  int coarse_iterations = 5;  // fixed-point steps of the visible-centroid translation
  // Pre-alignment of every hypothesis (its coarse_alignment is ignored: the initialiser's own
  // camera-aware step replaces it). Fewer points and iterations than a single-start ICP.
  // Rigid (estimate_scale false): a similarity ICP of a hypothesis whose arms do not match
  // (arms raised, a person cut by the border) grows the scale to cover them (skeltrack: 1.26-1.47
  // instead of about 1.05); the scale is estimated after the initialisation from close pairs.
  IcpInitOptions icp = [] {
    IcpInitOptions o;
    o.max_scan_points = 1500;
    o.max_iterations = 30;
    o.estimate_scale = false;
    return o;
  }();
  // The best this many ICP hypotheses (by quality score) are fitted by EM (>= 1). ICP from a
  // rest-like pose ranks the facings poorly when the person is mid-stride (the ICP scores of
  // facing away and towards the camera differ by ~0.05, after EM the right one wins by ~0.03),
  // so by default every yaw's best arm variant is fitted.
  int em_candidates = 4;
  // Candidates are the best arm variant of each yaw first (in score order), then the rest;
  // false: plain score order (several arm variants of one facing may take the places).
  bool em_one_per_yaw = true;
  // A candidate whose fit bends a knee forwards by more than this (degrees; KneeHyperextensionDeg)
  // ranks below every candidate that does not: a body turned round explains the depth nearly as
  // well as the right one, and its knees then bend the wrong way (docs/fitting.md "How often
  // the first frame is wrong"). The fits of 360 tracked virtual-Kinect frames bend forwards by at
  // most 4.8 degrees; the turned-round first frames by 13-26. 0: off.
  double max_knee_hyperextension_deg = 10.0;
  // EM iterations of a candidate's ranking fit (0: the whole first-frame schedule, and the
  // best candidate is accepted as fitted). > 0: a short fit for ranking, then the best
  // candidate is fitted again from its result with the whole first-frame schedule.
  int ranking_iterations = 0;
  // Arm refinement after the EM fits (the symmetric arm hypotheses above cannot show one arm
  // raised and the other down): each arm of the best fit is tried, straight, in the directions
  // below relative to the torso, scored by the fit quality without fitting; the best
  // direction of each arm (when it scores above the fitted arm) starts one more EM fit, kept
  // when its score is higher. Elevations below the horizontal (degrees): in the frontal plane
  // (80 down ... -80 straight up) and forwards (in front of the body).
  bool refine_arms = true;
  std::vector<double> refine_side_angles_deg = {80.0, 40.0, 0.0, -40.0, -80.0};
  std::vector<double> refine_front_angles_deg = {45.0, 0.0, -45.0};
  // Forearm of every tried direction: straight, bent up (a raised fist), forwards, or across
  // the body (the hand in front of the chest); a bend the forearm already has is skipped.
  // Straight only by default: all four change one of the twelve real stills slightly for
  // twice the initialisation time (docs/fitting.md "Unobserved joints").
  std::vector<ForearmBend> refine_forearm_bends = {ForearmBend::kStraight};
  FitQualityOptions quality;  // ranking (score) and the reported labels

  bool IsValid(std::string* error) const;
};

struct InitHypothesis {
  double yaw_deg = 0.0;        // relative to facing the camera
  double arm_angle_deg = 0.0;  // NaN: the initial pose's arms
  IcpInitResult icp;           // the pre-aligned pose
  FitQuality icp_quality;
  bool fitted = false;  // ranked by an EM fit
  FitSummary fit;       // of that fit
  Pose pose;            // after EM when fitted, else after ICP
  // KneeHyperextensionDeg of `pose` (NaN: not measured, or the template lacks the joints).
  double knee_hyperextension_deg = std::numeric_limits<double>::quiet_NaN();
  FitQuality quality;   // of `pose`
};

struct InitResult {
  bool ok = false;
  // EM fits ranked last for a knee bent forwards (max_knee_hyperextension_deg).
  int knees_bent_forwards = 0;
  bool arms_refined = false;  // the accepted fit started from a refined arm pose  // a hypothesis
                              // was fitted and accepted as the fitter's frame
  int chosen = -1;            // index into hypotheses
  std::vector<InitHypothesis> hypotheses;
  Pose pose;           // the accepted pose (fitter->pose())
  FitQuality quality;  // its quality
  FitSummary fit;      // its EM summary (the frame's)
  // Wall times: the hypotheses' ICP; the EM fits (the candidates' quality scores, computed
  // alongside their concurrent fits, included); the other quality scores; the whole call.
  double icp_seconds = 0.0, em_seconds = 0.0, quality_seconds = 0.0, total_seconds = 0.0;

  std::string BriefReport() const;
};

// How far the knees bend forwards, from posed joint centres (J x 3, the template's joints): for
// each leg, the angle between the thigh (hip to knee) and the shank (knee to ankle), positive
// when the shank bends towards the body's front (hyperextended), negative when it bends back as
// a knee does; the larger of the two legs (degrees). The front is the hips' left-right axis
// (l_hip - r_hip) crossed with the trunk's (pelvis to neck). NaN when the template lacks a joint
// named pelvis, neck, l_hip, l_knee, l_ankle, r_hip, r_knee or r_ankle.
double KneeHyperextensionDeg(const Template& model, const Eigen::MatrixX3d& joint_centers);

// Fits `scan` as the next frame of `fitter` (normally its first, or the first after
// fitter->Reset(); the scale then starts at fitter->PredictNextPose().scale, the nominal 1 or a
// kept estimate, and is estimated only when fitter->ScaleIsFree()). On success (ok) the fitter
// has the chosen pose as its accepted frame. With too few scan points, or when no candidate's
// fit passes the robustness checks, the frame is fitted by fitter->FitFrame / from the best ICP
// pose, as a normal frame (ok = false when that frame fails too). Throws artex::Error on
// invalid options. A fitter without a depth camera (EMFitter::SetDepthCamera) is given
// `depth_camera`, so joints out of its view are held (EMFitterOptions::out_of_view).
InitResult InitializeFit(EMFitter* fitter, const Scan& scan, const PinholeCamera& depth_camera,
                         const InitializerOptions& options);

// Refit after a gap in the frames (RefitFromPose).
struct GapRefitOptions {
  int coarse_iterations = 5;  // fixed-point steps of the re-centred start (0: none)
  // E-step radii (m) and EM iterations per radius of the refit (empty: the first-frame schedule).
  std::vector<double> radii = {0.08, 0.04, 0.03};
  int iterations_per_stage = 4;
  bool align_moved = true;  // rigid ICP of the re-centred start (`icp`, coarse step and scale off)
  IcpInitOptions icp = [] {
    IcpInitOptions o;
    o.max_scan_points = 1500;
    o.max_iterations = 30;
    return o;
  }();
  FitQualityOptions quality;  // ranks the starts and the fits
  // Two more fits, from the better start with the legs in stride: one hip swung forward and
  // the other back by this angle (degrees, about the template's left-right axis), each way
  // round; the fit with the best quality score is kept (0: the one fit of the better start).
  // A subject that stepped during the gap otherwise often ends up with both template legs in
  // one scan leg, a fit the quality labels still take for good.
  double leg_stride_deg = 20.0;

  bool IsValid(std::string* error) const;
};

// Fits `scan` after a gap in the frames (live mode: frames dropped while the tracker was busy,
// e.g. during the first frame's initialisation) from `start` (the last fitted pose), which the
// motion since may have left beyond a tracking frame's E-step radii. Two starts are ranked by
// the fit quality score: `start` itself, and `start` translated so that the centroid of its
// template vertices facing the camera and inside the depth image matches the scan centroid (the
// initialiser's coarse placement: it follows a subject that walked on, but is biased by a few
// centimetres, so a subject that stayed keeps `start`). The better is fitted as a first frame
// with options.radii, and with options.leg_stride_deg also that start with its legs in stride
// both ways round; the fit with the best quality score is kept. The fitter's history restarts
// from this frame (Reset, the scale estimate kept: the motion before the gap says little about
// the speed after it). The summary is the kept fit's, with the EM iterations and time of all
// the fits. Throws artex::Error for a pose with the wrong joint count or invalid options.
FitSummary RefitFromPose(EMFitter* fitter, const Scan& scan, const PinholeCamera& depth_camera,
                         const Pose& start, const GapRefitOptions& options);

// Yaw (radians) of a global rotation: the angle about +Y of its image of the template front
// +Z, atan2(x, z) of R e_z (0: facing +Z).
double YawOfRotation(const Eigen::Matrix3d& rotation);

}  // namespace artex
