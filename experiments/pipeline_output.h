// The per-run files of RunPipeline (docs/experiments.md "Run folder"): frames.csv (one row
// per frame: fit, fit quality, foreground, timings, texture, ground-truth errors),
// summary.json (per frame, the world frame, warnings) and metrics.json (the run's figures).
// Every file is written to a temporary and renamed.
#pragma once

#include <string>
#include <vector>

#include "experiments/pipeline.h"
#include "sensors/scene_segmentation.h"

namespace artex {

struct PipelineOutputInfo {
  std::string sequence;
  std::string template_name;
  bool texture = true;
  const WorldFrameEstimate* world = nullptr;  // null: the calibration's world frame
};

void WriteFramesCsv(const std::string& path, const PipelineResult& result);
// With ground truth: one row per evaluated frame, each joint's distance from the subject's true
// joint centre (mm, named by `joint_names`, the tracking template's; nan for a joint the
// subject lacks). frames.csv's mean_joint_error_mm is the mean of a row's numbers.
void WriteJointErrorsCsv(const std::string& path, const PipelineResult& result,
                         const std::vector<std::string>& joint_names);
// The stream's per-frame record sizes and times (result.stream; docs/streaming.md).
void WriteStreamFramesCsv(const std::string& path, const PipelineResult& result);
void WriteSummaryJson(const std::string& path, const PipelineResult& result,
                      const PipelineOutputInfo& info);
void WriteMetricsJson(const std::string& path, const PipelineResult& result);

}  // namespace artex
