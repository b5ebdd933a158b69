#include "experiments/pipeline.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <memory>
#include <nanoflann.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <optional>
#include <sstream>

#include "experiments/pipeline_output.h"
#include "experiments/pose_csv.h"
#include "experiments/shape_output.h"
#include "experiments/stream_sinks.h"
#include "experiments/texture_evaluation.h"
#include "models/error.h"
#include "models/mesh_export.h"
#include "models/normals.h"
#include "models/skinning.h"
#include "models/template_generator.h"
#include "models/template_io.h"
#include "sensors/bvh_export.h"
#include "sensors/calibration.h"
#include "sensors/frame_source.h"
#include "sensors/scene_segmentation.h"
#include "sensors/sequence.h"
#include "solvers/particle_predictor.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double Since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

// nanoflann adaptor over an N x 3 matrix.
struct PointCloud {
  const Eigen::MatrixX3d* points;
  size_t kdtree_get_point_count() const { return static_cast<size_t>(points->rows()); }
  double kdtree_get_pt(size_t i, size_t d) const {
    return (*points)(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(d));
  }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
};
using KdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, PointCloud>,
                                                   PointCloud, 3>;

// Distance of every tracked vertex to the ground-truth surface: to the nearest subject vertex,
// refined to the distance to that vertex's tangent plane (never more than the vertex distance).
void SurfaceErrors(const Eigen::MatrixX3d& tracked, const Eigen::MatrixX3d& truth,
                   const Eigen::MatrixX3d& truth_normals, double* mean, double* max) {
  PointCloud cloud{&truth};
  KdTree tree(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tree.buildIndex();
  double sum = 0.0, worst = 0.0;
  for (Eigen::Index t = 0; t < tracked.rows(); ++t) {
    const Eigen::Vector3d p = tracked.row(t);
    unsigned int index = 0;
    double d2 = 0.0;
    tree.knnSearch(p.data(), 1, &index, &d2);
    const Eigen::Vector3d q = truth.row(static_cast<Eigen::Index>(index));
    const Eigen::Vector3d n = truth_normals.row(static_cast<Eigen::Index>(index));
    const double plane = n.squaredNorm() > 0.5 ? std::abs(n.dot(p - q)) : std::sqrt(d2);
    const double d = std::min(std::sqrt(d2), plane);
    sum += d;
    worst = std::max(worst, d);
  }
  *mean = tracked.rows() ? sum / tracked.rows() : 0.0;
  *max = worst;
}

// Writes `image` as a PNG and returns the encoded bytes.
std::vector<unsigned char> WritePng(const std::string& path, const cv::Mat& image) {
  std::vector<unsigned char> bytes;
  if (!cv::imencode(".png", image, bytes)) throw Error(path + ": PNG encoding failed");
  WriteFileAtomically(path, std::string(bytes.begin(), bytes.end()));
  return bytes;
}

// Bytes to send the texels that changed in the last frame: their bounding box of the atlas
// as a JPEG (quality 90); 0 when nothing changed.
std::size_t TextureUpdateBytes(const Texturer& texturer) {
  const cv::Mat patch = texturer.ChangedPatch();
  if (patch.empty()) return 0;
  std::vector<unsigned char> bytes;
  cv::imencode(".jpg", patch, bytes, {cv::IMWRITE_JPEG_QUALITY, 90});
  return bytes.size();
}

// Rows of `points` mapped by `t`.
Eigen::MatrixX3d TransformRows(const Eigen::Isometry3d& t, const Eigen::MatrixX3d& points) {
  Eigen::MatrixX3d out = (points * t.linear().transpose()).rowwise() + t.translation().transpose();
  return out;
}

// The calibration tracking uses: the sequence's, or with the world frame estimated from the
// first readable frame (floor plane, gravity or the camera convention).
struct FrameWorld {
  Calibration calibration;
  std::optional<WorldFrameEstimate> estimate;
  Eigen::Isometry3d to_calibration_world = Eigen::Isometry3d::Identity();  // tracking -> sequence
};

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
  std::string warning;
  int i = begin;
  while (i < end && !source->ReadFrame(i, &frame, &warning)) ++i;
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

PipelineResult RunPipeline(const std::string& sequence_dir, const std::string& template_path,
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
  Template tmpl = template_path.empty() ? GenerateTemplate() : ReadTemplateGlb(template_path);
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) throw Error(out_dir + ": cannot create the output folder: " + ec.message());
  WriteFileAtomically(out_dir + "/config.yaml", resolved_config.ToYaml() + "\n");
  WriteCalibration(calibration, out_dir + "/calibration.yaml");

  Preprocessor preprocessor(calibration, options.preprocess);
  if (background.empty()) {
    preprocessor.TrainWithoutBackground();
    if (world.estimate) preprocessor.SetScenePlanes(world.estimate->planes);
  } else {
    preprocessor.Train(background);
  }
  EMFitter fitter(tmpl, options.fitting);
  const Skinning& skinning = fitter.skinning();
  std::unique_ptr<Texturer> texturer;
  if (options.texture) texturer = std::make_unique<Texturer>(tmpl, options.texturing);

  // Ground truth: the subject's mesh and skeleton (for surface and joint errors).
  result.has_ground_truth = sequence && sequence->has_ground_truth() &&
                            !sequence->GroundTruthSubjectPath().empty() &&
                            fs::exists(sequence->GroundTruthSubjectPath());
  std::unique_ptr<Template> subject;
  std::unique_ptr<Skinning> subject_skinning;
  std::vector<std::pair<int, int>> joint_pairs;  // (tracked joint, subject joint) by name
  if (result.has_ground_truth) {
    subject = std::make_unique<Template>(ReadTemplateGlb(sequence->GroundTruthSubjectPath()));
    subject_skinning = std::make_unique<Skinning>(*subject);
    for (int j = 0; j < tmpl.num_joints(); ++j) {
      const int s = subject->FindJoint(tmpl.joints[j].name);
      if (s >= 0) joint_pairs.emplace_back(j, s);
    }
  }
  // Novel-view texture quality needs the true texture as well.
  std::unique_ptr<TruthScene> truth_scene;
  if (result.has_ground_truth && texturer && options.texture_quality_every > 0 &&
      subject->has_uvs() && !sequence->GroundTruthTexturePath().empty()) {
    truth_scene = std::make_unique<TruthScene>();
    truth_scene->subject = subject.get();
    truth_scene->texture = cv::imread(sequence->GroundTruthTexturePath(), cv::IMREAD_COLOR);
    truth_scene->camera = reader.calibration().color;
    if (truth_scene->texture.empty()) truth_scene.reset();
  }
  FrameSinks sinks(options, tmpl, calibration, texturer.get(), out_dir);
  ShapeEstimator shape(tmpl, options.shape);
  shape.SetCameraCenter(calibration.depth.world_to_camera.inverse().translation());
  int shape_calibrated_frame = -1;
  double quality_psnr_sum = 0.0, quality_ssim_sum = 0.0;
  int quality_evaluations = 0;

  std::vector<Pose> poses;
  std::vector<int> pose_frames;
  Frame frame;
  Scan scan;
  Eigen::MatrixX3d posed, colours;
  std::size_t stream_bytes = 0;
  const auto start = Clock::now();
  double fit_seconds = 0.0, texture_seconds = 0.0, iterations = 0.0;
  double init_seconds = 0.0, quality_seconds = 0.0;
  int lost = 0, evaluated = 0, scored = 0, tracked_frames = 0;
  bool need_init = true;
  int doubtful_run = 0;  // consecutive doubtful frames
  double error_sum = 0.0, joint_sum = 0.0;
  std::vector<std::string> failures;  // why each failed fit failed
  if (options.export_meshes) {
    fs::create_directories(out_dir + "/meshes", ec);
    if (ec) throw Error(out_dir + "/meshes: cannot create the folder: " + ec.message());
  }
  if (options.export_foreground) {
    fs::create_directories(out_dir + "/foreground", ec);
    if (ec) throw Error(out_dir + "/foreground: cannot create the folder: " + ec.message());
  }
  for (int i = begin; i < end; ++i) {
    FrameRecord record;
    record.frame = i;
    std::string warning;
    if (!reader.ReadFrame(i, &frame, &warning)) {
      record.skipped = true;
      ++result.skipped_frames;
      result.warnings.push_back(warning);
      result.frames.push_back(record);
      continue;
    }
    const auto t_pre = Clock::now();
    PreprocessStats stats;
    preprocessor.Process(frame, &scan, &stats);
    record.preprocess_seconds = Since(t_pre);
    record.scan_points = scan.size();

    record.segmentation = stats.segmentation;
    if (options.export_foreground) {
      char name[64];
      std::snprintf(name, sizeof(name), "/foreground/%06d.png", i);
      WritePng(out_dir + name, preprocessor.foreground_mask());
    }

    // Fit: the multi-hypothesis initialisation on the first frame and after a lost one.
    const bool enough_points = scan.size() >= options.fitting.min_scan_points;
    const auto initialise = [&](FrameRecord* r) {
      const InitResult init = InitializeFit(&fitter, scan, calibration.depth, options.initializer);
      r->fit = init.fit;
      r->reinitialised = true;
      r->init_seconds = init.total_seconds;
      r->init_report = init.BriefReport();
      ++result.initialisations;
      init_seconds += init.total_seconds;
    };
    const auto evaluate = [&](FrameRecord* r) {
      skinning.Apply(fitter.pose(), &posed);
      if (r->fit.ok()) {
        r->quality =
            EvaluateFitQuality(posed, tmpl.triangles, scan, calibration.depth, options.quality);
      } else {
        r->quality = FitQuality();  // a failed fit is lost, whatever its kept pose shows
        r->quality.label = FitQualityLabel::kLost;
      }
      quality_seconds += r->quality.seconds;
    };
    if (need_init && enough_points) {
      initialise(&record);
    } else {
      record.fit = TrackFrame(&fitter, scan, calibration.depth, options.quality);
      fit_seconds += record.fit.total_seconds;
      ++tracked_frames;
    }
    evaluate(&record);
    Pose tracked_pose;
    bool keep_tracked = false;
    // Tracking that loses the frame (or doubts it, by option) is followed by a
    // re-initialisation in the same frame; the better of the two by quality score is kept.
    const FitQualityLabel label = record.quality.label;
    doubtful_run = label == FitQualityLabel::kDoubtful ? doubtful_run + 1 : 0;
    const bool doubted_long = options.reinitialise_after_doubtful > 0 &&
                              doubtful_run >= options.reinitialise_after_doubtful;
    if (!record.reinitialised && record.fit.ok() && enough_points &&
        (label == FitQualityLabel::kLost ||
         (label == FitQualityLabel::kDoubtful &&
          (doubted_long || options.reinitialise_on == ReinitialiseOn::kDoubtful)))) {
      doubtful_run = 0;
      tracked_pose = fitter.pose();
      const Scan tracked_scan = scan;
      FrameRecord retry = record;
      fitter.Reset(/*keep_scale=*/true);
      if (label == FitQualityLabel::kLost) {
        // The tracked component may be the wrong one: choose the subject again.
        preprocessor.ResetSubject();
        preprocessor.Process(frame, &scan, &stats);
        retry.scan_points = scan.size();
        retry.segmentation = stats.segmentation;
      }
      if (scan.size() >= options.fitting.min_scan_points) {
        initialise(&retry);
        evaluate(&retry);
      }
      if (retry.reinitialised && retry.fit.ok() && retry.quality.score > record.quality.score) {
        record = retry;
      } else {
        // The tracked fit stays (its scan too); a lost one is re-initialised next frame.
        scan = tracked_scan;
        fitter.Reset(/*keep_scale=*/true);
        if (label != FitQualityLabel::kLost) fitter.AcceptPose(scan, tracked_pose);
        keep_tracked = true;
        record.init_seconds = retry.init_seconds;
        record.init_report = retry.init_report + " (not better than tracking: kept)";
      }
    }
    if (!record.fit.ok()) {
      ++result.failed_frames;
      failures.push_back(FailedFitReason(i, record.fit, options.fitting.min_scan_points));
    }
    iterations += record.fit.iterations;
    const Pose frame_pose = keep_tracked ? tracked_pose : fitter.pose();
    // `posed` is the evaluated fit's (evaluate skins fitter.pose()), unless the tracked fit
    // was kept after a re-initialisation was tried.
    if (keep_tracked) skinning.Apply(frame_pose, &posed);
    poses.push_back(frame_pose);
    pose_frames.push_back(i);
    stream_bytes += sizeof(float) * frame_pose.num_parameters();
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
    const bool lost_frame = record.quality.label == FitQualityLabel::kLost;
    // A lost frame's pose is not texture: it would paint the room onto the body.
    const bool texture_frame = !lost_frame && (options.texture_doubtful_frames ||
                                               record.quality.label == FitQualityLabel::kGood);

    if (texturer && texture_frame) {
      record.texture = texturer->AddFrame(i, frame.color, calibration.color, posed);
      texture_seconds += record.texture.seconds_total;
      stream_bytes += TextureUpdateBytes(*texturer);
      if (options.colour_term) {
        std::vector<uint8_t> valid;
        texturer->VertexColors(&colours, &valid);
        int count = 0;
        Eigen::Vector3d mean = Eigen::Vector3d::Zero();
        for (int v = 0; v < colours.rows(); ++v) {
          if (!valid[v]) continue;
          mean += colours.row(v).transpose();
          ++count;
        }
        // The colour term starts once the texture covers most of the body; vertices without
        // texture take the mean colour (neutral for the colour distance on average).
        if (count > 0.9 * colours.rows()) {
          mean /= count;
          for (int v = 0; v < colours.rows(); ++v)
            if (!valid[v]) colours.row(v) = mean.transpose();
          fitter.SetTemplateColors(colours);
        }
      }
      for (int f : options.atlas_frames) {
        if (f == i) {
          char name[64];
          std::snprintf(name, sizeof(name), "/texture_%06d.png", i);
          WritePng(out_dir + name, texturer->Atlas());
        }
      }
    }
    sinks.AddFrame(i, frame_pose);
    if (options.export_meshes) {
      char name[64];
      std::snprintf(name, sizeof(name), "/meshes/%06d.ply", i);
      WritePosedMesh(out_dir + name, ToUpAxis(posed, options.mesh_up_axis), tmpl.triangles);
    }
    if (result.has_ground_truth) {
      const GroundTruthFrame truth = sequence->ReadGroundTruth(i);
      Eigen::MatrixX3d truth_normals;
      ComputeVertexNormals(truth.vertices, subject->triangles, &truth_normals);
      double mean = 0.0, max = 0.0;
      const Eigen::MatrixX3d tracked_in_truth = TransformRows(world.to_calibration_world, posed);
      SurfaceErrors(tracked_in_truth, truth.vertices, truth_normals, &mean, &max);
      record.mean_vertex_error_mm = 1000.0 * mean;
      record.max_vertex_error_mm = 1000.0 * max;
      Eigen::MatrixX3d ours, theirs;
      skinning.PosedJointCenters(frame_pose, &ours);
      ours = TransformRows(world.to_calibration_world, ours);
      subject_skinning->PosedJointCenters(truth.pose, &theirs);
      double joint = 0.0;
      for (const auto& [a, b] : joint_pairs) joint += (ours.row(a) - theirs.row(b)).norm();
      record.mean_joint_error_mm = joint_pairs.empty() ? 0.0 : 1000.0 * joint / joint_pairs.size();
      // A failed fit's kept pose is no measurement: it counts as lost and stays out of the
      // error averages (issue 20: all-failed runs reported a small error).
      if (record.fit.ok()) {
        error_sum += record.mean_vertex_error_mm;
        joint_sum += record.mean_joint_error_mm;
        result.max_vertex_error_mm =
            std::max(result.max_vertex_error_mm, record.max_vertex_error_mm);
        ++evaluated;
      }
      lost += record.mean_vertex_error_mm > options.lost_threshold_mm || !record.fit.ok();
      ++scored;
      const int every = options.texture_quality_every;
      if (truth_scene && ((i - begin + 1) % every == 0 || i == end - 1)) {
        truth_scene->vertices = truth.vertices;
        record.texture_quality =
            EvaluateNovelViews(tmpl, tracked_in_truth, texturer->Atlas(),
                               texturer->triangle_frames(), *truth_scene, options.held_out);
        const NovelViewQuality& q = record.texture_quality;
        if (std::isfinite(q.psnr_db) && std::isfinite(q.ssim)) {
          result.novel_view_psnr_db = q.psnr_db;
          result.novel_view_ssim = q.ssim;
          result.texture_coverage = q.coverage;
          quality_psnr_sum += q.psnr_db;
          quality_ssim_sum += q.ssim;
          ++quality_evaluations;
        }
      }
    } else {
      record.mean_vertex_error_mm = record.max_vertex_error_mm = record.mean_joint_error_mm =
          std::numeric_limits<double>::quiet_NaN();
    }
    // Subject shape (section shape): accepted frames feed the calibration; once solved (or
    // refined) the fitter tracks with the subject's template, as do the texturer and exports.
    if (shape.enabled() && record.fit.ok() && !lost_frame &&
        shape.AddFrame(scan, frame_pose,
                       !fitter.ScaleIsFree() || fitter.scale_samples() >=
                                                    options.fitting.scale_estimation_frames)) {
      tmpl = shape.SubjectTemplate();
      fitter.SetRestShape(tmpl);
      if (shape_calibrated_frame < 0) shape_calibrated_frame = i;
    }
    if (lost_frame) {
      // Re-initialise on the next frame with enough points; the scale estimate and the
      // texture survive (the same person), the tracked subject component does not.
      need_init = true;
      fitter.Reset(/*keep_scale=*/true);
      preprocessor.ResetSubject();
    } else {
      need_init = false;
    }
    result.frames.push_back(record);
    if (progress) {
      PipelineProgress p;
      p.done = i - begin + 1;
      p.total = end - begin;
      p.frames_per_second = p.done / std::max(1e-9, Since(start));
      p.last = &result.frames.back();
      progress(p);
    }
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
  result.stream_kbit_per_s = 8.0 * stream_bytes / fitted * calibration.frame_rate / 1000.0;
  if (quality_evaluations > 0) {
    result.mean_novel_view_psnr_db = quality_psnr_sum / quality_evaluations;
    result.mean_novel_view_ssim = quality_ssim_sum / quality_evaluations;
  } else {
    result.novel_view_psnr_db = result.novel_view_ssim = result.texture_coverage =
        result.mean_novel_view_psnr_db = result.mean_novel_view_ssim =
            std::numeric_limits<double>::quiet_NaN();
  }
  sinks.Finish(&result);
  result.evaluated_frames = evaluated;
  if (evaluated > 0) {
    result.mean_vertex_error_mm = error_sum / evaluated;
    result.mean_joint_error_mm = joint_sum / evaluated;
  } else {
    result.mean_vertex_error_mm = result.max_vertex_error_mm = result.mean_joint_error_mm =
        std::numeric_limits<double>::quiet_NaN();
  }
  result.lost_fraction =
      scored > 0 ? static_cast<double>(lost) / scored : std::numeric_limits<double>::quiet_NaN();

  WritePoseCsv(out_dir + "/poses.csv", tmpl, pose_frames, poses);

  GlbTexture texture;
  if (texturer) {
    texture.png = WritePng(out_dir + "/texture.png", texturer->Atlas());
    WritePng(out_dir + "/labels.png", texturer->LabelMap());
  }
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
  if (options.export_bvh && !poses.empty()) {
    WriteBvh(out_dir + "/tracked.bvh", tmpl, poses, calibration.frame_rate);
  }
  if (options.export_textured_mesh && !poses.empty()) {
    Eigen::MatrixX3d last;
    Skinning(tmpl).Apply(poses.back(), &last);
    TexturedMeshOptions mesh;
    mesh.up = options.mesh_up_axis;
    mesh.texture_file = texturer ? "texture.png" : "";
    WriteTexturedMesh(out_dir + "/tracked.obj", tmpl, last, mesh);
    WriteTexturedMesh(out_dir + "/tracked.ply", tmpl, last, mesh);
  }

  PipelineOutputInfo info;
  // Absolute, so that `artex overlay RUN` and `artex render RUN` find the recording from any
  // working directory.
  info.sequence = fs::absolute(sequence_dir).lexically_normal().string();
  info.template_name = template_path.empty() ? "default" : template_path;
  info.texture = texturer != nullptr;
  info.world = world.estimate ? &*world.estimate : nullptr;
  WriteFramesCsv(out_dir + "/frames.csv", result);
  WriteSummaryJson(out_dir + "/summary.json", result, info);
  if (shape.enabled() || result.has_ground_truth) {
    ShapeRunInfo shape_info;
    shape_info.estimator = &shape;
    shape_info.subject = &tmpl;
    shape_info.global_scale = poses.empty() ? 1.0 : poses.back().scale;
    shape_info.calibrated_frame = shape_calibrated_frame;
    shape_info.truth = subject.get();
    AddShapeToSummary(out_dir + "/summary.json", result, shape_info);
    if (shape.enabled()) WriteTemplateGlb(out_dir + "/subject.glb", tmpl, texturer ? &texture : nullptr);
  }
  WriteMetricsJson(out_dir + "/metrics.json", result);
  return result;
}

}  // namespace artex
