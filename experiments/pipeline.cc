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
#include <sstream>

#include <nanoflann.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "experiments/pose_csv.h"
#include "models/error.h"
#include "models/mesh_export.h"
#include "models/normals.h"
#include "models/skinning.h"
#include "models/template_generator.h"
#include "models/template_io.h"
#include "sensors/frame_source.h"
#include "sensors/sequence.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double Since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// nanoflann adaptor over an N x 3 matrix.
struct PointCloud {
  const Eigen::MatrixX3d* points;
  size_t kdtree_get_point_count() const { return static_cast<size_t>(points->rows()); }
  double kdtree_get_pt(size_t i, size_t d) const { return (*points)(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(d)); }
  template <class Box>
  bool kdtree_get_bbox(Box&) const { return false; }
};
using KdTree = nanoflann::KDTreeSingleIndexAdaptor<
    nanoflann::L2_Simple_Adaptor<double, PointCloud>, PointCloud, 3>;

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
  const Calibration& calibration = reader.calibration();
  const Template tmpl = template_path.empty() ? GenerateTemplate() : ReadTemplateGlb(template_path);
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) throw Error(out_dir + ": cannot create the output folder: " + ec.message());
  WriteFileAtomically(out_dir + "/config.yaml", resolved_config.ToYaml() + "\n");

  Preprocessor preprocessor(calibration, options.preprocess);
  const std::vector<cv::Mat> background = reader.ReadBackgroundFrames();
  if (background.empty()) {
    preprocessor.TrainWithoutBackground();
  } else {
    preprocessor.Train(background);
  }
  EMFitter fitter(tmpl, options.fitting);
  const Skinning& skinning = fitter.skinning();
  std::unique_ptr<Texturer> texturer;
  if (options.texture) texturer = std::make_unique<Texturer>(tmpl, options.texturing);

  // Ground truth: the subject's mesh and skeleton (for surface and joint errors).
  PipelineResult result;
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

  const int total_frames = reader.num_frames();
  const int begin = std::min(options.first_frame, total_frames);
  const int end = options.max_frames > 0 ? std::min(total_frames, begin + options.max_frames)
                                         : total_frames;
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
      const GroundTruthFrame truth = sequence->ReadGroundTruth(i);
      Eigen::MatrixX3d truth_normals;
      ComputeVertexNormals(truth.vertices, subject->triangles, &truth_normals);
      double mean = 0.0, max = 0.0;
      SurfaceErrors(posed, truth.vertices, truth_normals, &mean, &max);
      record.mean_vertex_error_mm = 1000.0 * mean;
      record.max_vertex_error_mm = 1000.0 * max;
      Eigen::MatrixX3d ours, theirs;
      skinning.PosedJointCenters(fitter.pose(), &ours);
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
                {"flags", {{"too_few_points", r.fit.too_few_points},
                           {"non_finite", r.fit.non_finite},
                           {"diverged", r.fit.diverged}}},
                {"seconds", {{"preprocess", r.preprocess_seconds},
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
                      {"seconds", {{"pool", r.texture.seconds_pool},
                                   {"mrf", r.texture.seconds_mrf},
                                   {"sampling", r.texture.seconds_sampling},
                                   {"levelling", r.texture.seconds_levelling},
                                   {"total", r.texture.seconds_total}}}};
    }
    summary_frames.push_back(f);
  }
  WriteFileAtomically(out_dir + "/frames.csv", frames_csv.str());
  WriteJson(out_dir + "/summary.json", {{"sequence", sequence_dir},
                                        {"template", template_path.empty() ? "default" : template_path},
                                        {"frames", summary_frames},
                                        {"warnings", result.warnings}});
  const auto number = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
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
