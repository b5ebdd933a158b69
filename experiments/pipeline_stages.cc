#include "experiments/pipeline_stages.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <limits>

#include "experiments/atomic_output.h"
#include "experiments/bounded_queue.h"
#include "experiments/surface_error.h"
#include "models/error.h"
#include "models/mesh_export.h"
#include "models/normals.h"
#include "models/numeric.h"
#include "sensors/image_codec.h"
#include "solvers/particle_predictor.h"

namespace artex {
namespace {

// Bytes to send the texels that changed in the last frame: their bounding box of the atlas
// as a JPEG (quality 90); 0 when nothing changed.
std::size_t TextureUpdateBytes(const Texturer& texturer) {
  const cv::Mat patch = texturer.ChangedPatch();
  if (patch.empty()) return 0;
  std::vector<unsigned char> bytes;
  std::string error;
  if (!EncodeJpeg(patch, 90, &bytes, &error)) throw Error("texture update: " + error);
  return bytes.size();
}

// Why frame `frame`'s fit failed: what was expected and what was found.
std::string FailedFitReason(int frame, const FitSummary& fit, int min_scan_points) {
  std::string why = "frame " + std::to_string(frame) + ": fit failed: ";
  if (fit.too_few_points) {
    why +=
        "too few scan points or correspondences (expected >= " + std::to_string(min_scan_points) +
        " points, found " + std::to_string(fit.num_scan_points) + ")";
  } else if (fit.non_finite) {
    why += "non-finite scan values or pose";
  } else {
    why += "diverged";
  }
  return why;
}

}  // namespace

const std::map<std::string, PipelineConcurrency>& PipelineConcurrencyNames() {
  static const std::map<std::string, PipelineConcurrency> names = {
      {"sequential", PipelineConcurrency::kSequential},
      {"pipelined", PipelineConcurrency::kPipelined}};
  return names;
}

bool RealtimeOptions::IsValid(std::string* error) const {
  std::string msg;
  if (queue_depth < 1) {
    msg = "pipeline.queue_depth: expected >= 1, found " + std::to_string(queue_depth);
  } else if (max_frames_in_flight < 0) {
    msg = "pipeline.max_frames_in_flight: expected >= 0 (0: no limit), found " +
          std::to_string(max_frames_in_flight);
  } else if (!(live_rate_hz >= 0.0) || live_rate_hz > 1000.0) {
    msg = "pipeline.live_rate_hz: expected 0 (the recording's rate) or a rate in (0, 1000] Hz, "
          "found " + std::to_string(live_rate_hz);
  } else if (live_queue_depth < 1) {
    msg = "pipeline.live_queue_depth: expected >= 1, found " + std::to_string(live_queue_depth);
  } else if (live_init_queue_depth < 0) {
    msg = "pipeline.live_init_queue_depth: expected >= 0 (0: live_queue_depth), found " +
          std::to_string(live_init_queue_depth);
  } else if (live_init_drain_every < 1) {
    msg = "pipeline.live_init_drain_every: expected >= 1, found " +
          std::to_string(live_init_drain_every);
  } else if (evaluation_queue_depth < 1) {
    msg = "pipeline.evaluation_queue_depth: expected >= 1, found " +
          std::to_string(evaluation_queue_depth);
  } else if (colour_delay_frames < 0) {
    msg = "pipeline.colour_delay_frames: expected >= 0, found " +
          std::to_string(colour_delay_frames);
  } else if (blas_threads < 0) {
    msg = "pipeline.blas_threads: expected >= 0 (0: the BLAS library's own setting), found " +
          std::to_string(blas_threads);
  } else if (threads < 0) {
    msg = "pipeline.threads: expected >= 0 (0: every core), found " + std::to_string(threads);
  } else if (heap_retain_mb < 0 || heap_retain_mb > 65536) {
    msg = "pipeline.heap_retain_mb: expected 0 (the allocator's defaults) to 65536, found " +
          std::to_string(heap_retain_mb);
  } else if (heap_arenas < 0 || heap_arenas > 1024) {
    msg = "pipeline.heap_arenas: expected 0 (glibc's default) to 1024, found " +
          std::to_string(heap_arenas);
  }
  if (msg.empty()) return true;
  if (error) *error = msg;
  return false;
}

std::vector<unsigned char> WritePngFile(const std::string& path, const cv::Mat& image) {
  std::vector<unsigned char> bytes;
  std::string error;
  if (!EncodePng(image, &bytes, &error)) throw Error(path + ": " + error);
  WriteFileAtomically(path, std::string(bytes.begin(), bytes.end()));
  return bytes;
}

// ---------------------------------------------------------------------------------------------
// ColourMailbox

void ColourMailbox::Post(int sequence, Eigen::MatrixX3d colours, bool changed) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (changed) pending_.emplace_back(sequence, std::move(colours));
  done_ = std::max(done_, sequence);
  posted_.notify_all();
}

