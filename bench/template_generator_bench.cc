// Generation time of the default human template (implicit body, meshing, skinning constants,
// UV atlas) at both resolutions, and of the atlas alone.
#include <benchmark/benchmark.h>

#include "models/template_generator.h"
#include "models/uv_atlas.h"

namespace artex {
namespace {

void BM_GenerateTemplate(benchmark::State& state) {
  BodyShapeOptions options;
  options.resolution = static_cast<int>(state.range(0));
  TemplateGeneratorOptions generator;
  generator.build_atlas = state.range(1) != 0;
  int vertices = 0;
  for (auto _ : state) {
    const Template t = GenerateTemplate(options, generator, nullptr);
    vertices = t.num_vertices();
    benchmark::DoNotOptimize(t.vertices.data());
  }
  state.counters["vertices"] = vertices;
}
BENCHMARK(BM_GenerateTemplate)
    ->ArgNames({"resolution", "atlas"})
    ->Args({0, 1})
    ->Args({1, 0})
    ->Args({1, 1})
    ->Unit(benchmark::kMillisecond);

void BM_BuildUvAtlas(benchmark::State& state) {
  const Template t = GenerateTemplate();
  UvAtlasOptions options;
  UvAtlas atlas;
  UvAtlasSummary summary;
  for (auto _ : state) {
    BuildUvAtlas(t.vertices, t.triangles, t.triangle_chart, Eigen::VectorXd(), options, &atlas,
                 &summary);
    benchmark::DoNotOptimize(atlas.uvs.data());
  }
  state.counters["coverage"] = summary.coverage;
}
BENCHMARK(BM_BuildUvAtlas)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace artex
