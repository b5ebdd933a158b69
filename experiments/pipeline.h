// The per-sequence pipeline behind `artex track` and the experiment runner: preprocess every
// frame, fit the template (EM), texture it on the fly, and write the results of a run into
// one folder (poses, per-frame summaries, texture, metrics against ground truth, exports).
#pragma once

#include <functional>
#include <map>
#include <limits>
#include <string>
#include <vector>

#include "experiments/config.h"
#include "experiments/realtime_options.h"
#include "models/template_cache.h"
#include "models/template_io.h"
#include "models/textured_mesh_export.h"
#include "sensors/frame_source.h"
#include "sensors/preprocess.h"
#include "solvers/em_fitter.h"
#include "solvers/fit_quality.h"
#include "solvers/initializer.h"
#include "solvers/shape_estimator.h"
#include "stream/stream_sender.h"
#include "texture/texture_quality.h"
#include "texture/texturer.h"

namespace artex {

// Which tracked frames are fitted again by the multi-hypothesis initialisation in the same frame
// (the better of both by quality score is kept): kLost, frames the tracking loses (always at
// least these); kDoubtful, also every frame it doubts (costs an initialisation per doubtful
// frame); kAuto, lost ones, a doubtful one that follows a good one (the quality dropped), and
// every doubtful one while in-place re-initialisations keep beating tracking
// (PipelineOptions::reinitialise_auto_*): a recording whose frames tracking cannot follow from
// one to the next (stills of different poses, cuts, a very low frame rate).
enum class ReinitialiseOn { kLost, kDoubtful, kAuto };
const std::map<std::string, ReinitialiseOn>& ReinitialiseOnNames();  // lost, doubtful, auto

struct PipelineOptions {
  FrameSourceOptions input;  // how recordings are read (TUM association, intrinsics)
  PreprocessOptions preprocess;
  EMFitterOptions fitting;
  InitializerOptions initializer;  // fitting.init: multi-hypothesis first frame / re-init
  FitQualityOptions quality;       // fitting.quality: per-frame labels (also initializer.quality)
  TexturingOptions texturing;
  bool texture = true;            // on-the-fly texturing on/off
  bool colour_term = true;        // feed the texture's colours back into the E-step
  int first_frame = 0;            // first frame index of the sequence to process
  int max_frames = 0;             // 0: all frames
  bool export_meshes = false;     // posed meshes per frame (meshes/NNNNNN.ply)
  bool export_foreground = false;  // foreground masks per frame (foreground/NNNNNN.png)
  // The default template (no template file given) from the cache this build wrote
  // (models/template_cache.h; pipeline.template_cache, template_cache_dir, template_cache_keep).
  TemplateCacheOptions template_cache;
  bool export_glb = true;         // animated, textured tracked.glb at the end
  // tracked.glb reproduces artex's LBS+SLERP fitted geometry in any glTF viewer (one corrective
  // morph target per frame, models/template_io.h AnimatedGlbOptions); false: glTF's plain LBS
  // only (differs by up to several cm at blended joints), a smaller file.
  bool glb_exact = true;
  // Longer runs get the plain LBS glb (with a warning): the correctives cost 12 bytes per glTF
  // vertex and frame (~160 KB per frame on the default template). 0: no limit.
  int glb_exact_max_frames = 600;
  bool export_bvh = true;  // tracked.bvh: the fitted motion as BVH (sensors/bvh_export.h), cm
  // tracked.obj (+ tracked.mtl) and tracked.ply: the last fitted frame with UVs and texture.png
  bool export_textured_mesh = true;
  // Up axis of the exported PLY/OBJ meshes (tracked.*, meshes/): y (artex) or z (Blender: the
  // mesh stands upright after a plain import).
  UpAxis mesh_up_axis = UpAxis::kY;
  std::vector<int> atlas_frames;  // also write the atlas after these frames
  double lost_threshold_mm = 50.0;  // a frame is lost when its mean vertex error exceeds this
  // Texture doubtful frames too (lost frames never are).
  bool texture_doubtful_frames = true;
  // A frame is textured only when it comes this many frames or more after the last textured
  // one (by the recording's frame numbers; 1: every good or doubtful frame). The others pass
  // with their pose and the texture as it stands: the atlas of a 30 Hz recording changes
  // little from one frame to the next (docs/realtime.md, "Texturing every n-th frame").
  int texture_every = 1;
  ReinitialiseOn reinitialise_on = ReinitialiseOn::kAuto;
  // kAuto: every doubtful frame is re-initialised too while a re-initialisation replaced the
  // tracked fit in at least `wins` of the last `window` tracked frames. In a recording that
  // tracking follows, re-initialisations seldom replace it (the tracked fit scores higher); in
  // stills (skeltrack) they replace it in most frames.
  int reinitialise_auto_wins = 1;
  int reinitialise_auto_window = 5;
  // After this many consecutive doubtful frames the next doubtful one is initialised again in
  // place too (the better fit kept): a wrong facing chosen at the start, which tracking keeps
  // doubtful but never loses, is corrected. 0: never.
  int reinitialise_after_doubtful = 10;
  // A tracking frame this many frames or more after the last processed one (frames dropped in
  // live mode, e.g. during the first frame's initialisation) is fitted by RefitFromPose
  // (solvers/initializer.h): the last pose or it moved onto the scan, fitted with wider radii.
  // 0: tracked as any frame (the prediction from before the gap).
  int gap_refit_frames = 3;
  // Its options: radii, iterations_per_stage and leg_stride_deg from pipeline.gap_refit_radii,
  // .gap_refit_iterations_per_stage and .gap_refit_leg_stride_deg, coarse_iterations and
  // quality from fitting.init and fitting.quality (LoadPipelineOptions).
  // shape.joint_limits: joint limits added to the pose priors of the shape solve only (not to
  // tracking), in fitting.joint_limits' form; weight 0 (default): none.
  JointLimitOptions shape_joint_limits;
  GapRefitOptions gap_refit;
  // pipeline.gap_refit_stride_frames: the refit's starts with the legs in stride
  // (gap_refit.leg_stride_deg) only after a gap of at least this many frames (a third of a
  // second at 30 Hz: shorter gaps rarely change which leg is ahead, and the two more fits
  // would widen the next gap).
  int gap_refit_stride_frames = 10;
  // With ground truth: novel-view texture quality (texture/texture_quality.h) every n-th frame
  // and at the last frame; 0: off.
  int texture_quality_every = 10;
  HeldOutViewOptions held_out;  // pipeline.texture_quality_yaws_deg, _height
  // Write the atlas after every fitted frame (atlases/NNNNNN.png, and the textured triangles
  // as atlases/NNNNNN_textured.png, one row): the input of `artex stream encode RUN/`.
  bool export_atlases = false;
  std::string stream_path;  // also write the tele-presence stream here (.artx; "" none)
  // The earlier bandwidth estimate stream_kbit_per_s (raw pose + a JPEG of the atlas box that
  // changed, encoded every frame in the texture stage: ~10 ms of CPU per frame); off: NaN.
  bool stream_estimate = false;
  StreamOptions stream;     // section stream
  // Sequential or pipelined stages, live replay (pipeline.concurrency, .queue_depth, .live,
  // .live_rate_hz, .colour_delay_frames; experiments/realtime_options.h).
  RealtimeOptions realtime;
  ShapeOptions shape;       // section shape: subject shape estimation (mode fixed: none)

