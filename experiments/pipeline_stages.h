// The stages of the per-sequence pipeline (experiments/pipeline.h, docs/realtime.md) and the
// scheduler that runs them one after another or concurrently (realtime_options.h).
//
// read -> track (preprocess + fit + fit quality + re-initialisation) -> pool (which frames are
// textured, their images prepared for the image pool) -> texture (view selection, atlas, stream
// sinks, colour feedback) -> output (ground-truth metrics, per-frame files, the run's record).
// Each stage is a serial unit owning its state: frames pass through every stage in order, so
// the pipelined schedule computes exactly what the sequential one does. Dependences between
// frames stay inside a stage (the fitter's pose history and predictor, the segmenter's tracked
// subject in track; the texturer's pool and labelling in texture), except the colour term:
// track of frame t waits until texture has finished frame t - 1 - colour_delay_frames and
// uses the colours of that state (ColourMailbox).
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "experiments/ground_truth_evaluation.h"
#include "experiments/pipeline.h"
#include "experiments/realtime_options.h"
#include "experiments/stream_sinks.h"
#include "experiments/texture_evaluation.h"
#include "models/skinning.h"
#include "sensors/calibration.h"
#include "sensors/preprocess.h"
#include "sensors/sequence.h"

namespace artex {

using PipelineClock = std::chrono::steady_clock;

// One frame travelling through the stages.
struct FrameWork {
  int sequence = 0;  // position among the frames that entered the stages (0, 1, ...)
  FrameRecord record;
  std::string warning;  // why the frame is unreadable (record.skipped)
  Frame frame;          // depth is released after tracking, colour after texturing
  PipelineClock::time_point captured, textured;
  Pose pose;                // the frame's pose (fitted frames)
  // Shape estimation swapped the tracking template after the previous frame: this frame's pose
  // is of this template (the stream's rest shape; null: unchanged).
  std::shared_ptr<const Template> rest_shape;
  Eigen::MatrixX3d posed;   // its skinned template (world, m)
  bool texture_frame = false;
  PreparedFrame prepared;   // the pool stage's work for the texture stage (texture frames)
  cv::Mat foreground;       // pipeline.export_foreground
  // The texture after this frame, for the output stage (novel-view quality, atlas_frames).
  cv::Mat atlas;
  std::vector<int> triangle_frames;
  bool evaluate_texture = false;
  bool write_atlas = false;
};

// Colours from the texture stage to the track stage: Post after texturing item n (or with
// colours empty, none changed); WaitAndTake(m) blocks until item m is posted and returns the
// newest colours posted for an item <= m (false: none new). Abort wakes every waiter.
class ColourMailbox {
 public:
  void Post(int sequence, Eigen::MatrixX3d colours, bool changed);
  bool WaitAndTake(int sequence, Eigen::MatrixX3d* colours);
  void Abort();

 private:
  std::mutex mutex_;
  std::condition_variable posted_;
  int done_ = -1;  // items 0..done_ posted
  std::vector<std::pair<int, Eigen::MatrixX3d>> pending_;
  bool aborted_ = false;
};

// Preprocessing and fitting: scan, EM fit (multi-hypothesis initialisation on the first frame,
// after a lost one and on doubt per pipeline.reinitialise_*), fit quality label.
class TrackStage {
 public:
  TrackStage(const PipelineOptions& options, const Calibration& calibration,
             Preprocessor* preprocessor, EMFitter* fitter);
  void Process(FrameWork* work);
  void SetTemplateColors(const Eigen::MatrixX3d& colours);
  // Subject shape (section shape): accepted frames feed `shape`; once it solves, *tmpl becomes
  // the subject's template and the fitter tracks with it. Other stages read *tmpl, so the
  // pipeline runs sequentially with shape estimation on (RunPipeline).
  void SetShape(ShapeEstimator* shape, Template* tmpl) {
    shape_ = shape;
    tmpl_ = tmpl;
  }
  int shape_calibrated_frame = -1;  // record.frame of the first swap (-1: none)
  // record.frame of the last calibration round's swap (shape_->calibrated() from then on).
  int shape_final_frame = -1;
  // record.frame of the surface detail's swap (-1: none; shape.detail).
  int shape_detail_frame = -1;

  // Totals over the processed frames.
  double fit_seconds = 0.0, init_seconds = 0.0, quality_seconds = 0.0;
  int tracked_frames = 0, initialisations = 0, gap_refits = 0;

 private:
  void Initialise(FrameRecord* record);
  void Evaluate(FrameRecord* record, Eigen::MatrixX3d* posed);
  // An accepted frame's scan_ and pose to the shape estimator; swaps the subject's template
  // into *tmpl_ and the fitter when it solves (experiments/track_shape.cc).
  void FeedShape(const Frame& input, const Pose& pose, int frame);

  const PipelineOptions& options_;
  const Calibration& calibration_;
  Preprocessor* preprocessor_;
  EMFitter* fitter_;
  ShapeEstimator* shape_ = nullptr;
  Template* tmpl_ = nullptr;
  std::shared_ptr<const Template> rest_shape_;  // swapped in, for the next frame's FrameWork
  Scan scan_;
  bool need_init_ = true;
  int last_frame_ = -1;  // Frame::index of the last processed frame
  int doubtful_run_ = 0;  // consecutive doubtful frames
  // Per recent tracked frame (at most reinitialise_auto_window): did an in-place
  // re-initialisation replace the tracked fit? (ReinitialiseOn::kAuto)
  std::deque<bool> recent_replaced_;
  FitQualityLabel previous_label_ = FitQualityLabel::kLost;  // of the last processed frame
};

// The first half of the texturing: whether a tracked frame is textured (pipeline.texture_every)
// and, if so, its colour image made ready for the image pool (Texturer::PrepareFrame: the
// visibility and colours of the new image, about a quarter of the texturing's CPU), on its own
// thread ahead of the texture stage.
class PoolStage {
 public:
  PoolStage(const PipelineOptions& options, const Calibration& calibration, Texturer* texturer);
  void Process(FrameWork* work);

