#include "experiments/stream_evaluation.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "experiments/pipeline_stages.h"  // WritePngFile
#include "experiments/pose_csv.h"
#include "experiments/stream_sinks.h"
#include "experiments/texture_evaluation.h"
#include "models/error.h"
#include "models/mesh_export.h"
#include "models/skinning.h"
#include "models/template_cache.h"
#include "models/template_io.h"
#include "sensors/calibration.h"
#include "sensors/image_io.h"
#include "sensors/sequence.h"
#include "stream/stream_player.h"
#include "texture/texturer.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

nlohmann::json Number(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
}

std::vector<int> FramesOf(const std::vector<int>& textured) {
  std::vector<int> frames(textured.size());
  for (std::size_t f = 0; f < textured.size(); ++f) frames[f] = textured[f] ? 0 : -1;
  return frames;
}

// Sender's compose + encode ms per frame from a run's stream_frames.csv (empty when absent).
std::map<int, double> ReadSenderTimes(const std::string& run_dir) {
  std::map<int, double> out;
  std::ifstream in(run_dir + "/stream_frames.csv");
  std::string line;
  if (!in || !std::getline(in, line)) return out;
  std::vector<std::string> names;
  std::stringstream header(line);
  for (std::string name; std::getline(header, name, ',');) names.push_back(name);
  const auto column = [&](const char* name) {
    return static_cast<int>(std::find(names.begin(), names.end(), name) - names.begin());
  };
  const int frame = column("frame"), compose = column("compose_ms"), encode = column("encode_ms");
  const int n = static_cast<int>(names.size());
  if (frame == n || compose == n || encode == n)
    throw Error(run_dir + "/stream_frames.csv: expected columns frame, compose_ms, encode_ms");
  while (std::getline(in, line)) {
    std::vector<std::string> v;
    std::stringstream row(line);
    for (std::string cell; std::getline(row, cell, ',');) v.push_back(cell);
    if (static_cast<int>(v.size()) != n)
      throw Error(run_dir + "/stream_frames.csv: expected " + std::to_string(n) +
                  " values per row, found " + std::to_string(v.size()) + " in: " + line);
    try {
      out[std::stoi(v[frame])] = std::stod(v[compose]) + std::stod(v[encode]);
    } catch (const std::exception&) {
      throw Error(run_dir + "/stream_frames.csv: expected numbers, found: " + line);
    }
  }
  return out;
}

}  // namespace

void StreamLatency(double frame_rate, double link_kbps, std::vector<FrameTiming>* frames) {
  double link_free_ms = -std::numeric_limits<double>::infinity();
  for (FrameTiming& t : *frames) {
    const double capture_ms = 1000.0 * t.frame / frame_rate;
    const double ready_ms = capture_ms + t.sender_ms;
    const double start_ms = std::max(ready_ms, link_free_ms);
    t.queue_ms = start_ms - ready_ms;
    t.transmit_ms = 8.0 * static_cast<double>(t.record_bytes) / link_kbps;  // bits / (bit/ms)
    link_free_ms = start_ms + t.transmit_ms;
    t.latency_ms = link_free_ms + t.decode_ms - capture_ms;
  }
}

StreamSummary EncodeRunStream(const std::string& run_dir, const std::string& template_path,
                              const std::string& stream_path, const StreamOptions& options) {
  const std::string glb = template_path.empty() ? run_dir + "/tracked.glb" : template_path;
  const Template tmpl = ReadTemplateFile(glb);
  const Calibration calibration = ReadCalibration(run_dir + "/calibration.yaml");
  const auto poses = ReadPoseCsv(run_dir + "/poses.csv", tmpl.num_joints());
  cv::Mat atlas;
  std::vector<int> frames;
  const bool texture = ReadExportedAtlas(run_dir, poses.front().first, &atlas, &frames);
  StreamSender sender(stream_path, tmpl, calibration.color, calibration.frame_rate,
                      texture ? atlas.cols : 0, texture, options);
  for (const auto& [frame, pose] : poses) {
    if (texture && !ReadExportedAtlas(run_dir, frame, &atlas, &frames))
      throw Error(run_dir + "/atlases: no atlas of frame " + std::to_string(frame) +
                  " (track with pipeline.export_atlases: true)");
    sender.AddFrame(frame, pose, atlas, texture ? &frames : nullptr);
  }
  return sender.Finish();
}

