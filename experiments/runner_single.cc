// One run of an experiment (the `experiment-run` child process, experiments/runner.h): the
// pipeline on one sequence with one configuration, then results.json (the metrics of
// Metrics()), trace.csv (per frame) and em_trace.csv (per EM iteration).
#include <tbb/global_control.h>

#include <cmath>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "experiments/config.h"
#include "experiments/pipeline.h"
#include "experiments/runner.h"
#include "experiments/runner_internal.h"
#include "sensors/sequence.h"

namespace artex {
namespace fs = std::filesystem;

using runner_internal::FormatNumber;
using runner_internal::Mean;

void RunSingle(const std::string& config_path, const std::string& sequence_dir,
               const std::string& template_path, const std::string& out_dir, int threads,
               const std::function<void(int, int)>& progress) {
  std::unique_ptr<tbb::global_control> limit;
  if (threads > 0) {
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                  static_cast<std::size_t>(threads));
    cv::setNumThreads(threads);
  }
  // Two instances: reading options touches the YAML nodes, the pipeline writes the other one.
  const PipelineOptions options = LoadPipelineOptions(Config::Load(config_path));
  const Config config = Config::Load(config_path);
  const PipelineResult result = RunPipeline(sequence_dir, template_path, options, config, out_dir,
                                            [&](const PipelineProgress& p) {
                                              if (progress) progress(p.done, p.total);
                                            });

