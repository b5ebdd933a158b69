// A TUM RGB-D folder (sensors/tum_reader.h): the input is rgb.txt, depth.txt and camera.yaml
// (fuzz_input.h parts); the reader's constructor and its first frames.
#include "fuzz/fuzz_input.h"
#include "models/error.h"
#include "sensors/tum_reader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::vector<std::string> parts = artex::fuzz::Parts(data, size, 3);
  artex::fuzz::WriteFile("tum/rgb.txt", parts[0]);
  artex::fuzz::WriteFile("tum/depth.txt", parts[1]);
  artex::fuzz::WriteFile("tum/camera.yaml", parts[2]);
  try {
    artex::TumReader reader(artex::fuzz::Scratch() + "/tum");
    artex::Frame frame;
    std::string warning;
    for (int i = 0; i < reader.num_frames() && i < 2; ++i) reader.ReadFrame(i, &frame, &warning);
  } catch (const artex::Error&) {
  }
  return 0;
}
