// Virtual Kinect fixtures. For the fit-quality and initialisation tests: a short sequence
// synthesised into a temporary folder (small colour camera and texture: the fits never read
// colour), read back and preprocessed with a background model trained on its empty-scene
// frames, giving the scans, the ground-truth poses and the depth camera. For the pipeline
// tests (tests/experiments/): a small sequence and the coarse tracking template on disk.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>
#include <vector>

#include "models/pose.h"
#include "models/template_io.h"
#include "render/camera.h"
#include "sensors/preprocess.h"
#include "sensors/scan.h"
#include "sensors/sequence.h"
#include "sensors/virtual_kinect.h"
#include "tests/testing_util.h"

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

// Synthesises `options` into FreshTempDir(name)/sequence, preprocesses frames
// [0, options.motion.frames) and removes the folder.
inline KinectScans SynthesizeScans(const SynthOptions& options, const std::string& name) {
  namespace fs = std::filesystem;
  const fs::path dir = FreshTempDir(name);
  const std::string sequence = (dir / "sequence").string();
  SynthesizeSequence(options, sequence);
  KinectScans out;
  {
    SequenceReader reader(sequence);
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

// TestSynthOptions on the small cameras of the pipeline tests: the depth camera at half size
// (320 x 240, f = 262.5), the coarsest subject, and its textured mesh written (the ground truth
// of the texture quality).
inline SynthOptions SmallSequenceOptions(int frames) {
  SynthOptions options = TestSynthOptions(frames);
  PinholeCamera& depth = options.kinect.depth_intrinsics;
  depth.width = 320;
  depth.height = 240;
  depth.fx = depth.fy = 262.5;
  depth.cx = 159.5;
  depth.cy = 119.5;
  options.subject_shape.resolution = 0;
  options.write_subject_glb = SynthOptions().write_subject_glb;
  return options;
}

// A sequence synthesised from `options` into root/sequence and the coarse tracking template
// (CoarseTemplate()) in root/template.glb, root = FreshTempDir(name); removed with the object
// (kept with ARTEX_KEEP_TEST_DIRS, as FreshTempDir's folders).
class SequenceFixture {
 public:
  SequenceFixture(const std::string& name, const SynthOptions& options)
      : root(FreshTempDir(name)),
        sequence((root / "sequence").string()),
        template_path((root / "template.glb").string()) {
    SynthesizeSequence(options, sequence);
    WriteTemplateGlb(template_path, CoarseTemplate());
  }
  ~SequenceFixture() {
    if (std::getenv("ARTEX_KEEP_TEST_DIRS") != nullptr) return;
    std::error_code ec;
    std::filesystem::remove_all(root, ec);
  }
  SequenceFixture(const SequenceFixture&) = delete;
  SequenceFixture& operator=(const SequenceFixture&) = delete;

  const std::filesystem::path root;
  const std::string sequence;
  const std::string template_path;
};

}  // namespace testing_util
}  // namespace artex
