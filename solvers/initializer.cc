#include "solvers/initializer.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <numeric>
#include <sstream>

#include "models/error.h"
#include "models/normals.h"
#include "models/numeric.h"
#include "models/so3.h"

namespace artex {

namespace {

using Clock = std::chrono::steady_clock;

// `base` with both upper arms at `elevation_deg` below the horizontal (rotation about the axis
// that raises the rest-pose upper arm), or false when the template has no such joints.
bool WithArms(const Template& model, const Pose& base, double elevation_deg, Pose* out) {
  *out = base;
  const char* const arms[2][2] = {{"l_shoulder", "l_elbow"}, {"r_shoulder", "r_elbow"}};
  for (const auto& arm : arms) {
    const int shoulder = model.FindJoint(arm[0]), elbow = model.FindJoint(arm[1]);
    if (shoulder < 0 || elbow < 0) return false;
    const Eigen::Vector3d upper = model.joints[elbow].center - model.joints[shoulder].center;
    const Eigen::Vector3d axis = upper.cross(Eigen::Vector3d::UnitY());
    if (upper.norm() <= 0.0 || axis.norm() <= 1e-9) return false;
    const double rest_deg = std::asin(std::clamp(-upper.normalized().y(), -1.0, 1.0)) / kDegToRad;
    out->joint_rotations[shoulder] =
        ExpSO3(axis.normalized() * ((rest_deg - elevation_deg) * kDegToRad));
  }
  return true;
}

// `base` with the arm of `shoulder` (its elbow straightened) pointing in the direction
// `elevation_deg` below the horizontal, sideways (frontal plane) or forwards, relative to the
// parent's frame (the torso).
Pose WithArmDirection(const Template& model, const Pose& base, int shoulder, int elbow,
                      int wrist, double elevation_deg, bool forwards, ForearmBend bend) {
  Pose out = base;
  const Eigen::Vector3d upper = model.joints[elbow].center - model.joints[shoulder].center;
  const double e = elevation_deg * kDegToRad;
  const double side = upper.x() >= 0.0 ? 1.0 : -1.0;
  // A little outwards when forwards, so the arm does not pass through the chest.
  const Eigen::Vector3d direction = forwards
                                        ? Eigen::Vector3d(0.2 * side, -std::sin(e), std::cos(e))
                                        : Eigen::Vector3d(side * std::cos(e), -std::sin(e), 0.0);
  const Eigen::Matrix3d r_shoulder =
      Eigen::Quaterniond::FromTwoVectors(upper.normalized(), direction.normalized())
          .toRotationMatrix();
  out.joint_rotations[shoulder] = r_shoulder;
  out.joint_rotations[elbow] = Eigen::Matrix3d::Identity();
  if (bend == ForearmBend::kStraight || wrist < 0) return out;
  // The forearm's direction in the template frame (+Y up, +Z front); the elbow's rotation
  // R_e with R_s R_e f_rest = f (rotations compose along the chain in the rest frame).
  const Eigen::Vector3d forearm = model.joints[wrist].center - model.joints[elbow].center;
  const Eigen::Vector3d f = bend == ForearmBend::kUp        ? Eigen::Vector3d(0.0, 1.0, 0.0)
                            : bend == ForearmBend::kForward ? Eigen::Vector3d(0.0, 0.0, 1.0)
                                                            : Eigen::Vector3d(-side, 0.0, 0.3);
  const Eigen::Vector3d current = r_shoulder * forearm.normalized();
  if (current.dot(f.normalized()) > 0.95) return out;  // already (nearly) that way
  out.joint_rotations[elbow] =
      r_shoulder.transpose() *
      Eigen::Quaterniond::FromTwoVectors(current, f.normalized()).toRotationMatrix() * r_shoulder;
  return out;
}

}  // namespace

const std::map<std::string, ForearmBend>& ForearmBendNames() {
  static const std::map<std::string, ForearmBend> names = {{"straight", ForearmBend::kStraight},
                                                           {"up", ForearmBend::kUp},
                                                           {"forward", ForearmBend::kForward},
                                                           {"across", ForearmBend::kAcross}};
  return names;
}

bool InitializerOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  std::string inner;
  const auto finite = [](const std::vector<double>& v) {
    return std::all_of(v.begin(), v.end(), [](double x) { return std::isfinite(x); });
  };
  if (yaws_deg.empty() || !finite(yaws_deg)) {
    msg << "yaws_deg: expected at least one finite yaw (degrees)";
  } else if (!(world_up.allFinite() && world_up.norm() > 0.0)) {
    msg << "world_up: expected a finite non-zero direction, found (" << world_up.transpose() << ")";
  } else if (!finite(arm_angles_deg)) {
    msg << "arm_angles_deg: expected finite angles (degrees)";
  } else if (coarse_iterations < 0) {
    msg << "coarse_iterations: expected >= 0, found " << coarse_iterations;
  } else if (!icp.IsValid(&inner)) {
    msg << "icp." << inner;
  } else if (em_candidates < 1) {
    msg << "em_candidates: expected >= 1, found " << em_candidates;
  } else if (!std::isfinite(max_knee_hyperextension_deg)) {
    msg << "max_knee_hyperextension_deg: expected a finite angle (degrees; 0: off), found "
        << max_knee_hyperextension_deg;
  } else if (ranking_iterations < 0) {
    msg << "ranking_iterations: expected >= 0 (0: the whole schedule), found "
        << ranking_iterations;
  } else if (!finite(refine_side_angles_deg) || !finite(refine_front_angles_deg)) {
    msg << "refine_side_angles_deg, refine_front_angles_deg: expected finite angles (degrees)";
  } else if (!quality.IsValid(&inner)) {
    msg << "quality." << inner;
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

double KneeHyperextensionDeg(const Template& model, const Eigen::MatrixX3d& joint_centers) {
  const int pelvis = model.FindJoint("pelvis"), neck = model.FindJoint("neck");
  const int legs[2][3] = {{model.FindJoint("l_hip"), model.FindJoint("l_knee"),
                           model.FindJoint("l_ankle")},
                          {model.FindJoint("r_hip"), model.FindJoint("r_knee"),
                           model.FindJoint("r_ankle")}};
  const double nan = std::numeric_limits<double>::quiet_NaN();
  if (pelvis < 0 || neck < 0 || joint_centers.rows() != model.num_joints()) return nan;
  for (const auto& leg : legs) {
    for (int j : leg) {
      if (j < 0) return nan;
    }
  }
  const auto at = [&](int j) { return Eigen::Vector3d(joint_centers.row(j).transpose()); };
  const Eigen::Vector3d left = at(legs[0][0]) - at(legs[1][0]);
  const Eigen::Vector3d front = left.cross(at(neck) - at(pelvis));
  double largest = -std::numeric_limits<double>::infinity();
  for (const auto& leg : legs) {
    const Eigen::Vector3d thigh = (at(leg[1]) - at(leg[0])).normalized();
    const Eigen::Vector3d shank = at(leg[2]) - at(leg[1]);
    const Eigen::Vector3d bend = shank - shank.dot(thigh) * thigh;
    const double angle = std::atan2(bend.norm(), shank.dot(thigh)) / kDegToRad;
    largest = std::max(largest, bend.dot(front) > 0.0 ? angle : -angle);
  }
  return std::isfinite(largest) ? largest : nan;
}

std::string InitResult::BriefReport() const {
  std::ostringstream out;
  out << (ok ? "initialised" : "initialisation failed") << " from " << hypotheses.size()
      << " hypotheses";
  if (chosen >= 0) {
    const InitHypothesis& h = hypotheses[chosen];
    out << ", chosen yaw " << h.yaw_deg << " deg, arms "
        << (arms_refined ? std::string("refined") : std::to_string(h.arm_angle_deg) + " deg")
        << ", " << quality.BriefReport();
  }
  if (knees_bent_forwards > 0) {
    out << ", " << knees_bent_forwards << " fits ranked last for a knee bent forwards";
  }
  out << "; " << total_seconds * 1e3 << " ms (ICP " << icp_seconds * 1e3 << ", EM "
      << em_seconds * 1e3 << ", quality " << quality_seconds * 1e3 << ")";
  return out.str();
}

double YawOfRotation(const Eigen::Matrix3d& rotation) {
  const Eigen::Vector3d front = rotation.col(2);
  return std::atan2(front.x(), front.z());
}

namespace {

// Fixed-point steps that move *translation so that the centroid of the vertices
// scale * rotation * x + translation that face the camera and project into its image matches
// scan_centroid (stops early when none is visible).
void PlaceAtVisibleCentroid(const Eigen::MatrixX3d& x, const Eigen::MatrixX3d& xn, double scale,
                            const Eigen::Matrix3d& rotation, const Eigen::Vector3d& scan_centroid,
                            const PinholeCamera& camera, int iterations,
                            Eigen::Vector3d* translation) {
  const Eigen::Vector3d eye = camera.Center();
  for (int it = 0; it < iterations; ++it) {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    int count = 0;
    for (int t = 0; t < x.rows(); ++t) {
      const Eigen::Vector3d w = scale * rotation * x.row(t).transpose() + *translation;
      if ((rotation * xn.row(t).transpose()).dot(eye - w) <= 0.0) continue;
      double z = 0.0;
      const Eigen::Vector2d uv = camera.Project(w, &z);
      if (!(z > 0.0) || uv.x() < -0.5 || uv.y() < -0.5 || uv.x() > camera.width - 0.5 ||
          uv.y() > camera.height - 0.5) {
        continue;
      }
      sum += w;
      ++count;
    }
    if (count == 0) break;
    *translation += scan_centroid - sum / count;
  }
}

// body(i) for every i in [0, n), each as its own oneTBB task (concurrently, in no fixed order;
// the parallel loops inside body share the same workers).
template <typename Body>
void ForEachConcurrently(int n, const Body& body) {
  tbb::parallel_for(
      tbb::blocked_range<int>(0, n, 1),
      [&](const tbb::blocked_range<int>& r) {
        for (int i = r.begin(); i != r.end(); ++i) body(i);
      },
      tbb::simple_partitioner());
}

}  // namespace

InitResult InitializeFit(EMFitter* fitter, const Scan& scan, const PinholeCamera& depth_camera,
                         const InitializerOptions& options) {
  const auto start = Clock::now();
  std::string error;
  if (!options.IsValid(&error)) throw Error("initializer options: " + error);
  if (fitter == nullptr) throw Error("InitializeFit: expected an EM fitter, found null");
  InitResult result;
  const Skinning& skinning = fitter->skinning();
  const Template& model = skinning.model();
  const bool by_part = options.quality.part_min_support > 0.0;  // the per-part check is on
  const Eigen::VectorXi parts =
      by_part ? FitQualityParts(model.vertex_joint, model.JointNames(), options.quality)
              : Eigen::VectorXi();
  // quality_of is thread-safe; evaluate adds its time to quality_seconds (one thread at a time;
  // the concurrent batch of quality_of is timed as a whole).
  const auto quality_of = [&](const Pose& pose) {
    Eigen::MatrixX3d posed;
    skinning.Apply(pose, &posed);
    return EvaluateFitQuality(posed, model.triangles, scan, depth_camera, options.quality,
                              by_part ? &parts : nullptr);
  };
  const auto evaluate = [&](const Pose& pose) {
    const auto t0 = Clock::now();
    const FitQuality q = quality_of(pose);
    result.quality_seconds += SecondsSince(t0);
    return q;
  };
  // A fit bending a knee forwards beyond the bound (max_knee_hyperextension_deg) ranks below
  // every fit that does not; among fits of one kind the quality score decides.
  const auto knee_of = [&](const Pose& pose) {
    Eigen::MatrixX3d centers;
    skinning.PosedJointCenters(pose, &centers);
    return KneeHyperextensionDeg(model, centers);
  };
  const auto implausible = [&](const InitHypothesis& h) {
    return options.max_knee_hyperextension_deg > 0.0 &&
           h.knee_hyperextension_deg > options.max_knee_hyperextension_deg;
  };
  const auto better = [&](const InitHypothesis& a, const InitHypothesis& b) {
    if (implausible(a) != implausible(b)) return !implausible(a);
    return a.quality.score > b.quality.score;
  };
  const auto finish = [&](InitResult* r) {
    r->pose = fitter->pose();
    r->total_seconds = SecondsSince(start);
  };
  // The hypotheses' joints out of the camera's view are held (EMFitterOptions::out_of_view).
  if (fitter->depth_camera() == nullptr) fitter->SetDepthCamera(depth_camera);
  const bool finite = scan.points.allFinite() && scan.normals.allFinite();
  if (scan.size() < std::max(fitter->options().min_scan_points, 3) || !finite ||
      scan.normals.rows() != scan.points.rows()) {
    result.fit = fitter->FitFrame(scan);  // flagged too_few_points / non_finite
    result.ok = result.fit.ok();
    finish(&result);
    return result;
  }

  // Arm variants of the start pose, at the scale the fitter would use.
  const Pose base = fitter->PredictNextPose();
  std::vector<std::pair<double, Pose>> arm_poses;
  for (double angle : options.arm_angles_deg) {
    Pose p;
    if (WithArms(model, base, angle, &p)) arm_poses.emplace_back(angle, p);
  }
  if (arm_poses.empty()) arm_poses.emplace_back(std::numeric_limits<double>::quiet_NaN(), base);

  const Eigen::Vector3d scan_centroid = scan.points.colwise().mean().transpose();
  const Eigen::Vector3d eye = depth_camera.Center();
  // Template up (+Y) to world_up, then the template front (+Z) turned about world_up towards
  // the camera.
  const Eigen::Vector3d up = options.world_up.normalized();
  const Eigen::Matrix3d upright =
      Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitY(), up).toRotationMatrix();
  const Eigen::Vector3d front = upright * Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d to_camera = eye - scan_centroid;
  const double facing_yaw =
      std::atan2(front.cross(to_camera).dot(up), front.dot(to_camera - to_camera.dot(up) * up));
  IcpInitOptions icp = options.icp;
  icp.coarse_alignment = false;
  icp.estimate_scale = icp.estimate_scale && fitter->ScaleIsFree();

  // 1. Coarse placement and similarity ICP of every hypothesis (arm pose major, yaw minor),
  // concurrently: each writes only its own hypothesis, so the result does not depend on the
  // order or the number of threads.
  const auto icp_start = Clock::now();
  const int num_arms = static_cast<int>(arm_poses.size());
  const int num_yaws = static_cast<int>(options.yaws_deg.size());
  {
    // Posed once per arm pose, shared by its facings' coarse placements and ICP alignments.
    std::vector<std::unique_ptr<IcpTemplate>> targets(num_arms);
    ForEachConcurrently(num_arms, [&](int a) {
      targets[a] = std::make_unique<IcpTemplate>(skinning, arm_poses[a].second, icp.kd_leaf_size,
                                                 icp.grid_cell);
    });
    result.hypotheses.resize(num_arms * num_yaws);
    ForEachConcurrently(num_arms * num_yaws, [&](int i) {
      const auto& [arm_angle, arm_pose] = arm_poses[i / num_yaws];
      const IcpTemplate& target = *targets[i / num_yaws];
      const Eigen::MatrixX3d& x = target.vertices();
      const Eigen::MatrixX3d& xn = target.normals();
      const double yaw_deg = options.yaws_deg[i % num_yaws];
      InitHypothesis& h = result.hypotheses[i];
      h.yaw_deg = yaw_deg;
      h.arm_angle_deg = arm_angle;
      Pose pose = arm_pose;
      pose.rotation =
          Eigen::AngleAxisd(facing_yaw + yaw_deg * kDegToRad, up).toRotationMatrix() * upright;
      // Translation: the centroid of the template vertices that face the camera and project
      // into the depth image matches the scan centroid (fixed point; starts from all vertices).
      pose.translation = scan_centroid - pose.scale * pose.rotation *
                                             Eigen::Vector3d(x.colwise().mean().transpose());
      PlaceAtVisibleCentroid(x, xn, pose.scale, pose.rotation, scan_centroid, depth_camera,
                             options.coarse_iterations, &pose.translation);
      h.icp = AlignByIcp(target, pose, scan, icp);
      h.pose = h.icp.pose;
    });
  }  // the posed ICP templates are freed here
  result.icp_seconds = SecondsSince(icp_start);
  const auto icp_quality_start = Clock::now();
  ForEachConcurrently(static_cast<int>(result.hypotheses.size()), [&](int i) {
    InitHypothesis& h = result.hypotheses[i];
    h.icp_quality = quality_of(h.pose);
    h.quality = h.icp_quality;
  });
  result.quality_seconds += SecondsSince(icp_quality_start);

  // 2. EM fits of the best candidates.
  std::vector<int> order(result.hypotheses.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return result.hypotheses[a].icp_quality.score > result.hypotheses[b].icp_quality.score;
  });
  if (options.em_one_per_yaw) {
    // The best arm variant of each yaw first (in score order), then the others.
    std::vector<int> first, rest;
    std::vector<double> seen;
    for (int h : order) {
      const double yaw = result.hypotheses[h].yaw_deg;
      if (std::find(seen.begin(), seen.end(), yaw) == seen.end()) {
        seen.push_back(yaw);
        first.push_back(h);
      } else {
        rest.push_back(h);
      }
    }
    order = first;
    order.insert(order.end(), rest.begin(), rest.end());
  }
  const int candidates = std::min<int>(options.em_candidates, static_cast<int>(order.size()));
  const auto em_start = Clock::now();
  const double quality_before_em = result.quality_seconds;
  // Concurrently, each in its own copy of the fitter: a candidate's fit depends only on the
  // fitter's state between frames, which the copies share, so the fits (and the choice below,
  // in candidate order) are those of one fitter fitting them one after another.
  ForEachConcurrently(candidates, [&](int c) {
    InitHypothesis& h = result.hypotheses[order[c]];
    const std::unique_ptr<EMFitter> copy = fitter->Clone();
    copy->BeginFrame(scan, h.icp.pose);
    int iterations = 0;
    while (!copy->frame_done() &&
           (options.ranking_iterations == 0 || iterations < options.ranking_iterations)) {
      copy->Iterate();
      ++iterations;
    }
    h.fit = copy->DiscardFrame(&h.pose);
    h.fitted = true;
    h.quality = quality_of(h.pose);
    h.knee_hyperextension_deg = knee_of(h.pose);
  });
  int best = -1;
  for (int c = 0; c < candidates; ++c) {
    const InitHypothesis& h = result.hypotheses[order[c]];
    result.knees_bent_forwards += implausible(h);
    if (h.fit.ok() && (best < 0 || better(h, result.hypotheses[best]))) best = order[c];
  }

