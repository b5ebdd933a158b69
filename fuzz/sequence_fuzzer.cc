// An artex sequence (sensors/sequence.h): the input is frames.csv, groundtruth/poses.csv and
// one ground-truth vertex file (fuzz_input.h parts) beside a valid calibration.yaml; the
// reader's constructor, every frame and every frame's ground truth are read.
#include <filesystem>

#include "fuzz/fuzz_input.h"
#include "models/error.h"
#include "sensors/calibration.h"
#include "sensors/sequence.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  namespace fs = std::filesystem;
  const std::vector<std::string> parts = artex::fuzz::Parts(data, size, 3);
  const std::string folder = artex::fuzz::Scratch() + "/sequence";
  static const bool calibrated = [&] {
    fs::create_directories(folder);
    artex::Calibration c;
    c.depth.width = c.color.width = 8;
    c.depth.height = c.color.height = 6;
    c.depth.cx = c.color.cx = 3.5;
    c.depth.cy = c.color.cy = 2.5;
    artex::WriteCalibration(c, folder + "/calibration.yaml");
    return true;
  }();
  (void)calibrated;
  artex::fuzz::WriteFile("sequence/frames.csv", parts[0]);
  artex::fuzz::WriteFile("sequence/groundtruth/poses.csv", parts[1]);
  artex::fuzz::WriteFile("sequence/groundtruth/vertices/000000.bin", parts[2]);
  try {
    artex::SequenceReader reader(folder);
    artex::Frame frame;
    std::string warning;
    for (int i = 0; i < reader.num_frames() && i < 4; ++i) {
      reader.ReadFrame(i, &frame, &warning);
      if (reader.has_ground_truth()) {
        try {
          reader.ReadGroundTruth(i);
        } catch (const artex::Error&) {
        }
      }
    }
    reader.ReadBackgroundFrames();
  } catch (const artex::Error&) {
  }
  return 0;
}
