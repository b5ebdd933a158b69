// ReadCalibration (sensors/calibration.h) on arbitrary text.
#include "fuzz/fuzz_input.h"
#include "models/error.h"
#include "sensors/calibration.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = artex::fuzz::WriteFile(
      "calibration.yaml", std::string(reinterpret_cast<const char*>(data), size));
  try {
    artex::ReadCalibration(path);
  } catch (const artex::Error&) {
  }
  return 0;
}