bool ColourMailbox::WaitAndTake(int sequence, Eigen::MatrixX3d* colours) {
  std::unique_lock<std::mutex> lock(mutex_);
  posted_.wait(lock, [&] { return aborted_ || done_ >= sequence; });
  if (aborted_) return false;
  auto newest = pending_.end();
  for (auto it = pending_.begin(); it != pending_.end(); ++it)
    if (it->first <= sequence) newest = it;
  if (newest == pending_.end()) return false;
  *colours = std::move(newest->second);
  pending_.erase(pending_.begin(), newest + 1);
  return true;
}

void ColourMailbox::Abort() {
  std::lock_guard<std::mutex> lock(mutex_);
  aborted_ = true;
  posted_.notify_all();
}

// ---------------------------------------------------------------------------------------------
// TrackStage

TrackStage::TrackStage(const PipelineOptions& options, const Calibration& calibration,
                       Preprocessor* preprocessor, EMFitter* fitter)
    : options_(options), calibration_(calibration), preprocessor_(preprocessor), fitter_(fitter) {}

void TrackStage::SetTemplateColors(const Eigen::MatrixX3d& colours) {
  fitter_->SetTemplateColors(colours);
}

void TrackStage::Initialise(FrameRecord* r) {
  const InitResult init = InitializeFit(fitter_, scan_, calibration_.depth, options_.initializer);
  r->fit = init.fit;
  r->reinitialised = true;
  r->init_seconds = init.total_seconds;
  r->init_report = init.BriefReport();
  ++initialisations;
  init_seconds += init.total_seconds;
}

void TrackStage::Evaluate(FrameRecord* r, Eigen::MatrixX3d* posed) {
  fitter_->skinning().Apply(fitter_->pose(), posed);
  if (r->fit.ok()) {
    const Template& model = fitter_->skinning().model();
    // The per-part map only when the per-part check is on (off by default: no work per frame).
    const bool by_part = options_.quality.part_min_support > 0.0;
    const Eigen::VectorXi parts =
        by_part ? FitQualityParts(model.vertex_joint, model.JointNames(), options_.quality)
                : Eigen::VectorXi();
    r->quality = EvaluateFitQuality(*posed, model.triangles, scan_, calibration_.depth,
                                    options_.quality, by_part ? &parts : nullptr);
  } else {
    r->quality = FitQuality();  // a failed fit is lost, whatever its kept pose shows
    r->quality.label = FitQualityLabel::kLost;
  }
  quality_seconds += r->quality.seconds;
}

