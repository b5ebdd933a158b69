// The pipeline tests' shared set-up (pipeline_test.cc, pipeline_shape_test.cc): a short
// virtual-Kinect walk per test program, the default configuration with a small texture atlas,
// and runs into the fixture's folder.
#pragma once

#include <filesystem>
#include <string>

#include "experiments/config.h"
#include "experiments/pipeline.h"
#include "tests/solvers/virtual_kinect_scans.h"

namespace artex {
namespace pipeline_test {

inline constexpr int kFrames = 6;
inline constexpr int kAtlasSize = 256;

// The fixture's folder name, defined by each test program (they may run at once).
const char* FixtureName();

// Per-process fixture data: a 6-frame walk from the virtual Kinect (default noise, half-size
// depth camera, small colour camera, coarse subject) and a coarse tracking template, made once.
inline const testing_util::SequenceFixture& TestData() {
  static const testing_util::SequenceFixture data(FixtureName(),
                                                  testing_util::SmallSequenceOptions(kFrames));
  return data;
}

// The default configuration with a small texture atlas (texturing on).
inline Config SmallConfig() {
  Config config = Config::Load(std::string(ARTEX_SOURCE_DIR) + "/configs/default.yaml");
  config.Set("texture.atlas_size", std::to_string(kAtlasSize));
  config.Set("pipeline.texture", "true");
  return config;
}

inline PipelineResult Track(const std::string& sequence, const std::string& out,
                            const Config& config = SmallConfig()) {
  const PipelineOptions options = LoadPipelineOptions(config);
  return RunPipeline(sequence, TestData().template_path, options, config, out);
}

inline std::filesystem::path OutDir(const std::string& name) { return TestData().root / name; }

}  // namespace pipeline_test
}  // namespace artex
