// ReadPoseCsv (experiments/pose_csv.h) on arbitrary text, for a 17-joint template.
#include "experiments/pose_csv.h"
#include "fuzz/fuzz_input.h"
#include "models/error.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path =
      artex::fuzz::WriteFile("poses.csv", std::string(reinterpret_cast<const char*>(data), size));
  try {
    artex::ReadPoseCsv(path, 17);
  } catch (const artex::Error&) {
  }
  return 0;
}