void TrackStage::Process(FrameWork* work) {
  FrameRecord& record = work->record;
  if (record.skipped) return;
  work->rest_shape = std::move(rest_shape_);  // leaves rest_shape_ empty
  const Frame& frame = work->frame;
  const auto t_pre = PipelineClock::now();
  PreprocessStats stats;
  preprocessor_->Process(frame, &scan_, &stats);
  record.preprocess_seconds = SecondsSince(t_pre);
  record.scan_points = scan_.size();
  record.segmentation = stats.segmentation;
  if (options_.export_foreground) work->foreground = preprocessor_->foreground_mask().clone();

  // Fit: the multi-hypothesis initialisation on the first frame and after a lost one.
  const bool enough_points = scan_.size() >= options_.fitting.min_scan_points;
  // Frames of the recording not processed since the last one: dropped by the live reader, or
  // missing from the recording (its own frame numbers).
  record.gap_frames = last_frame_ >= 0 ? std::max(0, frame.index - last_frame_ - 1) : 0;
  last_frame_ = frame.index;
  if (need_init_ && enough_points) {
    Initialise(&record);
  } else if (options_.gap_refit_frames > 0 && record.gap_frames >= options_.gap_refit_frames &&
             fitter_->tracking() && enough_points) {
    // Frames were dropped (live): the subject may have moved beyond the tracking radii.
    GapRefitOptions refit = options_.gap_refit;
    if (record.gap_frames < options_.gap_refit_stride_frames) refit.leg_stride_deg = 0.0;
    record.fit = RefitFromPose(fitter_, scan_, calibration_.depth, fitter_->pose(), refit);
    record.gap_refit = true;
    fit_seconds += record.fit.total_seconds;
    ++tracked_frames;
    ++gap_refits;
  } else {
    record.fit = TrackFrame(fitter_, scan_, calibration_.depth, options_.quality);
    fit_seconds += record.fit.total_seconds;
    ++tracked_frames;
  }
  Eigen::MatrixX3d& posed = work->posed;
  Evaluate(&record, &posed);
  Pose tracked_pose;
  bool keep_tracked = false;
  // Tracking that loses the frame (or doubts it, by option) is followed by a
  // re-initialisation in the same frame; the better of the two by quality score is kept. A
  // tracking fit that failed with enough scan points (no correspondence within the E-step's
  // radius of a prediction far off, or diverged) is lost and re-initialised the same way; a
  // scan with non-finite values is not fitted again.
  const FitQualityLabel label = record.quality.label;
  doubtful_run_ = label == FitQualityLabel::kDoubtful ? doubtful_run_ + 1 : 0;
  const bool doubted_long = options_.reinitialise_after_doubtful > 0 &&
                            doubtful_run_ >= options_.reinitialise_after_doubtful;
  const bool tracked = !record.reinitialised;
  const bool doubtful_too =
      options_.reinitialise_on == ReinitialiseOn::kDoubtful ||
      (options_.reinitialise_on == ReinitialiseOn::kAuto &&
       (previous_label_ == FitQualityLabel::kGood ||
        std::count(recent_replaced_.begin(), recent_replaced_.end(), true) >=
            options_.reinitialise_auto_wins));
  bool replaced = false;
  if (tracked && !record.fit.non_finite && enough_points &&
      (label == FitQualityLabel::kLost ||
       (label == FitQualityLabel::kDoubtful &&
        (doubted_long || doubtful_too)))) {
    doubtful_run_ = 0;
    tracked_pose = fitter_->pose();
    const Scan tracked_scan = scan_;
    FrameRecord retry = record;
    fitter_->Reset(/*keep_scale=*/true);
    if (label == FitQualityLabel::kLost) {
      // The tracked component may be the wrong one: choose the subject again.
      preprocessor_->ResetSubject();
      preprocessor_->Process(frame, &scan_, &stats);
      retry.scan_points = scan_.size();
      retry.segmentation = stats.segmentation;
    }
    if (scan_.size() >= options_.fitting.min_scan_points) {
      Initialise(&retry);
      Evaluate(&retry, &posed);
    }
    if (retry.reinitialised && retry.fit.ok() && retry.quality.score > record.quality.score) {
      record = retry;
      replaced = true;
    } else {
      // The tracked fit stays (its scan too); a lost one is re-initialised next frame.
      scan_ = tracked_scan;
      fitter_->Reset(/*keep_scale=*/true);
      if (label != FitQualityLabel::kLost) fitter_->AcceptPose(scan_, tracked_pose);
      keep_tracked = true;
      record.init_seconds = retry.init_seconds;
      record.init_report = retry.init_report + " (not better than tracking: kept)";
    }
  }
  previous_label_ = record.quality.label;
  if (tracked) {
    recent_replaced_.push_back(replaced);
    while (static_cast<int>(recent_replaced_.size()) > options_.reinitialise_auto_window) {
      recent_replaced_.pop_front();
    }
  }
  work->pose = keep_tracked ? tracked_pose : fitter_->pose();
  // `posed` is the evaluated fit's (Evaluate skins fitter.pose()), unless the tracked fit
  // was kept after a re-initialisation was tried.
  if (keep_tracked) fitter_->skinning().Apply(work->pose, &posed);
  const bool lost_frame = record.quality.label == FitQualityLabel::kLost;
  // A lost frame's pose is not texture: it would paint the room onto the body.
  work->texture_frame = !lost_frame && (options_.texture_doubtful_frames ||
                                        record.quality.label == FitQualityLabel::kGood);
  if (!lost_frame && record.fit.ok()) FeedShape(frame, work->pose, record.frame);
  if (lost_frame) {
    // Re-initialise on the next frame with enough points; the scale estimate and the
    // texture survive (the same person), the tracked subject component does not.
    need_init_ = true;
    fitter_->Reset(/*keep_scale=*/true);
    preprocessor_->ResetSubject();
  } else {
    need_init_ = false;
  }
  work->frame.depth.release();
}

