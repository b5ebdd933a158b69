// `artex synth`: renders a synthetic RGB-D sequence with ground truth (sensors/virtual_kinect.h)
// and optionally a preview picture of one frame (colour | depth | foreground depth mesh).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <string>

#include "experiments/commands.h"
#include "models/error.h"
#include "models/skinning.h"
#include "render/rasterizer.h"
#include "sensors/preprocess.h"
#include "sensors/sequence.h"
#include "sensors/virtual_kinect.h"

namespace artex {
namespace {

struct SynthCliOptions {
  std::string output;
  std::string motion = "walk";
  std::string bvh;
  std::string noise = "default";
  std::string preview;
  int preview_frame = -1;  // -1: middle frame
  int frames = 60;
  uint64_t seed = 1;
  double frame_rate = 30.0;
  int background_frames = 10;
  int color_width = 800;
  int color_height = 1016;
  int texture_size = 2048;
  int resolution = 1;
  bool no_glb = false;
  BodyShapeOptions shape = DefaultSubjectShape();
  double yaw_deg = 0.0;
};

// Depth image -> TURBO colour map over its valid range (near = red); missing pixels black.
cv::Mat DepthColormap(const cv::Mat& depth, double depth_scale) {
  double lo = std::numeric_limits<double>::max(), hi = 0;
  for (int y = 0; y < depth.rows; ++y) {
    for (int x = 0; x < depth.cols; ++x) {
      const uint16_t d = depth.at<uint16_t>(y, x);
      if (d == 0) continue;
      lo = std::min(lo, d / depth_scale);
      hi = std::max(hi, d / depth_scale);
    }
  }
  cv::Mat gray(depth.size(), CV_8UC1, cv::Scalar(0));
  if (hi > lo) {
    for (int y = 0; y < depth.rows; ++y) {
      for (int x = 0; x < depth.cols; ++x) {
        const uint16_t d = depth.at<uint16_t>(y, x);
        if (d)
          gray.at<uint8_t>(y, x) =
              static_cast<uint8_t>(std::lround(255.0 * (hi - d / depth_scale) / (hi - lo)));
      }
    }
  }
  cv::Mat color;
  cv::applyColorMap(gray, color, cv::COLORMAP_TURBO);
  color.setTo(cv::Scalar(0, 0, 0), depth == 0);
  return color;
}

// Renders a mesh (world frame) from `camera` with per-vertex normals shown as RGB = (n+1)/2
// in the camera frame (x right, y down, z towards the camera flipped so facing = blue).
cv::Mat NormalImage(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                    const Eigen::MatrixX3d& normals, const PinholeCamera& camera) {
  RasterBuffers buffers;
  Rasterize(vertices, triangles, camera, RasterOptions(), &buffers);
  const Eigen::Matrix3d r = camera.world_to_camera.linear();
  cv::Mat image(camera.height, camera.width, CV_8UC3, cv::Scalar(0, 0, 0));
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      const int i = buffers.index(x, y);
      const int f = buffers.triangle_id[i];
      if (f < 0) continue;
      const double b1 = buffers.barycentric[i].x(), b2 = buffers.barycentric[i].y();
      Eigen::Vector3d n = (1 - b1 - b2) * normals.row(triangles(f, 0)).transpose() +
                          b1 * normals.row(triangles(f, 1)).transpose() +
                          b2 * normals.row(triangles(f, 2)).transpose();
      if (n.norm() == 0) continue;
      n = r * n.normalized();
      const Eigen::Vector3d rgb(0.5 + 0.5 * n.x(), 0.5 - 0.5 * n.y(), 0.5 - 0.5 * n.z());
      image.at<cv::Vec3b>(y, x) =
          cv::Vec3b(static_cast<uint8_t>(255 * rgb.z()), static_cast<uint8_t>(255 * rgb.y()),
                    static_cast<uint8_t>(255 * rgb.x()));
    }
  }
  return image;
}

