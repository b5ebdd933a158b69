#include "experiments/pipeline_output.h"

#include <cmath>
#include <iomanip>
#include <nlohmann/json.hpp>
#include <sstream>

#include "models/mesh_export.h"

namespace artex {
namespace {

std::string Fixed(double v, int digits = 6) {
  if (!std::isfinite(v)) return "nan";
  std::ostringstream s;
  s << std::setprecision(digits) << v;
  return s.str();
}

nlohmann::json Number(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
}

void WriteJson(const std::string& path, const nlohmann::json& j) {
  WriteFileAtomically(path, j.dump(2) + "\n");
}

nlohmann::json QualityJson(const FitQuality& q) {
  return {{"label", FitQualityLabelName(q.label)},
          {"inlier_fraction", q.inlier_fraction},
          {"support_fraction", q.support_fraction},
          {"depth_residual_m", q.depth_residual_m},
          {"score", q.score}};
}

nlohmann::json StreamJson(const PipelineResult& result) {
  if (!result.has_stream) return nullptr;
  const StreamSummary& s = result.stream;
  return {{"frames", s.frames},
          {"keyframes", s.keyframes},
          {"header_bytes", s.header_bytes},
          {"template_glb_bytes", s.glb_bytes},
          {"rest_shapes", s.shapes},
          {"rest_shape_bytes", s.shape_bytes},
          {"pose_kbit_per_s", s.pose_kbps},
          {"texture_kbit_per_s", s.texture_kbps},
          {"total_kbit_per_s", s.total_kbps},
          {"max_hand_error_mm", s.max_hand_error_mm},
          {"mean_hand_error_mm", s.mean_hand_error_mm},
          {"encode_ms_per_frame", s.mean_encode_ms},
          {"max_encode_ms", s.max_encode_ms},
          {"encode_cpu_ms_per_frame", s.mean_encode_cpu_ms},
          {"compose_ms_per_frame", s.mean_compose_ms},
          {"max_compose_ms", s.max_compose_ms}};
}

}  // namespace

void WriteFramesCsv(const std::string& path, const PipelineResult& result) {
  std::ostringstream frames_csv;
  frames_csv << "frame,skipped,scan_points,subject_pixels,subject_tracked,quality,"
                "inlier_fraction,support_fraction,depth_residual_mm,reinitialised,init_ms,"
                "em_iterations,termination,initial_cost,final_cost,"
                "too_few_points,non_finite,diverged,scale,preprocess_ms,estep_ms,mstep_ms,fit_ms,"
                "texture_ms,texture_mrf_ms,texture_energy,texture_lower_bound,pool_size,"
                "seam_edges,changed_triangles,seam_rms_before,seam_rms_after,"
                "mean_vertex_error_mm,max_vertex_error_mm,mean_joint_error_mm,novel_view_psnr_db,"
                "novel_view_ssim,texture_coverage,silhouette_violations,unobserved_joints,unsupported_parts,"
                "out_of_view_joints,gap_frames,gap_refit,texture_skipped,texture_not_due\n";
  for (const FrameRecord& r : result.frames) {
    frames_csv << r.frame << "," << r.skipped << "," << r.scan_points << ","
               << r.segmentation.subject_pixels << "," << r.segmentation.tracked << ","
               << (r.skipped ? "skipped" : FitQualityLabelName(r.quality.label)) << ","
               << Fixed(r.quality.inlier_fraction) << "," << Fixed(r.quality.support_fraction)
               << "," << Fixed(1000 * r.quality.depth_residual_m) << "," << r.reinitialised << ","
               << Fixed(1000 * r.init_seconds) << "," << r.fit.iterations << ","
               << FrameTerminationName(r.fit.termination) << "," << Fixed(r.fit.initial_cost) << ","
               << Fixed(r.fit.final_cost) << "," << r.fit.too_few_points << "," << r.fit.non_finite
               << "," << r.fit.diverged << "," << Fixed(r.fit.scale) << ","
               << Fixed(1000 * r.preprocess_seconds) << "," << Fixed(1000 * r.fit.estep_seconds)
               << "," << Fixed(1000 * r.fit.mstep_seconds) << ","
               << Fixed(1000 * r.fit.total_seconds) << "," << Fixed(1000 * r.texture.seconds_total)
               << "," << Fixed(1000 * r.texture.seconds_mrf) << "," << Fixed(r.texture.energy)
               << "," << Fixed(r.texture.lower_bound) << "," << r.texture.pool_size << ","
               << r.texture.seam_edges << "," << r.texture.changed_triangles << ","
               << Fixed(r.texture.seam_rms_before) << "," << Fixed(r.texture.seam_rms_after) << ","
               << Fixed(r.mean_vertex_error_mm) << "," << Fixed(r.max_vertex_error_mm) << ","
               << Fixed(r.mean_joint_error_mm) << ","
               << (r.texture_quality.views ? Fixed(r.texture_quality.psnr_db) : "nan") << ","
               << (r.texture_quality.views ? Fixed(r.texture_quality.ssim) : "nan") << ","
               << (r.texture_quality.views ? Fixed(r.texture_quality.coverage) : "nan") << ","
               << (r.fit.trace.empty() ? 0 : r.fit.trace.back().silhouette_violations) << ","
               << (r.fit.trace.empty() ? 0 : r.fit.trace.back().unobserved_joints) << ","
               << r.quality.unsupported_parts << "," << r.fit.out_of_view_joints << ","
               << r.gap_frames << "," << r.gap_refit << "," << r.texture_skipped << ","
               << r.texture_not_due << "\n";
  }
  WriteFileAtomically(path, frames_csv.str());
}

void WriteJointErrorsCsv(const std::string& path, const PipelineResult& result,
                         const std::vector<std::string>& joint_names) {
  std::ostringstream csv;
  csv << "frame";
  for (const std::string& name : joint_names) csv << "," << name;
  csv << "\n";
  for (const FrameRecord& r : result.frames) {
    if (r.joint_errors_mm.size() != joint_names.size()) continue;  // not evaluated
    csv << r.frame;
    for (double e : r.joint_errors_mm) csv << "," << Fixed(e);
    csv << "\n";
  }
  WriteFileAtomically(path, csv.str());
}

void WriteStreamFramesCsv(const std::string& path, const PipelineResult& result) {
  std::ostringstream csv;
  csv << "frame,keyframe,pose_bytes,coverage_bytes,video_bytes,record_bytes,compose_ms,"
         "encode_ms,encode_cpu_ms,hand_error_mm,shape_bytes\n";
  for (const StreamFrameStats& s : result.stream.per_frame) {
    csv << s.frame << "," << s.keyframe << "," << s.pose_bytes << "," << s.mask_bytes << ","
        << s.video_bytes << "," << s.record_bytes << "," << Fixed(s.compose_ms) << ","
        << Fixed(s.pose_ms + s.video_ms) << "," << Fixed(s.video_cpu_ms) << ","
        << Fixed(s.hand_error_mm) << "," << s.shape_bytes << "\n";
  }
  WriteFileAtomically(path, csv.str());
}

void WriteSummaryJson(const std::string& path, const PipelineResult& result,
                      const PipelineOutputInfo& info) {
  nlohmann::json summary_frames = nlohmann::json::array();
  for (const FrameRecord& r : result.frames) {
    nlohmann::json f;
    f["frame"] = r.frame;
    f["skipped"] = r.skipped;
    f["fit"] = {{"iterations", r.fit.iterations},
                {"termination", FrameTerminationName(r.fit.termination)},
                {"initial_cost", r.fit.initial_cost},
                {"final_cost", r.fit.final_cost},
                {"flags",
                 {{"too_few_points", r.fit.too_few_points},
                  {"non_finite", r.fit.non_finite},
                  {"diverged", r.fit.diverged}}},
                {"seconds",
                 {{"preprocess", r.preprocess_seconds},
                  {"icp", r.fit.icp_seconds},
                  {"estep", r.fit.estep_seconds},
                  {"mstep", r.fit.mstep_seconds},
                  {"total", r.fit.total_seconds}}}};
    if (info.texture) {
      f["texture"] = {{"energy", r.texture.energy},
                      {"lower_bound", std::isfinite(r.texture.lower_bound)
                                          ? nlohmann::json(r.texture.lower_bound)
                                          : nlohmann::json(nullptr)},
                      {"mrf_iterations", r.texture.mrf_iterations},
                      {"pool_size", r.texture.pool_size},
                      {"pool_bytes", r.texture.pool_bytes},
                      {"seam_edges", r.texture.seam_edges},
                      {"changed_triangles", r.texture.changed_triangles},
                      {"seconds",
                       {{"pool", r.texture.seconds_pool},
                        {"mrf", r.texture.seconds_mrf},
                        {"sampling", r.texture.seconds_sampling},
                        {"levelling", r.texture.seconds_levelling},
                        {"total", r.texture.seconds_total}}}};
    }
    if (!r.skipped) {
      f["quality"] = QualityJson(r.quality);
      f["reinitialised"] = r.reinitialised;
      if (r.reinitialised) f["initialisation"] = r.init_report;
      f["foreground"] = {{"subject_pixels", r.segmentation.subject_pixels},
                         {"person_sized_components", r.segmentation.person_sized},
                         {"people_splits", r.segmentation.people_splits},
                         {"tracked", r.segmentation.tracked}};
    }
    summary_frames.push_back(f);
  }
  nlohmann::json world_json = {{"source", "calibration"}};
  if (info.world) {
    const WorldFrameEstimate& e = *info.world;
    nlohmann::json planes = nlohmann::json::array();
    for (const ScenePlane& p : e.planes) {
      planes.push_back({{"kind", PlaneKindName(p.kind)},
                        {"normal", {p.normal.x(), p.normal.y(), p.normal.z()}},
                        {"offset", p.offset},
                        {"inlier_fraction", p.inlier_fraction},
                        {"extent", {p.extent[0], p.extent[1]}},
                        {"coverage", p.coverage}});
    }
    world_json = {{"source", WorldFrameSourceName(e.source)},
                  {"up_camera", {e.up_camera.x(), e.up_camera.y(), e.up_camera.z()}},
                  {"camera_height", e.camera_height},
                  {"camera_pitch_deg", e.camera_pitch_deg},
                  {"camera_roll_deg", e.camera_roll_deg},
                  {"planes", planes}};
  }
  nlohmann::json glb = nullptr;
  if (result.glb_written) {
    const AnimatedGlbSummary& g = result.glb;
    glb = {{"frames", g.frames},
           {"exact", g.morph_targets > 0},
           {"morph_targets", g.morph_targets},
           {"lbs_max_residual_mm", g.lbs_max_residual_mm},
           {"lbs_mean_residual_mm", g.lbs_mean_residual_mm},
           {"max_residual_mm", g.exact_max_residual_mm},
           {"mean_residual_mm", g.exact_mean_residual_mm},
           {"singular_vertices", g.singular_vertices},
           {"bytes", g.bytes}};
  }
  WriteJson(path, {{"sequence", info.sequence},
                   {"world_frame", world_json},
                   {"template", info.template_name},
                   {"quality",
                    {{"good", result.good_frames},
                     {"doubtful", result.doubtful_frames},
                     {"lost", result.lost_frames},
                     {"failed", result.failed_frames},
                     {"initialisations", result.initialisations}}},
                   {"frames", summary_frames},
                   {"tracked_glb", glb},
                   {"warnings", result.warnings}});
}

void WriteMetricsJson(const std::string& path, const PipelineResult& result) {
  WriteJson(path, {{"frames", static_cast<int>(result.frames.size())},
                   {"skipped_frames", result.skipped_frames},
                   {"good_frames", result.good_frames},
                   {"doubtful_frames", result.doubtful_frames},
                   {"lost_frames", result.lost_frames},
                   {"failed_frames", result.failed_frames},
                   {"initialisations", result.initialisations},
                   {"gap_refits", result.gap_refits},
                   {"has_ground_truth", result.has_ground_truth},
                   {"evaluated_frames", result.evaluated_frames},
                   {"mean_vertex_error_mm", Number(result.mean_vertex_error_mm)},
                   {"max_vertex_error_mm", Number(result.max_vertex_error_mm)},
                   {"mean_joint_error_mm", Number(result.mean_joint_error_mm)},
                   {"lost_fraction", Number(result.lost_fraction)},
                   {"mean_em_iterations", result.mean_em_iterations},
                   {"fit_ms_per_frame", result.fit_ms_per_frame},
                   {"init_ms_per_initialisation", result.init_ms_per_initialisation},
                   {"quality_ms_per_frame", result.quality_ms_per_frame},
                   {"texture_ms_per_frame", result.texture_ms_per_frame},
                   {"stream_kbit_per_s", result.stream_kbit_per_s},
                   {"novel_view_psnr_db", Number(result.novel_view_psnr_db)},
                   {"novel_view_ssim", Number(result.novel_view_ssim)},
                   {"texture_coverage", Number(result.texture_coverage)},
                   {"mean_novel_view_psnr_db", Number(result.mean_novel_view_psnr_db)},
                   {"mean_novel_view_ssim", Number(result.mean_novel_view_ssim)},
                   {"stream", StreamJson(result)}});
}

}  // namespace artex