  // 2b. Arm refinement of the best fit: each arm's best straight direction by score.
  if (best >= 0 && options.ranking_iterations == 0 && options.refine_arms) {
    // A copy: the refined hypothesis is appended below, which may move the vector's elements.
    const InitHypothesis from = result.hypotheses[best];
    Pose refined = from.pose;
    double refined_score = from.quality.score;
    bool changed = false;
    const char* const arms[2][3] = {{"l_shoulder", "l_elbow", "l_wrist"},
                                    {"r_shoulder", "r_elbow", "r_wrist"}};
    for (const auto& arm : arms) {
      const int shoulder = model.FindJoint(arm[0]), elbow = model.FindJoint(arm[1]);
      const int wrist = model.FindJoint(arm[2]);
      if (shoulder < 0 || elbow < 0) continue;
      // The arm's directions replace its shoulder and elbow rotations whatever they were, so
      // they are all made from the pose as this arm's turn starts and scored concurrently; the
      // best is then taken in their order (the first of equal scores), as one after another.
      std::vector<Pose> tried;
      for (int forwards = 0; forwards < 2; ++forwards) {
        for (double angle :
             forwards ? options.refine_front_angles_deg : options.refine_side_angles_deg) {
          for (ForearmBend bend : options.refine_forearm_bends) {
            tried.push_back(
                WithArmDirection(model, refined, shoulder, elbow, wrist, angle, forwards, bend));
          }
        }
      }
      std::vector<double> scores(tried.size());
      const auto scoring_start = Clock::now();
      ForEachConcurrently(static_cast<int>(tried.size()),
                          [&](int k) { scores[k] = quality_of(tried[k]).score; });
      result.quality_seconds += SecondsSince(scoring_start);
      for (size_t k = 0; k < tried.size(); ++k) {
        if (scores[k] > refined_score) {
          refined_score = scores[k];
          refined = tried[k];
          changed = true;
        }
      }
    }
    if (changed) {
      InitHypothesis h;
      h.yaw_deg = from.yaw_deg;
      h.arm_angle_deg = std::numeric_limits<double>::quiet_NaN();
      h.icp = from.icp;
      h.icp_quality = from.icp_quality;
      fitter->BeginFrame(scan, refined);
      while (!fitter->frame_done()) fitter->Iterate();
      h.fit = fitter->DiscardFrame(&h.pose);
      h.fitted = true;
      h.quality = evaluate(h.pose);
      h.knee_hyperextension_deg = knee_of(h.pose);
      result.knees_bent_forwards += implausible(h);
      result.hypotheses.push_back(h);
      if (h.fit.ok() && better(h, from)) {
        best = static_cast<int>(result.hypotheses.size()) - 1;
        result.arms_refined = true;
      }
    }
  }

