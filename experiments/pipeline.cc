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

#include "experiments/pose_csv.h"
#include "models/error.h"
#include "models/mesh_export.h"
#include "models/normals.h"
#include "models/skinning.h"
#include "models/template_generator.h"
#include "models/template_io.h"
#include "sensors/calibration.h"
#include "sensors/scene_segmentation.h"
#include "sensors/sequence.h"

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

std::string Fixed(double v, int digits = 6) {
  if (!std::isfinite(v)) return "nan";
  std::ostringstream s;
  s << std::setprecision(digits) << v;
  return s.str();
}

void WriteJson(const std::string& path, const nlohmann::json& j) {
  WriteFileAtomically(path, j.dump(2) + "\n");
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

}  // namespace

PipelineResult RunPipeline(const std::string& sequence_dir, const std::string& template_path,
                           const PipelineOptions& options, const Config& resolved_config,
                           const std::string& out_dir,
                           const std::function<void(const PipelineProgress&)>& progress) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(why);
  SequenceReader reader(sequence_dir);
  const int total_frames = reader.num_frames();
  const int begin = std::min(options.first_frame, total_frames);
  const int end =
      options.max_frames > 0 ? std::min(total_frames, begin + options.max_frames) : total_frames;
  PipelineResult result;
  const std::vector<cv::Mat> background = reader.ReadBackgroundFrames();
  const FrameWorld world = ChooseWorldFrame(&reader, begin, end, options.preprocess,
                                            std::optional<Eigen::Vector3d>(), &result);
  const Calibration& calibration = world.calibration;
  const Template tmpl = template_path.empty() ? GenerateTemplate() : ReadTemplateGlb(template_path);
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
  result.has_ground_truth = reader.has_ground_truth() && !reader.GroundTruthSubjectPath().empty() &&
                            fs::exists(reader.GroundTruthSubjectPath());
  std::unique_ptr<Template> subject;
  std::unique_ptr<Skinning> subject_skinning;
  std::vector<std::pair<int, int>> joint_pairs;  // (tracked joint, subject joint) by name
  if (result.has_ground_truth) {
    subject = std::make_unique<Template>(ReadTemplateGlb(reader.GroundTruthSubjectPath()));
    subject_skinning = std::make_unique<Skinning>(*subject);
    for (int j = 0; j < tmpl.num_joints(); ++j) {
      const int s = subject->FindJoint(tmpl.joints[j].name);
      if (s >= 0) joint_pairs.emplace_back(j, s);
    }
  }

  std::vector<Pose> poses;
  std::vector<int> pose_frames;
  Frame frame;
  Scan scan;
  Eigen::MatrixX3d posed, colours;
  std::size_t stream_bytes = 0;
  const auto start = Clock::now();
  double fit_seconds = 0.0, texture_seconds = 0.0, iterations = 0.0;
  int lost = 0, evaluated = 0;
  double error_sum = 0.0, joint_sum = 0.0;
  if (options.export_meshes) {
    fs::create_directories(out_dir + "/meshes", ec);
    if (ec) throw Error(out_dir + "/meshes: cannot create the folder: " + ec.message());
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

    record.fit = fitter.FitFrame(scan);
    fit_seconds += record.fit.total_seconds;
    iterations += record.fit.iterations;
    skinning.Apply(fitter.pose(), &posed);
    poses.push_back(fitter.pose());
    pose_frames.push_back(i);
    stream_bytes += sizeof(float) * fitter.pose().num_parameters();

    if (texturer) {
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
    if (options.export_meshes) {
      char name[64];
      std::snprintf(name, sizeof(name), "/meshes/%06d.ply", i);
      WritePosedMesh(out_dir + name, posed, tmpl.triangles);
    }
    if (result.has_ground_truth) {
      const GroundTruthFrame truth = reader.ReadGroundTruth(i);
      Eigen::MatrixX3d truth_normals;
      ComputeVertexNormals(truth.vertices, subject->triangles, &truth_normals);
      double mean = 0.0, max = 0.0;
      const Eigen::MatrixX3d tracked_in_truth = TransformRows(world.to_calibration_world, posed);
      SurfaceErrors(tracked_in_truth, truth.vertices, truth_normals, &mean, &max);
      record.mean_vertex_error_mm = 1000.0 * mean;
      record.max_vertex_error_mm = 1000.0 * max;
      Eigen::MatrixX3d ours, theirs;
      skinning.PosedJointCenters(fitter.pose(), &ours);
      ours = TransformRows(world.to_calibration_world, ours);
      subject_skinning->PosedJointCenters(truth.pose, &theirs);
      double joint = 0.0;
      for (const auto& [a, b] : joint_pairs) joint += (ours.row(a) - theirs.row(b)).norm();
      record.mean_joint_error_mm = joint_pairs.empty() ? 0.0 : 1000.0 * joint / joint_pairs.size();
      error_sum += record.mean_vertex_error_mm;
      joint_sum += record.mean_joint_error_mm;
      result.max_vertex_error_mm = std::max(result.max_vertex_error_mm, record.max_vertex_error_mm);
      lost += record.mean_vertex_error_mm > options.lost_threshold_mm;
      ++evaluated;
    } else {
      record.mean_vertex_error_mm = record.max_vertex_error_mm = record.mean_joint_error_mm =
          std::numeric_limits<double>::quiet_NaN();
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
  if (fitted == 0) throw Error(sequence_dir + ": no usable frame in the sequence");
  result.mean_em_iterations = iterations / fitted;
  result.fit_ms_per_frame = 1000.0 * fit_seconds / fitted;
  result.texture_ms_per_frame = 1000.0 * texture_seconds / fitted;
  result.stream_kbit_per_s = 8.0 * stream_bytes / fitted * calibration.frame_rate / 1000.0;
  if (evaluated > 0) {
    result.mean_vertex_error_mm = error_sum / evaluated;
    result.mean_joint_error_mm = joint_sum / evaluated;
    result.lost_fraction = static_cast<double>(lost) / evaluated;
  } else {
    result.mean_vertex_error_mm = result.max_vertex_error_mm = result.mean_joint_error_mm =
        result.lost_fraction = std::numeric_limits<double>::quiet_NaN();
  }

  WritePoseCsv(out_dir + "/poses.csv", tmpl, pose_frames, poses);

  // frames.csv: per-frame metrics and per-stage timings.
  std::ostringstream frames_csv;
  frames_csv << "frame,skipped,scan_points,em_iterations,termination,initial_cost,final_cost,"
                "too_few_points,non_finite,diverged,scale,preprocess_ms,estep_ms,mstep_ms,fit_ms,"
                "texture_ms,texture_mrf_ms,texture_energy,texture_lower_bound,pool_size,"
                "seam_edges,changed_triangles,seam_rms_before,seam_rms_after,"
                "mean_vertex_error_mm,max_vertex_error_mm,mean_joint_error_mm\n";
  nlohmann::json summary_frames = nlohmann::json::array();
  for (const FrameRecord& r : result.frames) {
    frames_csv << r.frame << "," << r.skipped << "," << r.scan_points << "," << r.fit.iterations
               << "," << FrameTerminationName(r.fit.termination) << "," << Fixed(r.fit.initial_cost)
               << "," << Fixed(r.fit.final_cost) << "," << r.fit.too_few_points << ","
               << r.fit.non_finite << "," << r.fit.diverged << "," << Fixed(r.fit.scale) << ","
               << Fixed(1000 * r.preprocess_seconds) << "," << Fixed(1000 * r.fit.estep_seconds)
               << "," << Fixed(1000 * r.fit.mstep_seconds) << ","
               << Fixed(1000 * r.fit.total_seconds) << "," << Fixed(1000 * r.texture.seconds_total)
               << "," << Fixed(1000 * r.texture.seconds_mrf) << "," << Fixed(r.texture.energy)
               << "," << Fixed(r.texture.lower_bound) << "," << r.texture.pool_size << ","
               << r.texture.seam_edges << "," << r.texture.changed_triangles << ","
               << Fixed(r.texture.seam_rms_before) << "," << Fixed(r.texture.seam_rms_after) << ","
               << Fixed(r.mean_vertex_error_mm) << "," << Fixed(r.max_vertex_error_mm) << ","
               << Fixed(r.mean_joint_error_mm) << "\n";
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
    if (texturer) {
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
    summary_frames.push_back(f);
  }
  WriteFileAtomically(out_dir + "/frames.csv", frames_csv.str());
  nlohmann::json world_json = {{"source", "calibration"}};
  if (world.estimate) {
    const WorldFrameEstimate& e = *world.estimate;
    nlohmann::json planes = nlohmann::json::array();
    for (const ScenePlane& p : e.planes) {
      planes.push_back({{"kind", PlaneKindName(p.kind)},
                        {"normal", {p.normal.x(), p.normal.y(), p.normal.z()}},
                        {"offset", p.offset},
                        {"inlier_fraction", p.inlier_fraction},
                        {"extent", {p.extent[0], p.extent[1]}}});
    }
    world_json = {{"source", WorldFrameSourceName(e.source)},
                  {"up_camera", {e.up_camera.x(), e.up_camera.y(), e.up_camera.z()}},
                  {"camera_height", e.camera_height},
                  {"camera_pitch_deg", e.camera_pitch_deg},
                  {"camera_roll_deg", e.camera_roll_deg},
                  {"planes", planes}};
  }
  WriteJson(out_dir + "/summary.json",
            {{"sequence", sequence_dir},
             {"world_frame", world_json},
             {"template", template_path.empty() ? "default" : template_path},
             {"frames", summary_frames},
             {"warnings", result.warnings}});
  const auto number = [](double v) {
    return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
  };
  WriteJson(out_dir + "/metrics.json",
            {{"frames", static_cast<int>(result.frames.size())},
             {"skipped_frames", result.skipped_frames},
             {"has_ground_truth", result.has_ground_truth},
             {"mean_vertex_error_mm", number(result.mean_vertex_error_mm)},
             {"max_vertex_error_mm", number(result.max_vertex_error_mm)},
             {"mean_joint_error_mm", number(result.mean_joint_error_mm)},
             {"lost_fraction", number(result.lost_fraction)},
             {"mean_em_iterations", result.mean_em_iterations},
             {"fit_ms_per_frame", result.fit_ms_per_frame},
             {"texture_ms_per_frame", result.texture_ms_per_frame},
             {"stream_kbit_per_s", result.stream_kbit_per_s}});
  if (texturer) {
    GlbTexture texture;
    texture.png = WritePng(out_dir + "/texture.png", texturer->Atlas());
    WritePng(out_dir + "/labels.png", texturer->LabelMap());
    if (options.export_glb) {
      WriteAnimatedGlb(out_dir + "/tracked.glb", tmpl, poses, calibration.frame_rate, &texture);
    }
  } else if (options.export_glb) {
    WriteAnimatedGlb(out_dir + "/tracked.glb", tmpl, poses, calibration.frame_rate);
  }
  return result;
}

}  // namespace artex
