// `artex synth`: renders a synthetic RGB-D sequence with ground truth (sensors/virtual_kinect.h)
// and optionally a preview picture of one frame (colour | depth | foreground depth mesh).
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <string>

#include "experiments/atomic_output.h"
#include "experiments/commands.h"
#include "models/error.h"
#include "models/skinning.h"
#include "render/rasterizer.h"
#include "sensors/preprocess.h"
#include "sensors/sequence.h"
#include "sensors/synth_conditions.h"
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
  double speed = 1.0;  // playback speed of the motion
  int frame_step = 1;  // every frame_step-th frame of the motion kept (frames dropped)
  int background_frames = 10;
  int color_width = 800;
  int color_height = 1016;
  int texture_size = 2048;
  int resolution = 1;
  bool no_glb = false;
  BodyShapeOptions shape = DefaultSubjectShape();
  std::string subject_template;  // "" = the generated body
  double yaw_deg = 0.0;
  // Conditions (docs/synthesis.md "Conditions"); explicit flags override a --condition.
  std::vector<std::string> conditions;
  std::string framing = "full";
  CameraPlacement camera;  // used when a --camera-height/-distance/-azimuth/-target-height
  double camera_pitch_deg = 0.0;
  double camera_roll_deg = 0.0;
  std::string world_frame = "scene";
  DepthNoiseOptions depth_noise;  // the flags below override the --noise preset's
  int boxes = 0;
  bool second_person = false;
  std::string second_person_motion = "walk";
  double second_person_behind_m = 1.2;
  double second_person_start_m = -1.6;
  double second_person_speed = 0.8;
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
  const VirtualKinectOptions kinect_options = ResolveKinectOptions(options);
  const VirtualKinect kinect(kinect_options, s.subject, s.texture_bgr, s.others);
  const Skinning skinning(s.subject);
  Eigen::MatrixX3d posed;
  skinning.Apply(s.poses[frame_index], &posed);
  std::vector<Eigen::MatrixX3d> others(s.others.size());
  for (size_t k = 0; k < others.size(); ++k) {
    Skinning(s.others[k].body).Apply(s.other_poses[k][frame_index], &others[k]);
  }
  const std::vector<ColorConditions> conditions =
      GenerateColorConditions(kinect_options.color_model, kinect_options.seed, frame_index + 1);
  Frame frame;
  kinect.RenderFrame(frame_index, &posed, others, conditions[frame_index], &frame);

  // Foreground depth mesh through the preprocessing pipeline (background model from the
  // sequence's empty-scene frames, as in a real recording; none: every valid depth in range).
  std::vector<cv::Mat> background;
  for (int b = 0; b < options.background_frames; ++b) {
    background.push_back(kinect.RenderBackgroundDepth(b));
  }
  Preprocessor preprocessor(kinect.calibration());
  if (background.empty()) {
    preprocessor.TrainWithoutBackground();
  } else {
    preprocessor.Train(background);
  }
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

// Flags given explicitly on the command line (they override a --condition).
bool Given(const CLI::App& app, const char* flag) { return app.count(flag) > 0; }