  // 3. Accept the best (or fit the best ICP pose as a normal frame).
  if (best >= 0 && options.ranking_iterations == 0) {
    fitter->AcceptPose(scan, result.hypotheses[best].pose);
    result.fit = result.hypotheses[best].fit;
    result.quality = result.hypotheses[best].quality;
    if (fitter->pose().scale != result.hypotheses[best].pose.scale) {
      result.quality = evaluate(fitter->pose());  // the scale sample moved the pose
    }
    result.fit.scale = fitter->pose().scale;
    result.ok = true;
  } else {
    const Pose& from =
        best >= 0 ? result.hypotheses[best].pose : result.hypotheses[order[0]].icp.pose;
    fitter->BeginFrame(scan, from);
    while (!fitter->frame_done()) fitter->Iterate();
    result.fit = fitter->EndFrame();
    result.ok = result.fit.ok();
    if (best < 0) best = order[0];
    result.quality = evaluate(fitter->pose());
  }
  result.em_seconds = SecondsSince(em_start) - (result.quality_seconds - quality_before_em);
  result.chosen = best;
  finish(&result);
  return result;
}

bool GapRefitOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (coarse_iterations < 0) {
    msg << "coarse_iterations: expected >= 0, found " << coarse_iterations;
  } else if (iterations_per_stage < 1) {
    msg << "iterations_per_stage: expected >= 1, found " << iterations_per_stage;
  } else if (std::any_of(radii.begin(), radii.end(),
                         [](double r) { return !(r > 0.0) || !std::isfinite(r); })) {
    msg << "radii: expected finite radii > 0 (m)";
  } else if (!(leg_stride_deg >= 0.0 && leg_stride_deg < 90.0)) {
    msg << "leg_stride_deg: expected an angle in [0, 90) degrees (0: off), found "
        << leg_stride_deg;
  } else if (!icp.IsValid(error)) {
    return false;
  } else {
    return quality.IsValid(error);
  }
  if (error) *error = msg.str();
  return false;
}