// ---------------------------------------------------------------------------------------------
// PoolStage

PoolStage::PoolStage(const PipelineOptions& options, const Calibration& calibration,
                     Texturer* texturer)
    : options_(options), calibration_(calibration), texturer_(texturer) {}

void PoolStage::Process(FrameWork* work) {
  FrameRecord& record = work->record;
  if (record.skipped) return;
  const int i = record.frame;
  if (texturer_ && work->texture_frame && last_textured_ >= 0 &&
      i - last_textured_ < options_.texture_every) {
    work->texture_frame = false;  // not due yet: the texture stays as it is
    record.texture_not_due = true;
    ++frames_not_due;
  }
  if (texturer_ && work->texture_frame) {
    last_textured_ = i;
    work->prepared = texturer_->PrepareFrame(i, work->frame.color, calibration_.color, work->posed);
  }
  work->frame.color.release();
}

// ---------------------------------------------------------------------------------------------
// TextureStage

TextureStage::TextureStage(const PipelineOptions& options, Texturer* texturer, FrameSinks* sinks,
                           bool evaluate_texture, int begin, int end)
    : options_(options),
      texturer_(texturer),
      sinks_(sinks),
      evaluate_texture_(evaluate_texture && texturer != nullptr),
      begin_(begin),
      end_(end) {}

bool TextureStage::Process(FrameWork* work, Eigen::MatrixX3d* colours) {
  const FrameRecord& done = work->record;
  if (done.skipped) return false;
  const int i = done.frame;
  FrameRecord& record = work->record;
  bool changed = false;
  if (options_.stream_estimate) stream_bytes += sizeof(float) * work->pose.num_parameters();
  if (texturer_ && work->texture_frame) {
    record.texture = texturer_->AddPrepared(std::move(work->prepared));
    texture_seconds += record.texture.seconds_total;
    if (options_.stream_estimate) stream_bytes += TextureUpdateBytes(*texturer_);
    // The colour term starts once the texture covers most of the body (counted without
    // levelling the seams: the colours, which need it, are read only then); vertices without
    // texture take the mean colour (neutral for the colour distance on average).
    if (options_.colour_term &&
        texturer_->ColouredVertexCount() > 0.9 * work->posed.rows()) {
      std::vector<uint8_t> valid;
      Eigen::MatrixX3d& c = *colours;
      texturer_->VertexColors(&c, &valid);
      int count = 0;
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      for (int v = 0; v < c.rows(); ++v) {
        if (!valid[v]) continue;
        mean += c.row(v).transpose();
        ++count;
      }
      // count is ColouredVertexCount (the same corners), so above the 90 % already.
      mean /= count;
      for (int v = 0; v < c.rows(); ++v)
        if (!valid[v]) c.row(v) = mean.transpose();
      changed = true;
    }
    for (int f : options_.atlas_frames) work->write_atlas = work->write_atlas || f == i;
  }
  if (sinks_) sinks_->AddFrame(i, work->pose, work->rest_shape.get());
  const int every = options_.texture_quality_every;
  work->evaluate_texture =
      evaluate_texture_ && every > 0 && ((i - begin_ + 1) % every == 0 || i == end_ - 1);
  if (work->evaluate_texture || work->write_atlas) {
    work->atlas = texturer_->Atlas();  // a new image each call
    if (work->evaluate_texture) work->triangle_frames = texturer_->triangle_frames();
  }
  // Seams levelled by a read after AddFrame (texture.levelling_every_frame false: the colour
  // term, an atlas snapshot, the stream): the frame's record gets their residuals and time.
  if (texturer_ && work->texture_frame && std::isnan(record.texture.seam_rms_after) &&
      texturer_->seams_levelled()) {
    record.texture.seam_rms_before = texturer_->seam_rms_before();
    record.texture.seam_rms_after = texturer_->seam_rms_after();
    const double seconds = texturer_->levelling_seconds_since_add();
    record.texture.seconds_levelling += seconds;
    record.texture.seconds_total += seconds;
    texture_seconds += seconds;
  }
  return changed;
}

