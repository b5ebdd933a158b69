// The per-run files of RunPipeline (docs/experiments.md "Run folder"): frames.csv (one row
// per frame: fit, fit quality, foreground, timings, texture, ground-truth errors),
// summary.json (per frame, the world frame, warnings) and metrics.json (the run's figures).
// Every file is written to a temporary and renamed.
#pragma once

#include <string>

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
// The stream's per-frame record sizes and times (result.stream; docs/streaming.md).
void WriteStreamFramesCsv(const std::string& path, const PipelineResult& result);
void WriteSummaryJson(const std::string& path, const PipelineResult& result,
                      const PipelineOutputInfo& info);
void WriteMetricsJson(const std::string& path, const PipelineResult& result);

}  // namespace artex