  bool IsValid(std::string* error) const;
};

// Reads the sections input, preprocess, fitting, texture and pipeline of a configuration; unknown
// keys are errors listing the valid ones.
PipelineOptions LoadPipelineOptions(const Config& config);

struct FrameRecord {
  int frame = 0;
  bool skipped = false;          // unreadable input frame (counted, not fitted)
  FitSummary fit;
  FitQuality quality;            // without ground truth; failed fits are kLost
  bool reinitialised = false;    // fitted by the multi-hypothesis initialisation
  int gap_frames = 0;            // frames not processed since the previous processed one
  bool gap_refit = false;        // fitted by RefitFromPose after such a gap
  bool texture_skipped = false;  // live: not textured, a newer frame was waiting
  bool texture_not_due = false;  // not textured: too soon after the last (pipeline.texture_every)
  double init_seconds = 0.0;
  std::string init_report;       // the initialisation's hypotheses and choice
  SegmentationStats segmentation;  // foreground segmentation (no background frames)
  TextureFrameSummary texture;
  // Novel-view texture quality at this frame (views == 0: not evaluated).
  NovelViewQuality texture_quality;
  double preprocess_seconds = 0.0;
  int scan_points = 0;
  // Ground truth metrics (NaN without ground truth).
  double mean_vertex_error_mm = 0.0;
  double max_vertex_error_mm = 0.0;
  double mean_joint_error_mm = 0.0;
  // Per tracked joint (template index): distance to the true joint (mm; NaN: no true joint of
  // its name). Empty without ground truth.
  std::vector<double> joint_errors_mm;
};

struct PipelineResult {
  std::vector<FrameRecord> frames;
  int skipped_frames = 0;
  // Fit quality labels of the fitted frames (solvers/fit_quality.h); failed fits (too few
  // points, non-finite, diverged) count as lost and also as failed.
  int good_frames = 0, doubtful_frames = 0, lost_frames = 0, failed_frames = 0;
  int initialisations = 0;  // first frame and re-initialisations after lost frames
  int gap_refits = 0;       // frames fitted after a gap (pipeline.gap_refit_frames)
  double init_ms_per_initialisation = 0.0;
  double quality_ms_per_frame = 0.0;
  bool has_ground_truth = false;
  // Ground-truth errors average over the evaluated frames: fitted with ground truth and not
  // failed (a failed fit keeps the previous pose, no measurement). lost_fraction counts failed
  // fits as lost: (evaluated frames beyond lost_threshold_mm + failed) / (evaluated + failed).
  // NaN without ground truth (errors also when no frame was evaluated).
  int evaluated_frames = 0;
  double mean_vertex_error_mm = 0.0;
  double max_vertex_error_mm = 0.0;
  double mean_joint_error_mm = 0.0;
  double lost_fraction = 0.0;
  double mean_em_iterations = 0.0;
  double fit_ms_per_frame = 0.0;  // tracking frames (initialisations apart)
  double texture_ms_per_frame = 0.0;
  double stream_kbit_per_s = 0.0;  // pose + texture updates, compressed, at the frame rate
  // Novel-view texture quality with ground truth (NaN without): at the last evaluated frame,
  // and the mean over the evaluated frames.
  double novel_view_psnr_db = 0.0, novel_view_ssim = 0.0, texture_coverage = 0.0;
  double mean_novel_view_psnr_db = 0.0, mean_novel_view_ssim = 0.0;
  bool has_stream = false;
  StreamSummary stream;  // with options.stream_path
  std::vector<std::string> warnings;
  // The frame after which the subject's shape was calibrated (shape.mode != fixed); -1: never.
  int shape_calibrated_frame = -1;
  // The frame of the last calibration round's swap (the calibration phase complete); -1: never.
  int shape_final_frame = -1;
  // The frame after which the surface detail was swapped in (shape.detail); -1: none during
  // the frames (e.g. estimated at the end of the sequence from the frames kept).
  int shape_detail_frame = -1;
  bool glb_written = false;
  AnimatedGlbSummary glb;  // tracked.glb against artex's skinning (residuals in mm)
  RealtimeStats realtime;  // throughput, latency, drops, stage timings (realtime.json)
};

struct PipelineProgress {
  int done = 0;
  int total = 0;
  double frames_per_second = 0.0;
  const FrameRecord* last = nullptr;
  // Ground truth evaluated in the background (pipeline.evaluate_in_background): `last` has no
  // errors yet; the mean vertex error of the latest frame evaluated (NaN: none yet).
  double latest_evaluated_error_mm = std::numeric_limits<double>::quiet_NaN();
};

// Runs the pipeline on a recording (artex sequence or TUM RGB-D folder: OpenFrameSource with
// options.input) with the tracking template at template_path (.glb; "" = the default
// generated template) and writes into out_dir (created): config.yaml
// (resolved), poses.csv, frames.csv, summary.json, metrics.json (with ground truth),
// texture.png, labels.png, tracked.glb, realtime.json (throughput, latency, live drops),
// meshes/ on request. The stages run per options.realtime (experiments/pipeline_stages.h).
// With shape.retrack (and a shape mode other than fixed) the sequence is tracked twice: the
// first pass (fitting only) calibrates the subject into out_dir/shape_pass/ (subject.glb,
// frames.csv, summary.json), the second tracks it with that template and writes the rest.
// Throws artex::Error on bad input and when no frame is usable (every frame unreadable or its fit failed), listing the reasons.
PipelineResult RunPipeline(const std::string& sequence_dir, const std::string& template_path,
                           const PipelineOptions& options, const Config& resolved_config,
                           const std::string& out_dir,
                           const std::function<void(const PipelineProgress&)>& progress = {});

}  // namespace artex