// ---------------------------------------------------------------------------------------------
// OutputStage

OutputStage::OutputStage(const PipelineOptions& options, const Template& tmpl,
                         const GroundTruthContext& truth, const std::string& out_dir, int begin,
                         int end, PipelineResult* result,
                         const std::function<void(const PipelineProgress&)>& progress)
    : options_(options),
      tmpl_(tmpl),
      skinning_(tmpl),
      truth_(truth),
      evaluator_(tmpl, truth, options.held_out),
      out_dir_(out_dir),
      begin_(begin),
      end_(end),
      result_(result),
      progress_(progress),
      start_(PipelineClock::now()) {}

void OutputStage::SyncRestGeometry() {
  const Template& current = skinning_.model();
  // Only the joint centres enter PosedJointCenters (a girth-only change keeps them).
  bool same = current.num_joints() == tmpl_.num_joints();
  for (int j = 0; same && j < tmpl_.num_joints(); ++j) {
    same = current.joints[j].center == tmpl_.joints[j].center;
  }
  if (same) return;
  Eigen::MatrixX3d centers(tmpl_.num_joints(), 3);
  for (int j = 0; j < tmpl_.num_joints(); ++j) centers.row(j) = tmpl_.joints[j].center.transpose();
  skinning_.SetRestGeometry(tmpl_.vertices, centers);
}

void OutputStage::Process(FrameWork* work) {
  PipelineResult& result = *result_;
  FrameRecord& record = work->record;
  const int i = record.frame;
  if (record.skipped) {
    ++result.skipped_frames;
    result.warnings.push_back(work->warning);
    result.frames.push_back(record);
    return;
  }
  if (options_.export_foreground) {
    char name[64];
    std::snprintf(name, sizeof(name), "/foreground/%06d.png", i);
    WritePngFile(out_dir_ + name, work->foreground);
  }
  if (!record.fit.ok()) {
    ++result.failed_frames;
    failures.push_back(FailedFitReason(i, record.fit, options_.fitting.min_scan_points));
  }
  iterations += record.fit.iterations;
  const Pose& frame_pose = work->pose;
  const Eigen::MatrixX3d& posed = work->posed;
  poses.push_back(frame_pose);
  pose_frames.push_back(i);
  switch (record.quality.label) {
    case FitQualityLabel::kGood:
      ++result.good_frames;
      break;
    case FitQualityLabel::kDoubtful:
      ++result.doubtful_frames;
      break;
    case FitQualityLabel::kLost:
      ++result.lost_frames;
      break;
  }
  if (work->write_atlas) {
    char name[64];
    std::snprintf(name, sizeof(name), "/texture_%06d.png", i);
    WritePngFile(out_dir_ + name, work->atlas);
  }
  if (options_.export_meshes) {
    char name[64];
    std::snprintf(name, sizeof(name), "/meshes/%06d.ply", i);
    WritePosedMesh(out_dir_ + name, ToUpAxis(posed, options_.mesh_up_axis), tmpl_.triangles);
  }
  if (truth_.subject) {
    FrameEvaluation frame;
    frame.frame = i;
    frame.posed = std::move(work->posed);  // nothing after this reads it
    // Shape estimation swaps the subject's rest geometry into tmpl_ (TrackStage): the joint
    // centres must be the subject's from then on, not the template's this stage started with.
    SyncRestGeometry();
    skinning_.PosedJointCenters(frame_pose, &frame.joints);
    frame.evaluate_texture = truth_.truth_scene && work->evaluate_texture;
    if (frame.evaluate_texture) {
      // Moved, not shared: the evaluation's thread then owns the image alone (its reference
      // count lives in OpenCV, which ThreadSanitizer cannot see). Nothing after this reads it.
      frame.atlas = std::move(work->atlas);
      frame.triangle_frames = std::move(work->triangle_frames);
    }
    record.mean_vertex_error_mm = record.max_vertex_error_mm = record.mean_joint_error_mm =
        std::numeric_limits<double>::quiet_NaN();
    if (background_) {
      const int slot = static_cast<int>(result.frames.size());
      evaluation_slots_.push_back(slot);
      // The queue full (the machine busy): this frame here, at the stage's priority (TryPush
      // leaves the frame untouched when it refuses).
      if (!background_->TryPush(std::move(frame)))
        evaluated_here_[slot] = evaluator_.Evaluate(frame);
    } else {
      MergeEvaluation(evaluator_.Evaluate(frame), &record);
    }
  } else {
    record.mean_vertex_error_mm = record.max_vertex_error_mm = record.mean_joint_error_mm =
        std::numeric_limits<double>::quiet_NaN();
  }
  result.frames.push_back(record);
  if (progress_) {
    PipelineProgress p;
    p.done = i - begin_ + 1;
    p.total = end_ - begin_;
    p.frames_per_second = static_cast<double>(result.frames.size()) / std::max(1e-9, SecondsSince(start_));
    p.last = &result.frames.back();
    if (background_) p.latest_evaluated_error_mm = background_->latest_mean_vertex_error_mm();
    progress_(p);
  }
}

