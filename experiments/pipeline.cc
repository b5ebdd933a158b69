#include "experiments/pipeline.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iterator>
#include <limits>
#include <memory>
#include <nanoflann.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/core/utility.hpp>
#include <optional>
#include <sstream>
#include <tbb/global_control.h>
#include <tbb/task_group.h>

#include "experiments/blas_threads.h"
#include "experiments/heap_retention.h"
#include "experiments/pipeline_output.h"
#include "experiments/pipeline_stages.h"
#include "experiments/pose_csv.h"
#include "experiments/shape_output.h"
#include "experiments/stream_sinks.h"
#include "experiments/texture_evaluation.h"
#include "models/error.h"
#include "models/mesh_export.h"
#include "models/normals.h"
#include "models/skinning.h"
#include "models/template_cache.h"
#include "models/template_io.h"
#include "sensors/bvh_export.h"
#include "sensors/calibration.h"
#include "sensors/frame_source.h"
#include "sensors/image_io.h"
#include "sensors/scene_segmentation.h"
#include "sensors/sequence.h"
#include "solvers/particle_predictor.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

// The calibration tracking uses: the sequence's, or with the world frame estimated from the
// first readable frame (floor plane, gravity or the camera convention).
struct FrameWorld {
  Calibration calibration;
  std::optional<WorldFrameEstimate> estimate;
  Eigen::Isometry3d to_calibration_world = Eigen::Isometry3d::Identity();  // tracking -> sequence
};

// Reads the first readable frame of [begin, end) into *frame; its number, or end when none is.
int ReadFirstFrame(FrameSource* source, int begin, int end, Frame* frame) {
  std::string warning;
  int i = begin;
  while (i < end && !source->ReadFrame(i, frame, &warning)) ++i;
  return i;
}

FrameWorld ChooseWorldFrame(FrameSource* source, int begin, int end,
                            const PreprocessOptions& options,
                            const std::optional<Eigen::Vector3d>& gravity, PipelineResult* result) {
  FrameWorld world;
  world.calibration = source->calibration();
  const Eigen::Isometry3d given = world.calibration.depth.world_to_camera;
  const bool camera_frame = given.isApprox(Eigen::Isometry3d::Identity(), 1e-12);
  if (options.world_frame == WorldFrameMode::kCalibration ||
      (options.world_frame == WorldFrameMode::kAuto && !camera_frame)) {
    return world;
  }
  Frame frame;
  const int i = ReadFirstFrame(source, begin, end, &frame);
  if (i >= end) return world;  // nothing readable: the frame loop reports it
  WorldFrameOptions wo;
  wo.planes = options.segmentation.planes;
  wo.assumed_camera_height = options.assumed_camera_height;
  const WorldFrameEstimate estimate =
      EstimateWorldFrame(frame.depth, world.calibration.depth, world.calibration.depth_distortion,
                         world.calibration.depth_scale, gravity, wo);
  const Eigen::Isometry3d depth_to_color = world.calibration.DepthToColor();
  world.calibration.depth.world_to_camera = estimate.world_to_camera;
  world.calibration.color.world_to_camera = depth_to_color * estimate.world_to_camera;
  world.to_calibration_world = given.inverse() * estimate.world_to_camera;
  if (estimate.source == WorldFrameSource::kCameraConvention) {
    result->warnings.push_back(
        "no floor found in frame " + std::to_string(i) +
        " and no gravity: the world frame assumes the camera is upright (up = -y of the "
        "camera); set preprocess.world_frame: calibration with a calibration.yaml if it is not");
  }
  world.estimate = estimate;
  return world;
}

// The floor (world frame of `calibration`) in the first readable frame, for the shape's floor
// term; none without a readable frame or a floor in it.
std::optional<ScenePlane> FirstFrameFloor(FrameSource* source, int begin, int end,
                                          const Calibration& calibration,
                                          const PreprocessOptions& options) {
  Frame frame;
  if (ReadFirstFrame(source, begin, end, &frame) >= end) return std::nullopt;
  return FindWorldFloor(frame.depth, calibration.depth, calibration.depth_distortion,
                        calibration.depth_scale, options.segmentation.planes);
}