PlaybackReport PlayStream(const std::string& stream_path, const PlaybackOptions& options) {
  if (options.evaluate_every < 1) throw Error("stream play: evaluate_every must be >= 1");
  if (!(options.link_kbps >= 0)) throw Error("stream play: link_kbps must be >= 0");
  StreamPlayer player(stream_path, options.from_frame);
  const StreamHeader& header = player.header();
  const Template& model = player.model();  // changes with the stream's rest shapes
  auto skinning = std::make_unique<Skinning>(model);
  PlaybackReport report;
  report.stream_bytes = player.stream_bytes();
  report.glb_bytes = header.glb.size();
  report.header_bytes = EncodeStreamHeader(header).size();

  // Reference (sender) run and ground truth.
  std::map<int, Pose> sender_poses;
  std::map<int, double> sender_ms;
  if (!options.reference_run.empty()) {
    sender_ms = ReadSenderTimes(options.reference_run);
    for (auto& [f, p] : ReadPoseCsv(options.reference_run + "/poses.csv", model.num_joints()))
      sender_poses[f] = p;
  }
  std::unique_ptr<SequenceReader> sequence;
  std::unique_ptr<Template> subject;
  TruthScene truth;
  if (!options.sequence.empty()) {
    sequence = std::make_unique<SequenceReader>(options.sequence);
    if (!sequence->has_ground_truth() || sequence->GroundTruthTexturePath().empty())
      throw Error(options.sequence + ": no ground truth (subject, texture) to compare with");
    subject = std::make_unique<Template>(ReadTemplateGlb(sequence->GroundTruthSubjectPath()));
    truth.subject = subject.get();
    truth.texture = ReadImageFile(sequence->GroundTruthTexturePath(), ImageRead::kColor);
    truth.camera = sequence->calibration().color;
  }
  if (!options.out_dir.empty()) {
    std::error_code ec;
    fs::create_directories(options.out_dir + (options.render_every > 0 ? "/renders" : ""), ec);
    if (ec) throw Error(options.out_dir + ": cannot create the folder: " + ec.message());
  }

  NovelViewAccumulator vs_sender(options.views), vs_truth_receiver(options.views),
      vs_truth_sender(options.views);
  double atlas_se_psnr = 0.0;
  int atlas_count = 0;
  std::vector<int> frames;
  std::vector<Pose> poses;
  double decode_sum = 0.0;
  std::size_t pose_bytes = 0, texture_bytes = 0, record_bytes = 0;
  PlayedFrame f;
  Eigen::MatrixX3d posed, sender_posed;
  std::vector<std::string> rows;  // frames.csv without the latency columns
  std::vector<FrameTiming> timing;
  while (player.Next(&f)) {
    ++report.frames;
    report.keyframes += f.keyframe;
    if (report.first_frame < 0) report.first_frame = f.frame;
    report.last_frame = f.frame;
    decode_sum += f.decode_ms;
    report.max_decode_ms = std::max(report.max_decode_ms, f.decode_ms);
    pose_bytes += f.pose_bytes;
    texture_bytes += f.mask_bytes + f.video_bytes;
    record_bytes += f.record_bytes;
    frames.push_back(f.frame);
    poses.push_back(f.pose);
    rows.push_back(std::to_string(f.frame) + "," + std::to_string(f.keyframe) + "," +
                   std::to_string(f.offset) + "," + std::to_string(f.pose_bytes) + "," +
                   std::to_string(f.mask_bytes) + "," + std::to_string(f.video_bytes) + "," +
                   std::to_string(f.record_bytes) + "," + std::to_string(f.decode_ms));
    FrameTiming t;
    t.frame = f.frame;
    t.record_bytes = f.record_bytes;
    t.decode_ms = f.decode_ms;
    const auto s = sender_ms.find(f.frame);
    if (s != sender_ms.end()) t.sender_ms = s->second;
    timing.push_back(t);
    if (f.shape_changed) skinning = std::make_unique<Skinning>(model);
    skinning->Apply(f.pose, &posed);
    const std::vector<int> triangle_frames = FramesOf(f.textured);
    const bool has_atlas = !f.atlas.empty();
    const Eigen::Vector3d centre = posed.colwise().mean().transpose();
    const std::vector<PinholeCamera> cameras =
        HeldOutCameras(header.camera, centre, Eigen::Vector3d::UnitY(), options.views);
    if (has_atlas && options.render_every > 0 && !options.out_dir.empty() &&
        report.frames % options.render_every == 1 % options.render_every) {
      for (std::size_t k = 0; k < cameras.size(); ++k) {
        cv::Mat image, mask;
        RenderTextured(model, posed, f.atlas, cameras[k], &image, &mask);
        char name[64];
        std::snprintf(name, sizeof(name), "/renders/%06d_v%zu.png", f.frame, k);
        WritePngFile(options.out_dir + name, image);
      }
    }
    if (!has_atlas || (report.frames - 1) % options.evaluate_every != 0) continue;
    bool evaluated = false;
    cv::Mat sender_atlas;
    std::vector<int> sender_frames;
    const auto sp = sender_poses.find(f.frame);
    if (sp != sender_poses.end() &&
        ReadExportedAtlas(options.reference_run, f.frame, &sender_atlas, &sender_frames)) {
      skinning->Apply(sp->second, &sender_posed);
      report.max_vertex_error_mm = std::max(
          report.max_vertex_error_mm, 1000.0 * (posed - sender_posed).rowwise().norm().maxCoeff());
      cv::Mat resized = f.atlas;
      if (f.atlas.size() != sender_atlas.size())
        cv::resize(f.atlas, resized, sender_atlas.size(), 0, 0, cv::INTER_LINEAR);
      atlas_se_psnr += ImagePsnr(resized, sender_atlas);
      ++atlas_count;
      for (const PinholeCamera& camera : cameras) {
        cv::Mat a, am, b, bm;
        RenderTextured(model, posed, f.atlas, camera, &a, &am, &triangle_frames);
        RenderTextured(model, sender_posed, sender_atlas, camera, &b, &bm, &sender_frames);
        vs_sender.Add(a, am, b, bm);
      }
      evaluated = true;
    }
    if (sequence && f.frame < sequence->num_frames()) {
      truth.vertices = sequence->ReadGroundTruth(f.frame).vertices;
      const Eigen::Vector3d target = truth.vertices.colwise().mean().transpose();
      for (const PinholeCamera& camera :
           HeldOutCameras(truth.camera, target, Eigen::Vector3d::UnitY(), options.views)) {
        cv::Mat t, tm, a, am;
        RenderTextured(*truth.subject, truth.vertices, truth.texture, camera, &t, &tm);
        RenderTextured(model, posed, f.atlas, camera, &a, &am, &triangle_frames);
        vs_truth_receiver.Add(a, am, t, tm);
        if (!sender_atlas.empty()) {
          cv::Mat b, bm;
          RenderTextured(model, sender_posed, sender_atlas, camera, &b, &bm, &sender_frames);
          vs_truth_sender.Add(b, bm, t, tm);
        }
      }
      evaluated = true;
    }
    report.evaluated_frames += evaluated;
  }
  report.issues = player.issues();
  report.skipped_records = player.skipped_records();
  const double rate = header.frame_rate();
  if (report.frames > 0) {
    report.mean_decode_ms = decode_sum / report.frames;
    const double k = 8.0 * rate / 1000.0 / report.frames;
    report.pose_kbps = pose_bytes * k;
    report.texture_kbps = texture_bytes * k;
    report.total_kbps = record_bytes * k;
    report.link_kbps = options.link_kbps > 0 ? options.link_kbps : report.total_kbps;
    report.sender_times = !sender_ms.empty();
    StreamLatency(rate, report.link_kbps, &timing);
    std::vector<double> latency;
    for (const FrameTiming& t : timing) latency.push_back(t.latency_ms);
    std::sort(latency.begin(), latency.end());
    report.median_latency_ms = latency[latency.size() / 2];
    report.max_latency_ms = latency.back();
  }
  const NovelViewQuality qs = vs_sender.Result(), qr = vs_truth_receiver.Result(),
                         qt = vs_truth_sender.Result();
  report.psnr_vs_sender_db = qs.views ? qs.psnr_db : kNaN;
  report.ssim_vs_sender = qs.views ? qs.ssim : kNaN;
  report.atlas_psnr_db = atlas_count ? atlas_se_psnr / atlas_count : kNaN;
  if (!qs.views) report.max_vertex_error_mm = kNaN;
  report.receiver_psnr_db = qr.views ? qr.psnr_db : kNaN;
  report.receiver_ssim = qr.views ? qr.ssim : kNaN;
  report.sender_psnr_db = qt.views ? qt.psnr_db : kNaN;
  report.sender_ssim = qt.views ? qt.ssim : kNaN;

  if (!options.out_dir.empty()) {
    if (!poses.empty()) WritePoseCsv(options.out_dir + "/poses.csv", model, frames, poses);
    if (!f.atlas.empty()) WritePngFile(options.out_dir + "/atlas.png", f.atlas);
    std::string frames_csv =
        "frame,keyframe,offset,pose_bytes,coverage_bytes,video_bytes,record_bytes,decode_ms,"
        "sender_ms,queue_ms,transmit_ms,latency_ms\n";
    for (std::size_t i = 0; i < rows.size(); ++i) {
      const FrameTiming& t = timing[i];
      frames_csv += rows[i] + "," + std::to_string(t.sender_ms) + "," + std::to_string(t.queue_ms) +
                    "," + std::to_string(t.transmit_ms) + "," + std::to_string(t.latency_ms) + "\n";
    }
    WriteFileAtomically(options.out_dir + "/frames.csv", frames_csv);
    nlohmann::json issues = nlohmann::json::array();
    for (const StreamIssue& i : report.issues)
      issues.push_back({{"offset", i.offset}, {"frame", i.frame}, {"what", i.what}});
    const nlohmann::json j = {{"stream", stream_path},
                              {"codec", header.codec},
                              {"frame_rate", rate},
                              {"frames", report.frames},
                              {"keyframes", report.keyframes},
                              {"first_frame", report.first_frame},
                              {"last_frame", report.last_frame},
                              {"skipped_records", report.skipped_records},
                              {"issues", issues},
                              {"stream_bytes", report.stream_bytes},
                              {"header_bytes", report.header_bytes},
                              {"template_glb_bytes", report.glb_bytes},
                              {"pose_kbit_per_s", report.pose_kbps},
                              {"texture_kbit_per_s", report.texture_kbps},
                              {"total_kbit_per_s", report.total_kbps},
                              {"decode_ms_per_frame", report.mean_decode_ms},
                              {"max_decode_ms", report.max_decode_ms},
                              {"latency_median_ms", report.median_latency_ms},
                              {"latency_max_ms", report.max_latency_ms},
                              {"latency_link_kbit_per_s", report.link_kbps},
                              {"latency_includes_sender", report.sender_times},
                              {"evaluated_frames", report.evaluated_frames},
                              {"novel_view_psnr_vs_sender_db", Number(report.psnr_vs_sender_db)},
                              {"novel_view_ssim_vs_sender", Number(report.ssim_vs_sender)},
                              {"atlas_psnr_vs_sender_db", Number(report.atlas_psnr_db)},
                              {"max_vertex_error_vs_sender_mm", Number(report.max_vertex_error_mm)},
                              {"receiver_novel_view_psnr_db", Number(report.receiver_psnr_db)},
                              {"receiver_novel_view_ssim", Number(report.receiver_ssim)},
                              {"sender_novel_view_psnr_db", Number(report.sender_psnr_db)},
                              {"sender_novel_view_ssim", Number(report.sender_ssim)}};
    WriteFileAtomically(options.out_dir + "/report.json", j.dump(2) + "\n");
  }
  return report;
}

}  // namespace artex