void OutputStage::MergeEvaluation(const FrameErrors& e, FrameRecord* record) {
  PipelineResult& result = *result_;
  record->mean_vertex_error_mm = e.mean_vertex_error_mm;
  record->max_vertex_error_mm = e.max_vertex_error_mm;
  record->mean_joint_error_mm = e.mean_joint_error_mm;
  record->joint_errors_mm = e.joint_errors_mm;
  // A failed fit's kept pose is no measurement: it counts as lost and stays out of the
  // error averages (issue 20: all-failed runs reported a small error).
  if (record->fit.ok()) {
    error_sum += record->mean_vertex_error_mm;
    joint_sum += record->mean_joint_error_mm;
    result.max_vertex_error_mm = std::max(result.max_vertex_error_mm, record->max_vertex_error_mm);
    ++evaluated;
  }
  lost += record->mean_vertex_error_mm > options_.lost_threshold_mm || !record->fit.ok();
  ++scored;
  if (e.has_texture_quality) {
    record->texture_quality = e.texture_quality;
    const NovelViewQuality& q = record->texture_quality;
    if (std::isfinite(q.psnr_db) && std::isfinite(q.ssim)) {
      result.novel_view_psnr_db = q.psnr_db;
      result.novel_view_ssim = q.ssim;
      result.texture_coverage = q.coverage;
      psnr_sum += q.psnr_db;
      ssim_sum += q.ssim;
      ++quality_evaluations;
    }
  }
}

void OutputStage::StartBackgroundEvaluation(std::size_t queue_depth) {
  if (truth_.subject && !background_)
    background_ = std::make_unique<BackgroundEvaluation>(&evaluator_, queue_depth);
}

void OutputStage::FinishEvaluation() {
  if (!background_) return;
  const std::vector<FrameErrors> errors = background_->Finish();
  evaluation_cpu_seconds = background_->cpu_seconds();
  evaluation_busy_seconds = background_->busy_seconds();
  evaluation_frames = background_->frames_done() + background_->frames_done_by_finish();
  std::size_t next = 0;  // the background's results, in the order of the frames pushed
  for (const int slot : evaluation_slots_) {
    const auto here = evaluated_here_.find(slot);
    if (here != evaluated_here_.end()) {
      MergeEvaluation(here->second, &result_->frames[slot]);
    } else if (next < errors.size()) {
      MergeEvaluation(errors[next++], &result_->frames[slot]);
    }
  }
  evaluation_frames_here = static_cast<int>(evaluated_here_.size());
  background_.reset();
  evaluation_slots_.clear();
  evaluated_here_.clear();
}

}  // namespace artex
