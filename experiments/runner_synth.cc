// Synthetic sequences of experiment files (experiments/runner.h): the `synth:` spec (virtual
// Kinect options, recording conditions, depth outliers) and the generation of a sequence from
// it (the `experiment-synth` child process).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <opencv2/core.hpp>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "experiments/runner.h"
#include "experiments/runner_internal.h"
#include "models/error.h"
#include "sensors/image_io.h"
#include "sensors/sequence.h"
#include "sensors/synth_conditions.h"
#include "sensors/virtual_kinect.h"

namespace artex {
namespace fs = std::filesystem;

namespace runner_internal {
namespace {

constexpr int kDefaultDepthWidth = 640;
constexpr int kDefaultDepthHeight = 480;

}  // namespace

SynthSpec SynthSpecFromConfig(const Config& c) {
  c.CheckKeys(SynthSpecKeys());
  SynthSpec spec;
  SynthOptions& o = spec.options;
  if (c.Has("motion")) {
    std::string motion;
    c.Get("motion", &motion);
    try {
      o.motion.type = ParseMotionType(motion);
    } catch (const Error& e) {
      throw Error(c.Path("motion") + ": " + e.what());
    }
  }
  c.Get("bvh", &o.bvh_path);
  c.Get("frames", &o.motion.frames);
  int seed = 1;
  c.Get("seed", &seed);
  if (seed < 0) throw Error(c.Path("seed") + ": expected >= 0, found " + std::to_string(seed));
  o.kinect.seed = static_cast<uint64_t>(seed);
  o.texture.seed = static_cast<uint64_t>(seed);
  if (c.Has("noise")) {
    std::string noise;
    c.Get("noise", &noise);
    try {
      o.kinect.SetNoiseLevel(ParseNoiseLevel(noise));
    } catch (const Error& e) {
      throw Error(c.Path("noise") + ": " + e.what());
    }
  }
  c.Get("frame_rate", &o.motion.frame_rate);
  o.kinect.frame_rate = o.motion.frame_rate;
  c.Get("amplitude", &o.motion.amplitude);
  c.Get("period_s", &o.motion.period_s);
  c.Get("ramp_s", &o.motion.ramp_s);
  c.Get("speed", &o.motion.speed);
  c.Get("frame_step", &o.motion.frame_step);
  c.Get("background_frames", &o.background_frames);
  c.Get("color_width", &o.kinect.color_width);
  c.Get("color_height", &o.kinect.color_height);
  c.Get("texture_size", &o.texture.size);
  c.Get("subject_resolution", &o.subject_shape.resolution);
  c.Get("subject_height", &o.subject_shape.height);
  c.Get("subject_girth", &o.subject_shape.girth);
  c.Get("subject_template", &o.subject_template);
  c.Get("yaw_deg", &o.subject_yaw_deg);
  int depth_width = kDefaultDepthWidth, depth_height = kDefaultDepthHeight;
  c.Get("depth_width", &depth_width);
  c.Get("depth_height", &depth_height);
  if (depth_width < 16 || depth_height < 16) {
    throw Error(c.Path("depth_width") + ": expected a depth image of at least 16 x 16, found " +
                std::to_string(depth_width) + " x " + std::to_string(depth_height));
  }
  PinholeCamera& d = o.kinect.depth_intrinsics;
  const double sx = static_cast<double>(depth_width) / d.width;
  const double sy = static_cast<double>(depth_height) / d.height;
  d.fx *= sx;
  d.fy *= sy;
  d.cx = (d.cx + 0.5) * sx - 0.5;
  d.cy = (d.cy + 0.5) * sy - 0.5;
  d.width = depth_width;
  d.height = depth_height;
  c.Get("disparity_noise_px", &o.kinect.depth_noise.disparity_noise_px);
  c.Get("disparity_step_px", &o.kinect.depth_noise.disparity_step_px);
  c.Get("edge_drop_probability", &o.kinect.depth_noise.edge_drop_probability);
  c.Get("grazing_angle_deg", &o.kinect.depth_noise.grazing_angle_deg);
  c.Get("projector_shadow", &o.kinect.depth_noise.projector_shadow);
  c.Get("random_dropout", &o.kinect.depth_noise.random_dropout);
  c.Get("color_noise", &o.kinect.color_model.noise_std);
  c.Get("outlier_fraction", &spec.outlier_fraction);
  c.Get("outlier_range_m", &spec.outlier_range_m);
  // Recording conditions (docs/synthesis.md "Conditions"): presets first, then explicit keys.
  if (c.Has("condition")) {
    std::string list;
    c.Get("condition", &list);
    std::stringstream names(list);
    std::string name;
    while (std::getline(names, name, ',')) {
      name.erase(0, name.find_first_not_of(" \t"));
      name.erase(name.find_last_not_of(" \t") + 1);
      try {
        ApplySynthCondition(ParseSynthCondition(name), &o);
      } catch (const Error& e) {
        throw Error(c.Path("condition") + ": " + e.what());
      }
    }
    c.Get("background_frames", &o.background_frames);
    c.Get("yaw_deg", &o.subject_yaw_deg);
  }
  c.Get("camera_pitch_deg", &o.kinect.depth_pitch_deg);
  c.Get("camera_roll_deg", &o.kinect.depth_roll_deg);
  if (c.Has("world_frame")) {
    std::string frame;
    c.Get("world_frame", &frame);
    try {
      o.world_frame = ParseWorldFrame(frame);
    } catch (const Error& e) {
      throw Error(c.Path("world_frame") + ": " + e.what());
    }
  }
  c.Get("boxes", &o.random_boxes);
  c.Get("second_person", &o.second_person.enabled);
  if (c.Has("second_person")) {
    o.second_person.shape.resolution = o.subject_shape.resolution;
    o.second_person.texture.size = o.texture.size;
    o.second_person.texture.seed = o.texture.seed + 1;
  }
  o.write_subject_glb = true;
  if (!(spec.outlier_fraction >= 0 && spec.outlier_fraction <= 1)) {
    throw Error(c.Path("outlier_fraction") + ": expected a fraction in [0, 1], found " +
                FormatNumber(spec.outlier_fraction));
  }
  if (!(spec.outlier_range_m > 0)) {
    throw Error(c.Path("outlier_range_m") + ": expected > 0, found " +
                FormatNumber(spec.outlier_range_m));
  }
  std::string why;
  if (!o.IsValid(&why)) throw Error(c.Path("") + " invalid synthesis options: " + why);
  return spec;
}

}  // namespace runner_internal

namespace {

using runner_internal::SynthSpec;
using runner_internal::SynthSpecFromConfig;

// Replaces a fraction of the valid depth pixels by outliers displaced along the ray
// (deterministic per seed and frame).
void AddDepthOutliers(const SynthSpec& spec, const std::string& folder) {
  if (spec.outlier_fraction <= 0) return;
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(fs::path(folder) / "depth")) {
    if (entry.path().extension() == ".png") files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  const double scale = spec.options.kinect.depth_scale;
  for (std::size_t i = 0; i < files.size(); ++i) {
    cv::Mat depth = ReadImageFile(files[i].string(), ImageRead::kUnchanged);
    if (depth.type() != CV_16UC1) {
      throw Error(files[i].string() + ": expected a 16-bit depth PNG");
    }
    std::mt19937_64 rng(spec.options.kinect.seed * 1000003ull + i);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    std::uniform_real_distribution<double> shift(-spec.outlier_range_m, spec.outlier_range_m);
    for (int y = 0; y < depth.rows; ++y) {
      for (int x = 0; x < depth.cols; ++x) {
        uint16_t& d = depth.at<uint16_t>(y, x);
        if (d == 0 || u01(rng) >= spec.outlier_fraction) continue;
        const double z = d / scale + shift(rng);
        d = static_cast<uint16_t>(std::clamp(std::lround(std::max(z, 0.05) * scale), 1l, 65535l));
      }
    }
    WriteImageAtomic(files[i].string(), depth);
  }
}

}  // namespace

std::vector<std::string> SynthSpecKeys() {
  return {"motion", "bvh", "frames", "seed", "noise", "frame_rate", "amplitude", "period_s", "ramp_s",
          "speed", "frame_step",
          "background_frames", "color_width", "color_height", "texture_size",
          "subject_resolution", "subject_height", "subject_girth", "subject_template", "yaw_deg",
          "depth_width",
          "depth_height", "disparity_noise_px", "disparity_step_px", "edge_drop_probability",
          "grazing_angle_deg", "projector_shadow", "random_dropout", "color_noise",
          "outlier_fraction", "outlier_range_m", "condition", "camera_pitch_deg",
          "camera_roll_deg", "world_frame", "boxes", "second_person"};
}

void GenerateSyntheticSequence(const std::string& synth_yaml, const std::string& source_name,
                               const std::string& out_dir,
                               const std::function<void(int, int)>& progress) {
  const SynthSpec spec = SynthSpecFromConfig(Config::FromString(synth_yaml, source_name));
  SynthesizeSequence(spec.options, out_dir, [&](const SynthProgress& p) {
    if (p.stage == SynthProgress::Stage::kFrames && progress) progress(p.done, p.total);
  });
  AddDepthOutliers(spec, out_dir);
  WriteFileAtomic((fs::path(out_dir) / "synth.yaml").string(), synth_yaml + "\n");
}

}  // namespace artex