void Run(const SynthCliOptions& cli, const CLI::App& app) {
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
  options.motion.speed = cli.speed;
  options.motion.frame_step = cli.frame_step;
  options.bvh_path = cli.bvh;
  options.kinect.seed = cli.seed;
  options.texture.seed = cli.seed;
  options.kinect.SetNoiseLevel(noise);
  options.kinect.color_width = cli.color_width;
  options.kinect.color_height = cli.color_height;
  options.texture.size = cli.texture_size;
  options.subject_shape = cli.shape;
  options.subject_shape.resolution = cli.resolution;
  options.subject_template = cli.subject_template;
  options.background_frames = cli.background_frames;
  options.write_subject_glb = !cli.no_glb;
  // Conditions first (in the given order), then explicit flags.
  for (const std::string& name : cli.conditions) {
    try {
      ApplySynthCondition(ParseSynthCondition(name), &options);
    } catch (const Error& e) {
      throw Error(std::string("--condition: ") + e.what());
    }
  }
  if (cli.framing == "upper_body") {
    options.camera_placement = UpperBodyCameraPlacement(options.subject_shape.height);
  } else if (cli.framing != "full") {
    throw Error("--framing: expected one of full, upper_body; found '" + cli.framing + "'");
  }
  if (Given(app, "--subject-yaw")) options.subject_yaw_deg = cli.yaw_deg;
  if (Given(app, "--background-frames")) options.background_frames = cli.background_frames;
  if (Given(app, "--camera-height") || Given(app, "--camera-distance") ||
      Given(app, "--camera-azimuth") || Given(app, "--camera-target-height")) {
    CameraPlacement c = options.camera_placement.value_or(CameraPlacement());
    if (Given(app, "--camera-height")) c.height_m = cli.camera.height_m;
    if (Given(app, "--camera-distance")) c.distance_m = cli.camera.distance_m;
    if (Given(app, "--camera-azimuth")) c.azimuth_deg = cli.camera.azimuth_deg;
    if (Given(app, "--camera-target-height")) c.target_height_m = cli.camera.target_height_m;
    options.camera_placement = c;
  }
  if (Given(app, "--camera-pitch")) options.kinect.depth_pitch_deg = cli.camera_pitch_deg;
  if (Given(app, "--camera-roll")) options.kinect.depth_roll_deg = cli.camera_roll_deg;
  if (Given(app, "--world-frame")) {
    try {
      options.world_frame = ParseWorldFrame(cli.world_frame);
    } catch (const Error& e) {
      throw Error(std::string("--world-frame: ") + e.what());
    }
  }
  // The depth sensor's effects one by one, over the preset (docs/synthesis.md).
  DepthNoiseOptions& d = options.kinect.depth_noise;
  if (Given(app, "--disparity-noise")) d.disparity_noise_px = cli.depth_noise.disparity_noise_px;
  if (Given(app, "--disparity-step")) d.disparity_step_px = cli.depth_noise.disparity_step_px;
  if (Given(app, "--edge-drop")) d.edge_drop_probability = cli.depth_noise.edge_drop_probability;
  if (Given(app, "--grazing-angle")) d.grazing_angle_deg = cli.depth_noise.grazing_angle_deg;
  if (Given(app, "--projector-shadow")) d.projector_shadow = cli.depth_noise.projector_shadow;
  if (Given(app, "--boxes")) options.random_boxes = cli.boxes;
  SecondPersonOptions& person = options.second_person;
  if (cli.second_person) person.enabled = true;
  person.shape.resolution = options.subject_shape.resolution;
  person.texture.size = options.texture.size;
  person.texture.seed = options.texture.seed + 1;
  if (Given(app, "--second-person-motion")) {
    try {
      person.motion.type = ParseMotionType(cli.second_person_motion);
    } catch (const Error& e) {
      throw Error(std::string("--second-person-motion: ") + e.what());
    }
  }
  if (Given(app, "--second-person-behind")) person.behind_m = cli.second_person_behind_m;
  if (Given(app, "--second-person-start")) person.start_across_m = cli.second_person_start_m;
  if (Given(app, "--second-person-speed")) person.speed_m_s = cli.second_person_speed;
  std::string why;
  if (!options.IsValid(&why)) throw Error("invalid synthesis options: " + why);

  if (!cli.preview.empty()) {
    WritePreview(options, cli.preview_frame, cli.preview);
    std::fprintf(stderr, "synth: wrote preview %s\n", cli.preview.c_str());
  }
  if (cli.output.empty()) return;
  // Written into a temporary sibling, published complete at the end (docs/reliability.md): an
  // interrupted overwrite never leaves old frames or ground truth beside new ones.
  AtomicOutputFolder out(cli.output, "synth");
  const SynthSummary summary = SynthesizeSequence(options, out.path(), [](const SynthProgress& p) {
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
  out.Commit();
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
  sub->add_option("--motion", cli->motion,
                  "Built-in motion: walk, arm_raise, turn, bend, still, punch_kick")
      ->capture_default_str();
  sub->add_option("--bvh", cli->bvh, "Motion from a BVH file (retargeted; overrides --motion)")
      ->check(CLI::ExistingFile);
  sub->add_option("--frames", cli->frames, "Number of frames (with --bvh: at most; 0 = all)")
      ->capture_default_str()
      ->check(CLI::Range(0, 100000));
  sub->add_option("--frame-rate", cli->frame_rate, "Frame rate (Hz)")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 240.0));
  sub->add_option("--speed", cli->speed,
                  "Playback speed of the motion or BVH clip (2: twice as fast)")
      ->capture_default_str()
      ->check(CLI::Range(0.01, 8.0));
  sub->add_option("--frame-step", cli->frame_step,
                  "Keep every n-th frame of the motion (2: every second frame dropped)")
      ->capture_default_str()
      ->check(CLI::Range(1, 100));
  sub->add_option("--seed", cli->seed, "Seed of texture, noise and colour drift")
      ->capture_default_str();
  sub->add_option("--noise", cli->noise, "Sensor noise preset: off, default, high")
      ->capture_default_str();
  sub->add_option("--disparity-noise", cli->depth_noise.disparity_noise_px,
                  "Depth: Gaussian disparity noise std (px), over the --noise preset")
      ->check(CLI::Range(0.0, 10.0));
  sub->add_option("--disparity-step", cli->depth_noise.disparity_step_px,
                  "Depth: disparity quantisation step (px; 0: none), over the preset")
      ->check(CLI::Range(0.0, 10.0));
  sub->add_option("--edge-drop", cli->depth_noise.edge_drop_probability,
                  "Depth: drop-out probability at depth discontinuities, over the preset")
      ->check(CLI::Range(0.0, 1.0));
  sub->add_option("--grazing-angle", cli->depth_noise.grazing_angle_deg,
                  "Depth: surfaces seen beyond this angle to the view ray are missing (degrees; "
                  "90: none), over the preset")
      ->check(CLI::Range(1.0, 90.0));
  sub->add_option("--projector-shadow", cli->depth_noise.projector_shadow,
                  "Depth: the IR projector's shadow (true/false), over the preset");
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
  sub->add_option("--subject-template", cli->subject_template,
                  "Subject body from a template file (.glb with UVs and the default 17 joints, "
                  "e.g. from `artex template import-makehuman`) instead of the generated body "
                  "(the --subject-height ... shape flags are then not used)");
  sub->add_option("--subject-yaw,--yaw", cli->yaw_deg,
                  "Subject rotation about +Y (degrees; 180: facing away from the camera)")
      ->capture_default_str()
      ->check(CLI::Range(-180.0, 180.0));
  std::string condition_help =
      "Recording condition preset(s), comma-separated, applied in order "
      "before the other flags:";
  for (const std::string& name : SynthConditionNames()) condition_help += " " + name;
  sub->add_option("--condition", cli->conditions, condition_help)->delimiter(',');
  sub->add_option("--framing", cli->framing,
                  "full (default camera) or upper_body (close camera at chest height: the "
                  "image border cuts the body at the hips)")
      ->capture_default_str();
  sub->add_option("--camera-height", cli->camera.height_m,
                  "Depth camera height above the floor y = 0 (m)")
      ->capture_default_str()
      ->check(CLI::Range(0.05, 10.0));
  sub->add_option("--camera-distance", cli->camera.distance_m,
                  "Horizontal distance of the depth camera from the subject's start (m)")
      ->capture_default_str()
      ->check(CLI::Range(0.1, 20.0));
  sub->add_option("--camera-azimuth", cli->camera.azimuth_deg,
                  "Direction of the camera from the subject about +Y (degrees; 0 = +Z)")
      ->capture_default_str()
      ->check(CLI::Range(-360.0, 360.0));
  sub->add_option("--camera-target-height", cli->camera.target_height_m,
                  "Height above the floor of the look-at point over the subject's start (m)")
      ->capture_default_str()
      ->check(CLI::Range(-5.0, 10.0));
  sub->add_option("--camera-pitch", cli->camera_pitch_deg,
                  "Extra pitch about the camera's x axis after the look-at (degrees, + = down)")
      ->capture_default_str()
      ->check(CLI::Range(-89.0, 89.0));
  sub->add_option("--camera-roll", cli->camera_roll_deg,
                  "Roll about the optical axis (degrees, + = camera turned clockwise as seen "
                  "from behind it)")
      ->capture_default_str()
      ->check(CLI::Range(-180.0, 180.0));
  sub->add_option("--world-frame", cli->world_frame,
                  "Frame of calibration.yaml and ground truth: scene (Y up, floor y = 0) or "
                  "camera (depth camera = identity)")
      ->capture_default_str();
  sub->add_option("--boxes", cli->boxes,
                  "Furniture-like boxes beside/behind the subject (from --seed)")
      ->capture_default_str()
      ->check(CLI::Range(0, 32));
  sub->add_flag("--second-person", cli->second_person,
                "Add a second person (not in the ground truth) walking across behind the subject");
  sub->add_option("--second-person-motion", cli->second_person_motion,
                  "Motion of the second person: walk, arm_raise, turn, bend, still")
      ->capture_default_str();
  sub->add_option("--second-person-behind", cli->second_person_behind_m,
                  "How much further from the camera than the subject it starts (m)")
      ->capture_default_str()
      ->check(CLI::Range(-10.0, 10.0));
  sub->add_option("--second-person-start", cli->second_person_start_m,
                  "Start offset along the camera's right axis (m; negative = left)")
      ->capture_default_str()
      ->check(CLI::Range(-10.0, 10.0));
  sub->add_option("--second-person-speed", cli->second_person_speed,
                  "Walking speed along the camera's right axis (m/s; 0 = stands facing the camera)")
      ->capture_default_str()
      ->check(CLI::Range(-5.0, 5.0));
  sub->add_flag("--no-glb", cli->no_glb, "Do not write groundtruth/subject.glb");
  sub->add_option("--preview", cli->preview,
                  "Write a PNG of one frame: colour | depth | foreground depth mesh");
  sub->add_option("--preview-frame", cli->preview_frame, "Frame shown by --preview (-1: middle)")
      ->capture_default_str();
  sub->callback([cli, sub]() { Run(*cli, *sub); });
}

}  // namespace artex
