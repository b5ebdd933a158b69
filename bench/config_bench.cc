// Reading a configuration (experiments/config.h): what `artex track` does once per run and
// `artex experiment` once per combination of its grid.
//   BM_LoadDefaultConfig: Config::FromString of configs/default.yaml, then LoadPipelineOptions
//                         (every section bound, IsValid); time per configuration.
#include <benchmark/benchmark.h>

#include <fstream>
#include <sstream>
#include <string>

#include "experiments/config.h"
#include "experiments/pipeline.h"

namespace artex {
namespace {

std::string DefaultYaml() {
  std::ifstream in(std::string(ARTEX_SOURCE_DIR) + "/configs/default.yaml");
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

void BM_LoadDefaultConfig(benchmark::State& state) {
  const std::string yaml = DefaultYaml();
  if (yaml.empty()) {
    state.SkipWithError("configs/default.yaml not found");
    return;
  }
  for (auto _ : state) {
    const Config config = Config::FromString(yaml, "default.yaml");
    const PipelineOptions options = LoadPipelineOptions(config);
    std::string why;
    benchmark::DoNotOptimize(options.IsValid(&why));
  }
}
BENCHMARK(BM_LoadDefaultConfig)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace artex