// The error of a run without one usable frame: every reason, the first kListedReasons of each
// kind listed (a long all-black recording would otherwise give one line per frame).
std::string NoUsableFrameMessage(const std::string& sequence_dir, int frames,
                                 const std::vector<std::string>& skipped,
                                 const std::vector<std::string>& failed) {
  constexpr size_t kListedReasons = 10;
  std::string msg = sequence_dir + ": no usable frame in the sequence (" + std::to_string(frames) +
                    " frames: " + std::to_string(skipped.size()) + " unreadable, " +
                    std::to_string(failed.size()) + " failed fits)";
  for (const std::vector<std::string>* list : {&skipped, &failed}) {
    for (size_t k = 0; k < list->size() && k < kListedReasons; ++k) msg += "\n  " + (*list)[k];
    if (list->size() > kListedReasons)
      msg += "\n  ... and " + std::to_string(list->size() - kListedReasons) + " more";
  }
  return msg;
}

}  // namespace

namespace {

PipelineResult RunOnePass(const std::string& sequence_dir, const std::string& template_path,
                          const PipelineOptions& options, const Config& resolved_config,
                          const std::string& out_dir,
                          const std::function<void(const PipelineProgress&)>& progress) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(why);
  const std::unique_ptr<FrameSource> source = OpenFrameSource(sequence_dir, options.input);
  FrameSource& reader = *source;
  // Ground truth exists only in artex sequences.
  const SequenceReader* sequence = dynamic_cast<const SequenceReader*>(source.get());
  const int total_frames = reader.num_frames();
  const int begin = std::min(options.first_frame, total_frames);
  const int end =
      options.max_frames > 0 ? std::min(total_frames, begin + options.max_frames) : total_frames;
  PipelineResult result;
  const std::vector<cv::Mat> background = reader.ReadBackgroundFrames();
  const FrameWorld world =
      ChooseWorldFrame(&reader, begin, end, options.preprocess, reader.gravity(), &result);
  const Calibration& calibration = world.calibration;
  // Not const: replaced by the subject's template after the shape calibration (section shape).
  std::string cache_note;
  Template tmpl = template_path.empty() ? DefaultTemplate(options.template_cache, &cache_note)
                                        : ReadTemplateFile(template_path);
  if (!cache_note.empty()) result.warnings.push_back(cache_note);
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) throw Error(out_dir + ": cannot create the output folder: " + ec.message());
  WriteFileAtomically(out_dir + "/config.yaml", resolved_config.ToYaml() + "\n");
  WriteCalibration(calibration, out_dir + "/calibration.yaml");

  // The stages' state, built concurrently (each from inputs it only reads; the ground truth's
  // files are read meanwhile): about half the time of one after another on two cores.
  Preprocessor preprocessor(calibration, options.preprocess);
  std::unique_ptr<EMFitter> fitter_owner;
  std::unique_ptr<Texturer> texturer;
  // Ground truth: the subject's mesh and skeleton (for surface and joint errors).
  result.has_ground_truth = sequence && sequence->has_ground_truth() &&
                            !sequence->GroundTruthSubjectPath().empty() &&
                            fs::exists(sequence->GroundTruthSubjectPath());
  std::unique_ptr<Template> subject;
  std::unique_ptr<Skinning> subject_skinning;
  cv::Mat truth_texture;  // read when the novel-view texture quality is measured
  {
    tbb::task_group setup;
    setup.run([&] {
      if (background.empty()) {
        preprocessor.TrainWithoutBackground();
        if (world.estimate) preprocessor.SetScenePlanes(world.estimate->planes);
      } else {
        preprocessor.Train(background);
      }
    });
    setup.run([&] {
      fitter_owner = std::make_unique<EMFitter>(tmpl, options.fitting);
      // Joints out of the depth camera's view are held (out_of_view).
      fitter_owner->SetDepthCamera(calibration.depth);
    });
    if (options.texture) {
      setup.run([&] { texturer = std::make_unique<Texturer>(tmpl, options.texturing); });
    }
    if (result.has_ground_truth) {
      setup.run([&] {
        subject = std::make_unique<Template>(ReadTemplateGlb(sequence->GroundTruthSubjectPath()));
        subject_skinning = std::make_unique<Skinning>(*subject);
        if (options.texture && options.texture_quality_every > 0 && subject->has_uvs() &&
            !sequence->GroundTruthTexturePath().empty()) {
          truth_texture = ReadImageFile(sequence->GroundTruthTexturePath(), ImageRead::kColor);
        }
      });
    }
    setup.wait();  // rethrows the first task's exception
  }
  EMFitter& fitter = *fitter_owner;
  std::vector<std::pair<int, int>> joint_pairs;  // (tracked joint, subject joint) by name
  if (result.has_ground_truth) {
    for (int j = 0; j < tmpl.num_joints(); ++j) {
      const int s = subject->FindJoint(tmpl.joints[j].name);
      if (s >= 0) joint_pairs.emplace_back(j, s);
    }
  }
  // Novel-view texture quality needs the true texture as well (read above when measured).
  std::unique_ptr<TruthScene> truth_scene;
  if (!truth_texture.empty()) {
    truth_scene = std::make_unique<TruthScene>();
    truth_scene->subject = subject.get();
    truth_scene->texture = std::move(truth_texture);
    truth_scene->camera = reader.calibration().color;
  }
  FrameSinks sinks(options, tmpl, calibration, texturer.get(), out_dir);
  if (options.export_meshes) {
    fs::create_directories(out_dir + "/meshes", ec);
    if (ec) throw Error(out_dir + "/meshes: cannot create the folder: " + ec.message());
  }
  if (options.export_foreground) {
    fs::create_directories(out_dir + "/foreground", ec);
    if (ec) throw Error(out_dir + "/foreground: cannot create the folder: " + ec.message());
  }

  // The frame loop: read -> track -> texture -> output, one after another or concurrently
  // (options.realtime; experiments/pipeline_stages.h).
  GroundTruthContext truth;
  if (result.has_ground_truth) {
    truth.sequence = sequence;
    truth.subject = subject.get();
    truth.subject_skinning = subject_skinning.get();
    truth.joint_pairs = joint_pairs;
    truth.truth_scene = truth_scene.get();
    truth.to_truth_world = world.to_calibration_world;
  }
  ShapeEstimator shape(tmpl, options.shape);
  // The joint solve minimises the tracker's energy: its pose priors apply to every frame.
  {
    std::vector<std::shared_ptr<const FittingTerm>> priors = fitter.pose_priors();
    if (options.shape_joint_limits.weight > 0.0) {
      const JointLimitOptions limits =
          ResolveJointLimits(options.shape_joint_limits, tmpl.JointNames());
      std::string why;
      if (!limits.IsValid(tmpl.num_joints(), &why)) throw Error("shape.joint_limits." + why);
      priors.push_back(std::make_shared<JointLimitTerm>(limits, tmpl.num_joints()));
    }
    shape.SetPosePriors(std::move(priors));
  }
  const std::string uncoupled =
      options.fitting.joint_coupling.weight > 0.0
          ? JointCouplingTerm::MissingJoints(options.fitting.joint_coupling, tmpl.JointNames())
          : std::string();
  if (!uncoupled.empty()) {
    result.warnings.push_back("fitting.joint_coupling: the template has no joint " + uncoupled +
                              "; those pairs are not coupled");
  }
  shape.SetDepthCamera(calibration.depth, options.fitting.out_of_view);
  if (shape.enabled() && options.shape.floor_weight > 0.0) {
    const std::optional<ScenePlane> floor =
        FirstFrameFloor(&reader, begin, end, calibration, options.preprocess);
    if (floor) shape.SetFloor(floor->normal, floor->offset);
  }
  TrackStage track(options, calibration, &preprocessor, &fitter);
  track.SetShape(&shape, &tmpl);
  PoolStage pooling(options, calibration, texturer.get());
  TextureStage texturing(options, texturer.get(), &sinks, truth_scene != nullptr, begin, end);
  OutputStage output(options, tmpl, truth, out_dir, begin, end, &result, progress);
  const double rate_hz = options.realtime.live_rate_hz > 0 ? options.realtime.live_rate_hz
                                                           : calibration.frame_rate;
  // Shape estimation swaps the template the other stages read: one thread then.
  RealtimeOptions realtime = options.realtime;
  if (shape.enabled()) realtime.concurrency = PipelineConcurrency::kSequential;
  // Ground truth off the frame loop, unless the template changes under it (shape estimation).
  const bool background_evaluation =
      options.realtime.evaluate_in_background && result.has_ground_truth && !shape.enabled();
  if (background_evaluation)
    output.StartBackgroundEvaluation(static_cast<std::size_t>(options.realtime.evaluation_queue_depth));
  result.realtime =
      RunStages(realtime, &reader, begin, end, rate_hz, &track, &pooling, &texturing, &output);
  if (background_evaluation) {
    const auto waited = std::chrono::steady_clock::now();
    result.realtime.evaluated_in_background = true;
    result.realtime.evaluated_during_loop = output.evaluation_frames_done();
    output.FinishEvaluation();
    result.realtime.evaluation_after_loop_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - waited).count();
    StageTiming evaluate;
    evaluate.name = "evaluate";
    evaluate.frames = output.evaluation_frames + output.evaluation_frames_here;
    result.realtime.evaluated_in_output_stage = output.evaluation_frames_here;
    evaluate.busy_seconds = output.evaluation_busy_seconds;
    evaluate.cpu_seconds = output.evaluation_cpu_seconds;
    result.realtime.stages.push_back(evaluate);
  }
  const int shape_calibrated_frame = track.shape_calibrated_frame;
  result.shape_calibrated_frame = shape_calibrated_frame;
  result.shape_final_frame = track.shape_final_frame;
  result.shape_detail_frame = track.shape_detail_frame;
  if (shape.enabled() && shape_calibrated_frame >= 0) AddShapeWarnings(shape, &result.warnings);
  const std::vector<Pose>& poses = output.poses;
  const std::vector<std::string>& failures = output.failures;
  const double fit_seconds = track.fit_seconds, init_seconds = track.init_seconds;
  const double quality_seconds = track.quality_seconds, iterations = output.iterations;
  const double texture_seconds = texturing.texture_seconds;
  const std::size_t stream_bytes = texturing.stream_bytes;
  const int tracked_frames = track.tracked_frames, evaluated = output.evaluated;
  result.initialisations = track.initialisations;
  result.gap_refits = track.gap_refits;
  if (result.realtime.frames_dropped > 0) {
    result.warnings.push_back("live: " + std::to_string(result.realtime.frames_dropped) + " of " +
                              std::to_string(result.realtime.frames_offered) +
                              " frames dropped (arrived while the tracker was busy)");
  }

  const int fitted = static_cast<int>(poses.size());
  if (fitted == result.failed_frames) {
    // Nothing usable: the error keeps every frame's reason (file, expected, found).
    throw Error(NoUsableFrameMessage(sequence_dir, end - begin, result.warnings, failures));
  }
  result.mean_em_iterations = iterations / fitted;
  result.fit_ms_per_frame = tracked_frames ? 1000.0 * fit_seconds / tracked_frames : 0.0;
  result.init_ms_per_initialisation =
      result.initialisations ? 1000.0 * init_seconds / result.initialisations : 0.0;
  result.quality_ms_per_frame = 1000.0 * quality_seconds / fitted;
  if (result.lost_frames > fitted / 2) {
    std::ostringstream w;
    w << "most frames are lost (" << result.lost_frames << " of " << fitted
      << "): the template does not explain the scan; check the foreground (docs/real-data.md)";
    result.warnings.push_back(w.str());
  }
  result.texture_ms_per_frame = 1000.0 * texture_seconds / fitted;
  result.stream_kbit_per_s = options.stream_estimate
                                 ? 8.0 * stream_bytes / fitted * calibration.frame_rate / 1000.0
                                 : std::numeric_limits<double>::quiet_NaN();
  if (output.quality_evaluations > 0) {
    result.mean_novel_view_psnr_db = output.psnr_sum / output.quality_evaluations;
    result.mean_novel_view_ssim = output.ssim_sum / output.quality_evaluations;
  } else {
    result.novel_view_psnr_db = result.novel_view_ssim = result.texture_coverage =
        result.mean_novel_view_psnr_db = result.mean_novel_view_ssim =
            std::numeric_limits<double>::quiet_NaN();
  }
  sinks.Finish(&result);
  result.evaluated_frames = evaluated;
  if (evaluated > 0) {
    result.mean_vertex_error_mm = output.error_sum / evaluated;
    result.mean_joint_error_mm = output.joint_sum / evaluated;
  } else {
    result.mean_vertex_error_mm = result.max_vertex_error_mm = result.mean_joint_error_mm =
        std::numeric_limits<double>::quiet_NaN();
  }
  result.lost_fraction = output.scored > 0 ? static_cast<double>(output.lost) / output.scored
                                            : std::numeric_limits<double>::quiet_NaN();

  WritePoseCsv(out_dir + "/poses.csv", tmpl, output.pose_frames, poses);

  // The files nothing else here reads (labels.png, tracked.bvh, tracked.obj / .ply) are written
  // concurrently with texture.png and tracked.glb, which embeds the texture (the same files).
  tbb::task_group side_outputs;
  if (texturer) {
    side_outputs.run([&] { WritePngFile(out_dir + "/labels.png", texturer->LabelMap()); });
  }
  if (options.export_bvh && !poses.empty()) {
    side_outputs.run(
        [&] { WriteBvh(out_dir + "/tracked.bvh", tmpl, poses, calibration.frame_rate); });
  }
  if (options.export_textured_mesh && !poses.empty()) {
    side_outputs.run([&] {
      Eigen::MatrixX3d last;
      Skinning(tmpl).Apply(poses.back(), &last);
      TexturedMeshOptions mesh;
      mesh.up = options.mesh_up_axis;
      mesh.texture_file = texturer ? "texture.png" : "";
      WriteTexturedMesh(out_dir + "/tracked.obj", tmpl, last, mesh);
      WriteTexturedMesh(out_dir + "/tracked.ply", tmpl, last, mesh);
    });
  }
  GlbTexture texture;
  try {
    if (texturer) texture.png = WritePngFile(out_dir + "/texture.png", texturer->Atlas());
    if (options.export_glb && !poses.empty()) {
      AnimatedGlbOptions glb;
      glb.exact = options.glb_exact &&
                  (options.glb_exact_max_frames == 0 ||
                   static_cast<int>(poses.size()) <= options.glb_exact_max_frames);
      if (options.glb_exact && !glb.exact) {
        result.warnings.push_back("tracked.glb: " + std::to_string(poses.size()) +
                                  " frames exceed pipeline.glb_exact_max_frames (" +
                                  std::to_string(options.glb_exact_max_frames) +
                                  "): written with glTF's plain LBS, without exact correctives");
      }
      WriteAnimatedGlb(out_dir + "/tracked.glb", tmpl, poses, calibration.frame_rate,
                       texturer ? &texture : nullptr, glb, &result.glb);
      result.glb_written = true;
    }
  } catch (...) {
    try {
      side_outputs.wait();  // not left running past this function's locals
    } catch (...) {
    }
    throw;
  }
  side_outputs.wait();  // rethrows a side output's error

  PipelineOutputInfo info;
  // Absolute, so that `artex overlay RUN` and `artex render RUN` find the recording from any
  // working directory.
  info.sequence = fs::absolute(sequence_dir).lexically_normal().string();
  // A template inside the run (shape.retrack's shape_pass/subject.glb) is named relative to it,
  // since the run is written into a temporary sibling and renamed at the end.
  const std::string prefix = out_dir + "/";
  info.template_name = template_path.empty() ? "default"
                       : template_path.rfind(prefix, 0) == 0 ? template_path.substr(prefix.size())
                                                             : template_path;
  info.texture = texturer != nullptr;
  info.world = world.estimate ? &*world.estimate : nullptr;
  WriteFramesCsv(out_dir + "/frames.csv", result);
  if (result.has_ground_truth) {
    WriteJointErrorsCsv(out_dir + "/joint_errors.csv", result, tmpl.JointNames());
  }
  if (result.has_stream) WriteStreamFramesCsv(out_dir + "/stream_frames.csv", result);
  WriteSummaryJson(out_dir + "/summary.json", result, info);
  if (shape.enabled() || result.has_ground_truth) {
    // A sequence that ended before the surface detail's frames were all kept: estimated from
    // those kept, for subject.glb (and shape.retrack's second pass) only; no frame was tracked
    // with it, so the exports above keep the template the frames were tracked with.
    const bool late_detail = shape.FinishDetail();
    ShapeRunInfo shape_info;
    shape_info.estimator = &shape;
    shape_info.subject = &tmpl;
    shape_info.global_scale = poses.empty() ? 1.0 : poses.back().scale;
    shape_info.calibrated_frame = shape_calibrated_frame;
    shape_info.final_frame = track.shape_final_frame;
    shape_info.detail_frame = track.shape_detail_frame;
    shape_info.truth = subject.get();
    AddShapeToSummary(out_dir + "/summary.json", result, shape_info);
    if (shape.enabled()) {
      WriteTemplateGlb(out_dir + "/subject.glb", late_detail ? shape.SubjectTemplate() : tmpl,
                       texturer ? &texture : nullptr);
    }
  }
  WriteMetricsJson(out_dir + "/metrics.json", result);
  WriteRealtimeJson(out_dir + "/realtime.json", result.realtime);
  return result;
}

}  // namespace