void Label(cv::Mat* image, const std::string& text) {
  cv::putText(*image, text, cv::Point(8, 22), cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(0, 0, 0), 3,
              cv::LINE_AA);
  cv::putText(*image, text, cv::Point(8, 22), cv::FONT_HERSHEY_SIMPLEX, 0.6,
              cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
}

// One frame: colour | colour-mapped depth | foreground depth mesh (normals), side by side.
void WritePreview(const SynthOptions& options, int frame_index, const std::string& path) {
  const SynthSubject s = PrepareSynthSubject(options);
  if (frame_index < 0) frame_index = static_cast<int>(s.poses.size()) / 2;
  if (frame_index >= static_cast<int>(s.poses.size())) {
    throw Error("--preview-frame: expected a frame in [0, " + std::to_string(s.poses.size()) +
                "), found " + std::to_string(frame_index));
  }
  VirtualKinectOptions kinect_options = options.kinect;
  kinect_options.frame_rate = options.motion.frame_rate;
  const VirtualKinect kinect(kinect_options, s.subject, s.texture_bgr);
  const Skinning skinning(s.subject);
  Eigen::MatrixX3d posed;
  skinning.Apply(s.poses[frame_index], &posed);
  const std::vector<ColorConditions> conditions =
      GenerateColorConditions(kinect_options.color_model, kinect_options.seed, frame_index + 1);
  Frame frame;
  kinect.RenderFrame(frame_index, &posed, conditions[frame_index], &frame);

  // Foreground depth mesh through the preprocessing pipeline (background model from
  // empty-scene frames, as in a real recording).
  std::vector<cv::Mat> background;
  const int num_background = std::max(5, options.background_frames);
  for (int b = 0; b < num_background; ++b) {
    background.push_back(kinect.RenderBackgroundDepth(b));
  }
  Preprocessor preprocessor(kinect.calibration());
  preprocessor.Train(background);
  Scan scan;
  preprocessor.Process(frame, &scan);

  const int h = kinect.calibration().depth.height;
  cv::Mat color;
  const double scale = static_cast<double>(h) / frame.color.rows;
  cv::resize(frame.color, color, cv::Size(std::lround(frame.color.cols * scale), h), 0, 0,
             cv::INTER_AREA);
  cv::Mat depth = DepthColormap(frame.depth, kinect.calibration().depth_scale);
  cv::Mat mesh = NormalImage(scan.points, scan.triangles, scan.normals, kinect.calibration().depth);
  Label(&color, "colour (frame " + std::to_string(frame_index) + ")");
  Label(&depth, "depth (near red, far blue; black = missing)");
  Label(&mesh, "foreground depth mesh: " + std::to_string(scan.size()) + " points (normals)");
  cv::Mat composite;
  cv::hconcat(std::vector<cv::Mat>{color, depth, mesh}, composite);
  WriteImageAtomic(path, composite);
}

void Run(const SynthCliOptions& cli) {
  if (cli.output.empty() && cli.preview.empty()) {
    throw Error("-o/--output: an output folder is required (or --preview PNG)");
  }
  if (cli.frames == 0 && cli.bvh.empty()) {
    throw Error("--frames: expected >= 1 (0 = the whole clip, only with --bvh), found 0");
  }
  SynthOptions options;
  try {
    options.motion.type = ParseMotionType(cli.motion);
  } catch (const Error& e) {
    throw Error(std::string("--motion: ") + e.what());
  }
  NoiseLevel noise;
  try {
    noise = ParseNoiseLevel(cli.noise);
  } catch (const Error& e) {
    throw Error(std::string("--noise: ") + e.what());
  }
  options.motion.frames = cli.frames;
  options.motion.frame_rate = cli.frame_rate;
  options.bvh_path = cli.bvh;
  options.kinect.seed = cli.seed;
  options.texture.seed = cli.seed;
  options.kinect.SetNoiseLevel(noise);
  options.kinect.color_width = cli.color_width;
  options.kinect.color_height = cli.color_height;
  options.texture.size = cli.texture_size;
  options.subject_shape = cli.shape;
  options.subject_shape.resolution = cli.resolution;
  options.subject_yaw_deg = cli.yaw_deg;
  options.background_frames = cli.background_frames;
  options.write_subject_glb = !cli.no_glb;
  std::string why;
  if (!options.IsValid(&why)) throw Error("invalid synthesis options: " + why);

  if (!cli.preview.empty()) {
    WritePreview(options, cli.preview_frame, cli.preview);
    std::fprintf(stderr, "synth: wrote preview %s\n", cli.preview.c_str());
  }
  if (cli.output.empty()) return;
  const SynthSummary summary = SynthesizeSequence(options, cli.output, [](const SynthProgress& p) {
    switch (p.stage) {
      case SynthProgress::Stage::kSetup:
        if (p.done == 0) std::fprintf(stderr, "synth: generating subject, texture and motion...\n");
        break;
      case SynthProgress::Stage::kBackground:
        std::fprintf(stderr, "\rsynth: background %d/%d", p.done, p.total);
        if (p.done == p.total) std::fprintf(stderr, "\n");
        break;
      case SynthProgress::Stage::kFrames:
        std::fprintf(stderr, "\rsynth: frame %d/%d", p.done, p.total);
        if (p.done == p.total) std::fprintf(stderr, "\n");
        break;
      case SynthProgress::Stage::kFinish:
        if (p.done == 0) std::fprintf(stderr, "synth: writing ground truth...\n");
        break;
    }
    std::fflush(stderr);
  });
  std::fprintf(
      stderr,
      "synth: wrote %d frames + %d background frames to %s in %.2f s "
      "(setup %.2f s; %.1f ms per frame; per image set: render %.1f ms, write %.1f ms)\n",
      summary.frames, summary.background_frames, cli.output.c_str(), summary.total_seconds,
      summary.setup_seconds, summary.ms_per_frame(),
      1000.0 * summary.render_seconds / std::max(1, summary.frames + summary.background_frames),
      1000.0 * summary.write_seconds / std::max(1, summary.frames + summary.background_frames));
}

}  // namespace

