#include "experiments/shape_output.h"

#include <cmath>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <sstream>
#include <vector>

#include "models/error.h"
#include "models/mesh_export.h"

namespace artex {

namespace {
double Finite(double x) { return std::isfinite(x) ? x : std::numeric_limits<double>::quiet_NaN(); }

std::string JoinNames(const std::vector<std::string>& names) {
  std::string out;
  for (const std::string& n : names) out += (out.empty() ? "" : ", ") + n;
  return out;
}
}  // namespace

void AddShapeWarnings(const ShapeEstimator& shape, std::vector<std::string>* warnings) {
  const std::vector<std::string>& unseen = shape.unseen_parameters();
  if (!unseen.empty()) {
    warnings->push_back(std::string(kShapeWarningPrefix) + std::to_string(unseen.size()) +
                        " parameters held (their parts were out of the depth image in every "
                        "calibration frame; shape.hold_unseen): " + JoinNames(unseen) +
                        "; the subject template keeps the template's proportions there");
  }
  if (shape.floor_contradicted()) {
    warnings->push_back(std::string(kShapeWarningPrefix) +
                        "the floor found in the first frame lies above the subject's scan in a "
                        "calibration solve, which left the floor term out there "
                        "(shape.floor_weight; summary.json shape.floor)");
  }
  const std::vector<std::string> bounded = shape.ParametersAtBounds();
  if (!bounded.empty()) {
    warnings->push_back(std::string(kShapeWarningPrefix) + std::to_string(bounded.size()) +
                        " parameters at their bounds (shape.bone_min/bone_max, "
                        "girth_min/girth_max): " + JoinNames(bounded) +
                        "; the solve would have moved them further: check that the recording "
                        "shows those parts");
  }
}

void AddShapeToSummary(const std::string& summary_path, const PipelineResult& result,
                       const ShapeRunInfo& info) {
  nlohmann::json summary;
  {
    std::ifstream in(summary_path);
    if (!in) throw Error(summary_path + ": cannot read the run summary");
    try {
      in >> summary;
    } catch (const std::exception& e) {
      throw Error(summary_path + ": not valid JSON: " + e.what());
    }
  }
  const ShapeEstimator& est = *info.estimator;
  const Template& subject = *info.subject;
  nlohmann::json shape;
  shape["mode"] = ShapeModeName(est.options().mode);
  shape["calibrated"] = est.calibrated();
  shape["calibrated_after_frame"] = info.calibrated_frame;
  shape["global_scale"] = info.global_scale;
  nlohmann::json params = nlohmann::json::object();
  for (int p = 0; p < est.model().num_parameters(); ++p) {
    params[est.model().parameter_names()[p]] = 1.0 + est.parameters()[p];
  }
  shape["parameters"] = params;
  shape["parameters_held_unseen"] = est.unseen_parameters();
  shape["parameters_at_bounds"] = est.ParametersAtBounds();
  const BodyShape body = est.shape();
  nlohmann::json joints = nlohmann::json::array();
  double bone_sum = 0.0, bone_max = 0.0;
  int bones = 0;
  for (int j = 0; j < subject.num_joints(); ++j) {
    nlohmann::json jj;
    jj["name"] = subject.joints[j].name;
    jj["girth"] = body.girth[j];
    if (est.options().leaf_lengths && body.leaf_length[j] != 1.0) {
      jj["leaf_length_factor"] = body.leaf_length[j];
    }
    if (est.options().fork_widths && body.fork_width[j] != 1.0) {
      jj["width_factor"] = body.fork_width[j];
    }
    if (est.options().girth_depth && est.options().mode == ShapeMode::kBonesGirth) {
      jj["depth_factor"] = body.girth[j] + body.depth[j] - 1.0;  // of the cross-section's depth
    }
    if (j > 0) {
      const int p = subject.joints[j].parent;
      const double length =
          info.global_scale * (subject.joints[j].center - subject.joints[p].center).norm();
      jj["bone_length_factor"] = body.bone_length[j];
      jj["bone_length_m"] = length;
      if (info.truth) {
        const int tj = info.truth->FindJoint(subject.joints[j].name);
        const int tp = info.truth->FindJoint(subject.joints[p].name);
        if (tj >= 0 && tp >= 0) {
          const double truth =
              (info.truth->joints[tj].center - info.truth->joints[tp].center).norm();
          const double error = 1000.0 * std::abs(length - truth);
          jj["bone_length_truth_m"] = truth;
          jj["bone_length_error_mm"] = error;
          bone_sum += error;
          bone_max = std::max(bone_max, error);
          ++bones;
        }
      }
    }
    joints.push_back(jj);
  }
  shape["joints"] = joints;
  if (bones > 0) {
    shape["mean_bone_length_error_mm"] = bone_sum / bones;
    shape["max_bone_length_error_mm"] = bone_max;
  }
  const ShapeSolveSummary& c = est.calibration_summary();
  shape["calibration"] = {{"frames", c.frames},
                          {"iterations", c.iterations},
                          {"initial_cost", c.initial_cost},
                          {"final_cost", c.final_cost},
                          {"seconds", c.seconds}};
  if (est.options().detail.enabled) {
    const ShapeDetailSummary& d = est.detail_summary();
    shape["detail"] = {{"estimated", est.detail().size() > 0},
                       {"after_frame", info.detail_frame},
                       {"frames", d.frames},
                       {"iterations", d.iterations},
                       {"observed_vertices", d.observed_vertices},
                       {"observations", d.observations},
                       {"residual_before_mm", 1e3 * d.residual_before},
                       {"residual_after_mm", 1e3 * d.residual_after},
                       {"frame_mean_residual_mm", 1e3 * d.frame_mean_residual},
                       {"mean_offset_mm", 1e3 * d.mean_offset},
                       {"rms_offset_mm", 1e3 * d.rms_offset},
                       {"max_offset_mm", 1e3 * d.max_offset},
                       {"vertices_at_bound", d.at_bound},
                       {"seconds", d.seconds}};
    // Per segment (the vertices of each joint): mean and rms offset (mm, + outwards).
    const Eigen::VectorXd& offsets = est.detail();
    if (offsets.size() == subject.num_vertices()) {
      const int nj = subject.num_joints();
      std::vector<double> sum(nj, 0.0), sum2(nj, 0.0);
      std::vector<int> count(nj, 0);
      for (int v = 0; v < subject.num_vertices(); ++v) {
        const int j = subject.vertex_joint[v];
        sum[j] += offsets[v];
        sum2[j] += offsets[v] * offsets[v];
        ++count[j];
      }
      nlohmann::json by_joint = nlohmann::json::object();
      for (int j = 0; j < nj; ++j) {
        if (count[j] == 0) continue;
        by_joint[subject.joints[j].name] = {{"mean_mm", 1e3 * sum[j] / count[j]},
                                            {"rms_mm", 1e3 * std::sqrt(sum2[j] / count[j])}};
      }
      shape["detail"]["segments"] = by_joint;
    }
  }
  // The floor plane of the floor term (shape.floor_weight; null: none found or off).
  shape["floor"] = nullptr;
  if (est.has_floor()) {
    const Eigen::Vector3d& n = est.floor_normal();
    shape["floor"] = {{"normal", {n.x(), n.y(), n.z()}},
                      {"offset", est.floor_offset()},
                      {"contradicted", est.floor_contradicted()}};
  }
  shape["refinements"] = est.refinements();
  shape["refine_seconds"] = est.refine_seconds();
  shape["rounds"] = est.rounds_done();
  shape["final_calibration_after_frame"] = info.final_frame;
  if (result.has_ground_truth) {
    // Mean errors over the evaluated frames after `after` (-1: all; `never`: none, NaN).
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const auto add_window = [&](int after, bool never, const std::string& suffix) {
      double vertex = 0.0, joint = 0.0;
      int n = 0;
      for (const FrameRecord& r : result.frames) {
        if (never || r.skipped || !r.fit.ok() || r.frame <= after) continue;
        if (!std::isfinite(r.mean_vertex_error_mm)) continue;
        vertex += r.mean_vertex_error_mm;
        joint += r.mean_joint_error_mm;
        ++n;
      }
      // Per joint (by name): where the mean joint error comes from.
      nlohmann::json by_joint = nlohmann::json::object();
      for (int j = 0; j < subject.num_joints(); ++j) {
        double sum = 0.0;
        int m = 0;
        for (const FrameRecord& r : result.frames) {
          if (never || r.skipped || !r.fit.ok() || r.frame <= after) continue;
          if (!std::isfinite(r.mean_vertex_error_mm) || j >= int(r.joint_errors_mm.size())) continue;
          if (!std::isfinite(r.joint_errors_mm[j])) continue;
          sum += r.joint_errors_mm[j];
          ++m;
        }
        if (m > 0) by_joint[subject.joints[j].name] = sum / m;
      }
      shape["joint_errors_mm_after_" + suffix] = by_joint;
      shape["frames_after_" + suffix] = n;
      shape["mean_vertex_error_mm_after_" + suffix] = n ? Finite(vertex / n) : nan;
      shape["mean_joint_error_mm_after_" + suffix] = n ? Finite(joint / n) : nan;
    };
    // From the first round's swap (the calibration phase still running; all frames when it
    // never swapped, as before) ...
    add_window(info.calibrated_frame, false, "calibration");
    // ... and from the last round's swap (the calibration phase complete; fixed: all frames).
    add_window(info.final_frame, est.enabled() && info.final_frame < 0, "final_calibration");
    // ... and from the surface detail's swap.
    if (est.options().detail.enabled) {
      add_window(info.detail_frame, info.detail_frame < 0, "detail");
    }
  }
  summary["shape"] = shape;
  WriteFileAtomically(summary_path, summary.dump(2) + "\n");
}

}  // namespace artex
