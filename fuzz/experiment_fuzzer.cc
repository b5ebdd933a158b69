// ParseExperiment (experiments/runner.h) on arbitrary YAML: parsed and validated, never run.
#include "experiments/runner.h"
#include "fuzz/fuzz_input.h"
#include "models/error.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    artex::ParseExperiment(std::string(reinterpret_cast<const char*>(data), size), "fuzz.yaml",
                           artex::fuzz::Scratch());
  } catch (const artex::Error&) {
  }
  return 0;
}