void RegisterSynthCommand(CLI::App* app) {
  auto cli = std::make_shared<SynthCliOptions>();
  CLI::App* sub = app->add_subcommand(
      "synth", "Render a synthetic RGB-D sequence with ground truth (virtual Kinect)");
  sub->add_option("-o,--output", cli->output, "Output sequence folder");
  sub->add_option("--motion", cli->motion, "Built-in motion: walk, arm_raise, turn, bend, still")
      ->capture_default_str();
  sub->add_option("--bvh", cli->bvh, "Motion from a BVH file (retargeted; overrides --motion)")
      ->check(CLI::ExistingFile);
  sub->add_option("--frames", cli->frames, "Number of frames (with --bvh: at most; 0 = all)")
      ->capture_default_str()
      ->check(CLI::Range(0, 100000));
  sub->add_option("--frame-rate", cli->frame_rate, "Frame rate (Hz)")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 240.0));
  sub->add_option("--seed", cli->seed, "Seed of texture, noise and colour drift")
      ->capture_default_str();
  sub->add_option("--noise", cli->noise, "Sensor noise preset: off, default, high")
      ->capture_default_str();
  sub->add_option("--background-frames", cli->background_frames, "Empty-scene depth frames")
      ->capture_default_str()
      ->check(CLI::Range(0, 1000));
  sub->add_option("--color-width", cli->color_width, "Colour camera width (pixels)")
      ->capture_default_str()
      ->check(CLI::Range(16, 8192));
  sub->add_option("--color-height", cli->color_height, "Colour camera height (pixels)")
      ->capture_default_str()
      ->check(CLI::Range(16, 8192));
  sub->add_option("--texture-size", cli->texture_size, "Subject texture atlas side (texels)")
      ->capture_default_str()
      ->check(CLI::Range(64, 8192));
  sub->add_option("--subject-resolution", cli->resolution,
                  "Subject mesh: 0 coarse (~3k vertices), 1 default (~12.5k)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1));
  sub->add_option("--subject-height", cli->shape.height, "Subject stature (m)")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 2.3));
  sub->add_option("--subject-girth", cli->shape.girth, "Subject girth factor")
      ->capture_default_str()
      ->check(CLI::Range(0.6, 1.6));
  sub->add_option("--subject-shoulder", cli->shape.shoulder_width, "Shoulder width factor")
      ->capture_default_str()
      ->check(CLI::Range(0.7, 1.3));
  sub->add_option("--subject-hip", cli->shape.hip_width, "Hip width factor")
      ->capture_default_str()
      ->check(CLI::Range(0.7, 1.3));
  sub->add_option("--subject-arm-length", cli->shape.arm_length, "Arm length factor")
      ->capture_default_str()
      ->check(CLI::Range(0.8, 1.2));
  sub->add_option("--subject-leg-length", cli->shape.leg_length, "Leg length factor")
      ->capture_default_str()
      ->check(CLI::Range(0.8, 1.2));
  sub->add_option("--subject-yaw", cli->yaw_deg, "Subject rotation about +Y (degrees)")
      ->capture_default_str()
      ->check(CLI::Range(-180.0, 180.0));
  sub->add_flag("--no-glb", cli->no_glb, "Do not write groundtruth/subject.glb");
  sub->add_option("--preview", cli->preview,
                  "Write a PNG of one frame: colour | depth | foreground depth mesh");
  sub->add_option("--preview-frame", cli->preview_frame, "Frame shown by --preview (-1: middle)")
      ->capture_default_str();
  sub->callback([cli]() { Run(*cli); });
}

}  // namespace artex
