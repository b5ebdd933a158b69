// The walk sequence shared by the texturing benchmarks (texture_bench, image_pool_bench): the
// default template (GenerateTemplate()) posed by a walk (GenerateMotion + Skinning) and seen by
// the virtual Kinect's colour camera (800 x 1016, 2.5 m in front; procedural subject texture,
// exposure drift, sensor noise), plus the timing helpers both report with.
#pragma once

#include <time.h>

#include <algorithm>
#include <stdexcept>
#include <string>
#include <vector>

#include "models/skinning.h"
#include "models/template_generator.h"
#include "sensors/motion.h"
#include "sensors/subject_texture.h"
#include "sensors/virtual_kinect.h"

namespace artex {
namespace bench {

inline double ProcessCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

inline double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Posed template and colour image per frame.
struct WalkSequence {
  Template body;
  cv::Mat texture;  // the subject's true texture
  PinholeCamera camera;
  std::vector<Eigen::MatrixX3d> posed;
  std::vector<cv::Mat> color;
};

constexpr int kSubjectTextureSize = 1024;  // the true texture (rendering only)
constexpr double kMotionRampSeconds = 0.3;

// The walk of `frames` frames seen by a virtual Kinect with these options (a few seconds).
inline WalkSequence MakeWalk(int frames, const VirtualKinectOptions& kinect_options) {
  WalkSequence s;
  s.body = GenerateTemplate();
  SubjectTextureOptions texture_options;
  texture_options.size = kSubjectTextureSize;
  s.texture = GenerateSubjectTexture(s.body, texture_options);
  MotionOptions motion;
  motion.type = MotionType::kWalk;
  motion.frames = frames;
  motion.ramp_s = kMotionRampSeconds;
  const std::vector<Pose> poses = GenerateMotion(s.body, motion);
  const Skinning skinning(s.body);
  const VirtualKinect kinect(kinect_options, s.body, s.texture);
  s.camera = kinect.calibration().color;
  const std::vector<ColorConditions> conditions = GenerateColorConditions(
      kinect.options().color_model, kinect.options().seed, static_cast<int>(poses.size()));
  for (std::size_t f = 0; f < poses.size(); ++f) {
    Eigen::MatrixX3d posed;
    skinning.Apply(poses[f], &posed);
    s.color.push_back(kinect.RenderColor(static_cast<int>(f), &posed, conditions[f]));
    s.posed.push_back(std::move(posed));
  }
  return s;
}

// MakeWalk with the virtual Kinect's defaults, built on the first call; every later call must
// ask for the same length.
inline const WalkSequence& Walk(int frames) {
  static const WalkSequence seq = MakeWalk(frames, VirtualKinectOptions());
  if (static_cast<int>(seq.posed.size()) != frames)
    throw std::logic_error("Walk: built with " + std::to_string(seq.posed.size()) +
                           " frames, asked for " + std::to_string(frames));
  return seq;
}

}  // namespace bench
}  // namespace artex