FitSummary RefitFromPose(EMFitter* fitter, const Scan& scan, const PinholeCamera& depth_camera,
                         const Pose& start, const GapRefitOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw Error("gap refit options: " + error);
  if (fitter == nullptr) throw Error("RefitFromPose: expected an EM fitter, found null");
  const Skinning& skinning = fitter->skinning();
  const Template& model = skinning.model();
  if (start.num_joints() != model.num_joints()) {
    throw Error("RefitFromPose: expected a pose of " + std::to_string(model.num_joints()) +
                " joints, found " + std::to_string(start.num_joints()));
  }
  if (fitter->depth_camera() == nullptr) fitter->SetDepthCamera(depth_camera);
  const auto score = [&](const Pose& p) {
    Eigen::MatrixX3d posed;
    skinning.Apply(p, &posed);
    return EvaluateFitQuality(posed, model.triangles, scan, depth_camera, options.quality).score;
  };
  Pose pose = start;
  if (options.coarse_iterations > 0 && scan.size() > 0 && scan.points.allFinite() &&
      start.AllFinite()) {
    Eigen::MatrixX3d x, xn;
    skinning.Apply(start, &x);
    ComputeVertexNormals(x, model.triangles, &xn);
    const Eigen::Vector3d scan_centroid = scan.points.colwise().mean().transpose();
    Eigen::Vector3d shift = Eigen::Vector3d::Zero();
    PlaceAtVisibleCentroid(x, xn, 1.0, Eigen::Matrix3d::Identity(), scan_centroid, depth_camera,
                           options.coarse_iterations, &shift);
    Pose moved = start;
    moved.translation += shift;
    // The centroid is biased (the far side of the template, parts the scan lacks): a rigid ICP
    // of the moved start against the scan places it.
    if (options.align_moved) {
      IcpInitOptions icp = options.icp;
      icp.coarse_alignment = false;
      icp.estimate_scale = false;
      moved = AlignByIcp(skinning, moved, scan, icp).pose;
    }
    if (shift.allFinite() && score(moved) > score(start)) pose = moved;
  }
  // The starts: the better one, and with legs in stride (template +X: the left-right axis).
  std::vector<Pose> starts = {pose};
  const int l_hip = model.FindJoint("l_hip"), r_hip = model.FindJoint("r_hip");
  if (options.leg_stride_deg > 0.0 && l_hip >= 0 && r_hip >= 0) {
    const double swing = options.leg_stride_deg * kDegToRad;
    for (const double sign : {1.0, -1.0}) {
      Pose p = pose;
      p.joint_rotations[l_hip] = ExpSO3(Eigen::Vector3d(sign * swing, 0.0, 0.0)) *
                                 pose.joint_rotations[l_hip];
      p.joint_rotations[r_hip] = ExpSO3(Eigen::Vector3d(-sign * swing, 0.0, 0.0)) *
                                 pose.joint_rotations[r_hip];
      starts.push_back(p);
    }
  }
  fitter->Reset(/*keep_scale=*/true);
  // Fits `from` on `f` (the fitter or a copy of it) up to ending the frame.
  const auto begin = [&](EMFitter* f, const Pose& from) {
    if (!options.radii.empty()) {
      f->SetNextFrameSchedule(options.radii, options.iterations_per_stage);
    }
    f->BeginFrame(scan, from);
    while (!f->frame_done()) f->Iterate();
  };
  if (starts.size() == 1) {
    begin(fitter, pose);
    return fitter->EndFrame();
  }
  // Every start fitted and discarded, concurrently, each in its own copy of the fitter (as
  // InitializeFit's candidates); the best by score is accepted, the first of equal scores.
  struct StartFit {
    FitSummary fit;
    Pose pose;
    Eigen::MatrixXd information;
    double score = -std::numeric_limits<double>::infinity();
  };
  std::vector<StartFit> fits(starts.size());
  ForEachConcurrently(static_cast<int>(starts.size()), [&](int k) {
    const std::unique_ptr<EMFitter> copy = fitter->Clone();
    begin(copy.get(), starts[k]);
    StartFit& f = fits[k];
    f.fit = copy->DiscardFrame(&f.pose);
    if (!f.fit.ok()) return;
    f.information = copy->frame_information();
    f.score = score(f.pose);
  });
  FitSummary best;
  Pose best_pose;
  Eigen::MatrixXd best_information;
  double best_score = -std::numeric_limits<double>::infinity();
  int iterations = 0;
  double seconds = 0.0;
  for (const StartFit& f : fits) {
    iterations += f.fit.iterations;
    seconds += f.fit.total_seconds;
    if (!f.fit.ok()) continue;
    if (f.score > best_score) {
      best_score = f.score;
      best = f.fit;
      best_pose = f.pose;
      best_information = f.information;
    }
  }
  if (!(best_score > -std::numeric_limits<double>::infinity())) {
    begin(fitter, pose);  // no fit succeeded: the better start's, recorded as it fails
    return fitter->EndFrame();
  }
  fitter->AcceptPose(scan, best_pose, best_information);
  best.iterations = iterations;
  best.total_seconds = seconds;
  return best;
}

}  // namespace artex
