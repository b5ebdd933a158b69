// Outputs of the subject shape estimation of a run (solvers/shape_estimator.h, section shape):
// the subject template subject.glb (same rig, skinning constants and UVs as the tracking
// template, rest geometry of the estimated shape; the tracked poses' global scale s0 is not
// baked in) and a "shape" object added to summary.json.
#pragma once

#include <string>
#include <vector>

#include "experiments/pipeline.h"
#include "models/template.h"
#include "models/template_io.h"
#include "solvers/shape_estimator.h"

namespace artex {

struct ShapeRunInfo {
  const ShapeEstimator* estimator = nullptr;
  const Template* subject = nullptr;  // the template tracking ended with
  double global_scale = 1.0;          // s0 of the last tracked pose
  int calibrated_frame = -1;          // sequence frame after which the shape was swapped in
  int final_frame = -1;               // ... after the last calibration round (phase complete)
  int detail_frame = -1;              // ... with the surface detail (shape.detail; -1: none)
  const Template* truth = nullptr;    // ground-truth subject (bone length errors), optional
};

// Adds "shape" to the summary.json at `summary_path` (rewritten atomically): mode, parameter
// names and values, per-joint bone length and girth factors, the subject's bone lengths (m,
// times s0), the calibration solve (frames, iterations, cost, seconds), refinements, and with
// ground truth the bone length errors (mm) and the mean vertex / joint errors (mm) over the
// evaluated frames after the first calibration round's swap (*_after_calibration) and after the
// last round's (*_after_final_calibration: the calibration phase complete). Throws artex::Error naming the file on I/O failure.
void AddShapeToSummary(const std::string& summary_path, const PipelineResult& result,
                       const ShapeRunInfo& info);

// The start of every warning AddShapeWarnings adds.
inline constexpr char kShapeWarningPrefix[] = "shape: ";
// Appends the doubts about a calibrated shape to `warnings`: parameters held because their
// parts were out of view in every calibration frame (ShapeOptions::hold_unseen), parameters at
// a bound (the solve would have moved them further).
void AddShapeWarnings(const ShapeEstimator& shape, std::vector<std::string>* warnings);

}  // namespace artex
