// A configuration (experiments/config.h, LoadPipelineOptions) and a `--set key=value`
// override: the input's first line is the override, the rest the YAML file.
#include "experiments/config.h"
#include "experiments/pipeline.h"
#include "fuzz/fuzz_input.h"
#include "models/error.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  const size_t newline = text.find('\n');
  const std::string set = text.substr(0, newline);
  const std::string yaml = newline == std::string::npos ? "" : text.substr(newline + 1);
  try {
    artex::Config config = artex::Config::FromString(yaml, "fuzz.yaml");
    const size_t eq = set.find('=');
    if (eq != std::string::npos && eq > 0) config.Set(set.substr(0, eq), set.substr(eq + 1));
    const artex::PipelineOptions options = artex::LoadPipelineOptions(config);
    std::string why;
    options.IsValid(&why);
    config.ToYaml();
  } catch (const artex::Error&) {
  }
  return 0;
}