  int frames_not_due = 0;  // left untextured by pipeline.texture_every

 private:
  const PipelineOptions& options_;
  const Calibration& calibration_;
  Texturer* texturer_;
  int last_textured_ = -1;  // frame number of the last textured frame (-1: none yet)
};

// On-the-fly texturing of the fitted frames (the pool stage's prepared images), the stream
// sinks, the vertex colours for the colour term, and the texture snapshots the output stage
// evaluates.
class TextureStage {
 public:
  // texturer, sinks may be null. evaluate_texture: novel-view quality is measured (every
  // options.texture_quality_every-th frame of [begin, end) and the last).
  TextureStage(const PipelineOptions& options, Texturer* texturer, FrameSinks* sinks,
               bool evaluate_texture, int begin, int end);
  // True and *colours set when the fitter's template colours change after this frame.
  bool Process(FrameWork* work, Eigen::MatrixX3d* colours);

  double texture_seconds = 0.0;
  std::size_t stream_bytes = 0;  // pose + texture updates

 private:
  const PipelineOptions& options_;
  Texturer* texturer_;
  FrameSinks* sinks_;
  bool evaluate_texture_;
  int begin_, end_;
};

// Ground-truth metrics, per-frame files (meshes, foreground, atlases) and the run's record:
// fills result (frames, labels, failures, error sums) in frame order, calls progress. The
// ground-truth metrics are computed in Process, or after StartBackgroundEvaluation on a thread
// of their own (experiments/ground_truth_evaluation.h) and merged into the records in frame
// order by FinishEvaluation: the same numbers either way.
class OutputStage {
 public:
  OutputStage(const PipelineOptions& options, const Template& tmpl,
              const GroundTruthContext& truth, const std::string& out_dir, int begin, int end,
              PipelineResult* result, const std::function<void(const PipelineProgress&)>& progress);
  void Process(FrameWork* work);
  // With ground truth: evaluate on a background thread, at most queue_depth frames waiting.
  // Only where nothing changes the template's triangles and UVs while frames are evaluated.
  void StartBackgroundEvaluation(std::size_t queue_depth);
  // Waits for the background evaluation and merges its metrics (no-op without one).
  void FinishEvaluation();
  // Frames the background evaluation has finished so far (0 without one).
  int evaluation_frames_done() const { return background_ ? background_->frames_done() : 0; }
  // The background evaluation's CPU and busy time (s, its thread's) and frames (those
  // FinishEvaluation evaluated on the calling thread included; after FinishEvaluation).
  double evaluation_cpu_seconds = 0.0, evaluation_busy_seconds = 0.0;
  int evaluation_frames = 0;
  int evaluation_frames_here = 0;  // of the background evaluation's: done in Process (queue full)

  std::vector<Pose> poses;
  std::vector<int> pose_frames;
  std::vector<std::string> failures;  // why each failed fit failed
  double iterations = 0.0;
  double error_sum = 0.0, joint_sum = 0.0;
  int evaluated = 0, lost = 0, scored = 0;
  double psnr_sum = 0.0, ssim_sum = 0.0;
  int quality_evaluations = 0;

 private:
  const PipelineOptions& options_;
  const Template& tmpl_;
  // Takes tmpl_'s rest geometry into skinning_ when its joint centres changed (a subject
  // shape swapped in).
  void SyncRestGeometry();

  // A frame's metrics into its record and the run's sums (in frame order).
  void MergeEvaluation(const FrameErrors& errors, FrameRecord* record);

  Skinning skinning_;  // its own: the track stage's is busy
  GroundTruthContext truth_;
  GroundTruthEvaluator evaluator_;
  std::unique_ptr<BackgroundEvaluation> background_;
  // Background: each evaluated frame's index in result.frames, in frame order, and the metrics
  // of those the output stage evaluated itself (the queue full), by that index.
  std::vector<int> evaluation_slots_;
  std::map<int, FrameErrors> evaluated_here_;
  std::string out_dir_;
  int begin_, end_;
  PipelineResult* result_;
  std::function<void(const PipelineProgress&)> progress_;
  PipelineClock::time_point start_;
};

// Runs frames [begin, end) of source through the stages per options (sequential or
// pipelined; live: on a clock at rate_hz, dropping what the first queue cannot take) and
// returns what it measured. Rethrows the first stage's exception after stopping all stages.
RealtimeStats RunStages(const RealtimeOptions& options, FrameSource* source, int begin, int end,
                        double rate_hz, TrackStage* track, PoolStage* pool,
                        TextureStage* texture, OutputStage* output);

// Writes realtime.json (RealtimeStats) into out_dir.
void WriteRealtimeJson(const std::string& path, const RealtimeStats& stats);

// Writes `image` as a PNG (atomically) and returns the encoded bytes.
std::vector<unsigned char> WritePngFile(const std::string& path, const cv::Mat& image);

}  // namespace artex