  // Per-frame trace and metrics.
  std::ostringstream trace, em;
  trace << "frame,skipped,ok,termination,em_iterations,scan_points,vertex_error_mm,"
           "max_vertex_error_mm,joint_error_mm,lost,scale,preprocess_ms,icp_ms,estep_ms,mstep_ms,"
           "fit_ms,texture_pool_ms,texture_mrf_ms,texture_sampling_ms,texture_levelling_ms,"
           "texture_ms,mrf_energy,pool_size,seam_edges,changed_triangles,textured_triangles,"
           "seam_rms_before,seam_rms_after,mrf_iterations\n";
  em << "frame,iteration,stage,radius,cost,max_update,total_weight,num_pairs,scale,converged\n";
  int fitted = 0, lost = 0, failed = 0, converged = 0;
  std::vector<double> iterations, errors, seam_before, seam_after, changed, pool, pre, estep,
      mstep, fit, tex, mrf, lev, mrf_iterations;
  const FrameRecord* last_textured = nullptr;
  const FrameRecord* last_evaluated = nullptr;  // fitted, not failed
  for (const FrameRecord& r : result.frames) {
    // A failed fit is lost whatever its kept pose shows, and no measurement for the errors.
    const bool is_lost = result.has_ground_truth && !r.skipped &&
                         (!r.fit.ok() || !(r.mean_vertex_error_mm <= options.lost_threshold_mm));
    trace << r.frame << "," << (r.skipped ? 1 : 0) << "," << (r.fit.ok() ? 1 : 0) << ","
          << FrameTerminationName(r.fit.termination) << "," << r.fit.iterations << ","
          << r.scan_points << "," << FormatNumber(r.mean_vertex_error_mm) << ","
          << FormatNumber(r.max_vertex_error_mm) << "," << FormatNumber(r.mean_joint_error_mm)
          << "," << (is_lost ? 1 : 0) << "," << FormatNumber(r.fit.scale) << ","
          << FormatNumber(1e3 * r.preprocess_seconds) << "," << FormatNumber(1e3 * r.fit.icp_seconds)
          << "," << FormatNumber(1e3 * r.fit.estep_seconds) << ","
          << FormatNumber(1e3 * r.fit.mstep_seconds) << "," << FormatNumber(1e3 * r.fit.total_seconds)
          << "," << FormatNumber(1e3 * r.texture.seconds_pool) << ","
          << FormatNumber(1e3 * r.texture.seconds_mrf) << ","
          << FormatNumber(1e3 * r.texture.seconds_sampling) << ","
          << FormatNumber(1e3 * r.texture.seconds_levelling) << ","
          << FormatNumber(1e3 * r.texture.seconds_total) << "," << FormatNumber(r.texture.energy)
          << "," << r.texture.pool_size << "," << r.texture.seam_edges << ","
          << r.texture.changed_triangles << "," << r.texture.textured_triangles << ","
          << FormatNumber(r.texture.seam_rms_before) << "," << FormatNumber(r.texture.seam_rms_after)
          << "," << r.texture.mrf_iterations << "\n";
    for (const EMIterationInfo& it : r.fit.trace) {
      em << r.frame << "," << it.iteration << "," << it.stage << "," << FormatNumber(it.radius)
         << "," << FormatNumber(it.cost) << "," << FormatNumber(it.max_update) << ","
         << FormatNumber(it.total_weight) << "," << it.num_pairs << "," << FormatNumber(it.scale)
         << "," << (it.converged ? 1 : 0) << "\n";
    }
    if (r.skipped) continue;
    ++fitted;
    if (is_lost) ++lost;
    if (!r.fit.ok()) ++failed;
    if (r.fit.termination == FrameTermination::kConverged) ++converged;
    iterations.push_back(r.fit.iterations);
    if (result.has_ground_truth && r.fit.ok()) {
      errors.push_back(r.mean_vertex_error_mm);
      last_evaluated = &r;
    }
    pre.push_back(1e3 * r.preprocess_seconds);
    estep.push_back(1e3 * r.fit.estep_seconds);
    mstep.push_back(1e3 * r.fit.mstep_seconds);
    fit.push_back(1e3 * r.fit.total_seconds);
    if (options.texture) {
      tex.push_back(1e3 * r.texture.seconds_total);
      mrf.push_back(1e3 * r.texture.seconds_mrf);
      lev.push_back(1e3 * r.texture.seconds_levelling);
      changed.push_back(r.texture.changed_triangles);
      mrf_iterations.push_back(r.texture.mrf_iterations);
      pool.push_back(r.texture.pool_size);
      // Frames whose seams were levelled (texture.levelling_every_frame false: those whose
      // texture was read; the others' residuals are NaN).
      if (r.texture.seam_edges > 0 && std::isfinite(r.texture.seam_rms_after)) {
        seam_before.push_back(r.texture.seam_rms_before);
        seam_after.push_back(r.texture.seam_rms_after);
      }
      last_textured = &r;
    }
  }
  nlohmann::ordered_json m;
  auto put = [&](const char* name, double value) {
    if (std::isfinite(value)) m[name] = value;
  };
  if (result.has_ground_truth && fitted > 0) {
    put("mean_vertex_error_mm", result.mean_vertex_error_mm);
    put("max_vertex_error_mm", result.max_vertex_error_mm);
    put("mean_joint_error_mm", result.mean_joint_error_mm);
    if (last_evaluated) put("final_vertex_error_mm", last_evaluated->mean_vertex_error_mm);
    put("evaluated_frames", result.evaluated_frames);
    put("lost_frames", lost);
    put("lost_fraction", static_cast<double>(lost) / fitted);
  }
  put("failed_frames", failed);
  put("skipped_frames", result.skipped_frames);
  if (fitted > 0) {
    put("mean_em_iterations", Mean(iterations));
    put("converged_fraction", static_cast<double>(converged) / fitted);
  }
  if (last_textured) {
    put("seam_rms_before", Mean(seam_before));
    put("seam_rms_after", Mean(seam_after));
    put("seam_edges", last_textured->texture.seam_edges);
    put("changed_triangles", Mean(changed));
    put("textured_triangles", last_textured->texture.textured_triangles);
    put("mrf_energy", last_textured->texture.energy);
    put("mrf_iterations", Mean(mrf_iterations));
    put("pool_size", Mean(pool));
    put("stream_kbit_per_s", result.stream_kbit_per_s);
    put("novel_view_psnr_db", result.novel_view_psnr_db);
    put("novel_view_ssim", result.novel_view_ssim);
    put("texture_coverage", result.texture_coverage);
    put("mean_novel_view_psnr_db", result.mean_novel_view_psnr_db);
  }
  if (fitted > 0) {
    put("preprocess_ms", Mean(pre));
    put("estep_ms", Mean(estep));
    put("mstep_ms", Mean(mstep));
    put("fit_ms", Mean(fit));
    if (!tex.empty()) {
      put("texture_ms", Mean(tex));
      put("texture_mrf_ms", Mean(mrf));
      put("texture_levelling_ms", Mean(lev));
    }
    put("frame_ms", Mean(pre) + Mean(fit) + (tex.empty() ? 0.0 : Mean(tex)));
  }
  nlohmann::ordered_json doc;
  doc["metrics"] = m;
  doc["frames"] = static_cast<int>(result.frames.size());
  doc["fitted_frames"] = fitted;
  doc["has_ground_truth"] = result.has_ground_truth;
  doc["warnings"] = result.warnings;
  const fs::path out(out_dir);
  WriteFileAtomic((out / "trace.csv").string(), trace.str());
  WriteFileAtomic((out / "em_trace.csv").string(), em.str());
  WriteFileAtomic((out / "results.json").string(), doc.dump(2) + "\n");
}

}  // namespace artex