PipelineResult RunPipeline(const std::string& sequence_dir, const std::string& template_path,
                           const PipelineOptions& options, const Config& resolved_config,
                           const std::string& out_dir,
                           const std::function<void(const PipelineProgress&)>& progress) {
  // pipeline.heap_retain_mb: process-wide, kept after the run (heap_retention.h).
  RetainFreedHeap(options.realtime.heap_retain_mb);
  // pipeline.heap_arenas: the same, for the threads the run starts (heap_retention.h).
  LimitHeapArenas(options.realtime.heap_arenas);
  // pipeline.blas_threads: process-wide, kept after the run (blas_threads.h).
  LimitBlasThreads(options.realtime.blas_threads);
  // pipeline.threads: the parallel loops' threads for this run (restored after it).
  std::unique_ptr<tbb::global_control> limit;
  const int opencv_threads = cv::getNumThreads();
  struct RestoreOpenCv {
    int threads;
    bool set;
    ~RestoreOpenCv() {
      if (set) cv::setNumThreads(threads);
    }
  } restore{opencv_threads, options.realtime.threads > 0};
  if (options.realtime.threads > 0) {
    limit = std::make_unique<tbb::global_control>(
        tbb::global_control::max_allowed_parallelism,
        static_cast<std::size_t>(options.realtime.threads));
    cv::setNumThreads(options.realtime.threads);
  }
  if (!options.shape.retrack || options.shape.mode == ShapeMode::kFixed) {
    return RunOnePass(sequence_dir, template_path, options, resolved_config, out_dir, progress);
  }
  // Pass 1: calibrate the subject's shape, fitting only.
  std::string why;
  if (!options.IsValid(&why)) throw Error(why);
  PipelineOptions first = options;
  first.texture = false;
  first.export_glb = first.export_bvh = first.export_textured_mesh = false;
  first.export_meshes = first.export_foreground = first.export_atlases = false;
  first.atlas_frames.clear();
  first.stream_path.clear();
  const std::string shape_dir = out_dir + "/shape_pass";
  const PipelineResult calibration =
      RunOnePass(sequence_dir, template_path, first, resolved_config, shape_dir, progress);
  // Pass 2: the whole sequence with the subject's template, its shape fixed.
  PipelineOptions second = options;
  second.shape.mode = ShapeMode::kFixed;
  const bool calibrated = calibration.shape_calibrated_frame >= 0;
  PipelineResult result =
      RunOnePass(sequence_dir, calibrated ? shape_dir + "/subject.glb" : template_path, second,
                 resolved_config, out_dir, progress);
  result.shape_calibrated_frame = calibration.shape_calibrated_frame;
  result.shape_final_frame = calibration.shape_final_frame;
  // The first pass's doubts about the shape the second pass used.
  std::vector<std::string> doubts;
  std::copy_if(calibration.warnings.begin(), calibration.warnings.end(),
               std::back_inserter(doubts),
               [](const std::string& w) { return w.rfind(kShapeWarningPrefix, 0) == 0; });
  result.warnings.insert(result.warnings.begin(), doubts.begin(), doubts.end());
  result.warnings.insert(
      result.warnings.begin(),
      calibrated ? "shape.retrack: tracked twice; the second pass used the subject's template "
                   "calibrated after frame " +
                       std::to_string(calibration.shape_calibrated_frame) +
                       " of the first (shape_pass/ of the run)"
                 : "shape.retrack: the first pass never calibrated the shape (too few accepted "
                   "frames); the second pass used the given template");
  return result;
}

}  // namespace artex
