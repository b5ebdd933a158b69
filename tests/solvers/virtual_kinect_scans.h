// Virtual Kinect fixtures for the fit-quality and initialisation tests: a short sequence
// synthesised into a temporary folder (small colour camera and texture: the fits never read
// colour), read back and preprocessed with a background model trained on its empty-scene
// frames, giving the scans, the ground-truth poses and the depth camera.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>
#include <vector>

#include "models/pose.h"
#include "render/camera.h"
#include "sensors/preprocess.h"
#include "sensors/scan.h"
#include "sensors/sequence.h"
#include "sensors/virtual_kinect.h"

namespace artex {
namespace testing_util {

struct KinectScans {
  std::vector<Scan> scans;
  std::vector<Pose> truth;  // ground-truth poses of the subject (scale 1, its own shape)
  PinholeCamera depth_camera;
};

// Default synthesis of these tests: walk, default sensor noise, default subject shape.
inline SynthOptions TestSynthOptions(int frames) {
  SynthOptions options;
  options.motion.type = MotionType::kWalk;
  options.motion.frames = frames;
  options.kinect.SetNoiseLevel(NoiseLevel::kDefault);
  options.kinect.color_width = 160;
  options.kinect.color_height = 204;
  options.texture.size = 256;
  options.background_frames = 5;
  options.write_subject_glb = false;
  return options;
}

// Synthesises `options` into a temporary folder named after `name`, preprocesses frames
// [0, options.motion.frames) and removes the folder.
inline KinectScans SynthesizeScans(const SynthOptions& options, const std::string& name) {
  namespace fs = std::filesystem;
  const fs::path dir =
      fs::temp_directory_path() / ("artex_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  SynthesizeSequence(options, dir.string());
  KinectScans out;
  {
    SequenceReader reader(dir.string());
    out.depth_camera = reader.calibration().depth;
    Preprocessor preprocessor(reader.calibration());
    preprocessor.Train(reader.ReadBackgroundFrames());
    Frame frame;
    std::string warning;
    for (int i = 0; i < reader.num_frames(); ++i) {
      if (!reader.ReadFrame(i, &frame, &warning)) continue;
      Scan scan;
      preprocessor.Process(frame, &scan);
      out.scans.push_back(std::move(scan));
      out.truth.push_back(reader.ReadGroundTruth(i).pose);
    }
  }
  fs::remove_all(dir);
  return out;
}

}  // namespace testing_util
}  // namespace artex
