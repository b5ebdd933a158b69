// MRF solvers on a texturing-like view-selection problem (docs/design.md "Texture", eq. 14): the
// 25,088 triangles of a 112 x 112 x 2 triangulated grid (37,408 shared edges), 10 images, each
// triangle visible in ~4 of them (+inf elsewhere). D = beta (1 - W) + (1 - beta) age with W a
// smooth random viewing-quality field per image; V_ij = 0 if equal, else edge length times
// (1 - alpha) ||I_a - I_b||^2 + alpha (squared colour difference at the edge midpoint between two
// smoothly mis-registered images: not a metric, so expansion moves need truncation).
// Median figures: --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <vector>

#include "solvers/mrf.h"

namespace artex {
namespace {

constexpr int kGrid = 112;                // cells per side; 2 triangles per cell
constexpr int kNumImages = 10;            // labels
constexpr double kVisibleFraction = 0.4;  // share of triangles each image sees
constexpr double kBeta = 0.7;             // quality vs age in D
constexpr double kAlpha = 0.3;            // Potts part of V
constexpr double kColourScale = 20.0;
constexpr double kLambda = 0.25;
constexpr int kNumWaves = 5;  // sinusoids per smooth random field
constexpr std::uint64_t kSeed = 2024;
constexpr std::uint64_t kPerturbSeed = 7;
constexpr double kPerturbation = 0.05;  // relative unary noise of the "next frame"

// A smooth random field on [0, 1]^2 with values in about [-1, 1].
class SmoothField {
 public:
  explicit SmoothField(std::mt19937_64* rng) {
    std::uniform_real_distribution<double> u(0.0, 1.0);
    for (auto& w : waves_) w = {6.0 * u(*rng) - 3.0, 6.0 * u(*rng) - 3.0, 6.283 * u(*rng)};
  }
  double operator()(double x, double y) const {
    double v = 0.0;
    for (const auto& w : waves_) v += std::sin(3.1416 * (w[0] * x + w[1] * y) + w[2]);
    return v / std::sqrt(static_cast<double>(kNumWaves));
  }

 private:
  std::array<std::array<double, 3>, kNumWaves> waves_;
};

struct Triangle {
  double cx, cy;  // centroid in [0, 1]^2
};

// Triangle t of cell (r, c): 2 (r kGrid + c) + {0: lower-left, 1: upper-right}.
std::vector<Triangle> Triangles() {
  std::vector<Triangle> triangles;
  const double h = 1.0 / kGrid;
  for (int r = 0; r < kGrid; ++r) {
    for (int c = 0; c < kGrid; ++c) {
      triangles.push_back({(c + 1.0 / 3.0) * h, (r + 1.0 / 3.0) * h});
      triangles.push_back({(c + 2.0 / 3.0) * h, (r + 2.0 / 3.0) * h});
    }
  }
  return triangles;
}

struct SharedEdge {
  int a, b;
  double mx, my, length;
};

std::vector<SharedEdge> SharedEdges() {
  std::vector<SharedEdge> edges;
  const double h = 1.0 / kGrid;
  auto id = [](int r, int c, int k) { return 2 * (r * kGrid + c) + k; };
  for (int r = 0; r < kGrid; ++r) {
    for (int c = 0; c < kGrid; ++c) {
      edges.push_back({id(r, c, 0), id(r, c, 1), (c + 0.5) * h, (r + 0.5) * h, std::sqrt(2.0)});
      if (c + 1 < kGrid)
        edges.push_back({id(r, c, 1), id(r, c + 1, 0), (c + 1) * h, (r + 0.5) * h, 1.0});
      if (r + 1 < kGrid)
        edges.push_back({id(r, c, 1), id(r + 1, c, 0), (c + 0.5) * h, (r + 1) * h, 1.0});
    }
  }
  return edges;
}

struct Scene {
  std::vector<SmoothField> quality;                // per image
  std::vector<std::array<SmoothField, 3>> colour;  // per image: registration error per channel
  std::vector<double> age;                         // per image, in [0, 1]
};

Scene MakeScene() {
  std::mt19937_64 rng(kSeed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Scene scene;
  for (int l = 0; l < kNumImages; ++l) {
    scene.quality.emplace_back(&rng);
    scene.colour.push_back({SmoothField(&rng), SmoothField(&rng), SmoothField(&rng)});
    scene.age.push_back(u(rng));
  }
  return scene;
}

// The sampled scene: per-triangle candidate images and unaries, per-edge midpoint colours.
struct Frame {
  std::vector<std::vector<int>> labels;
  std::vector<std::vector<double>> costs;
  std::vector<SharedEdge> edges;
  std::vector<std::array<double, 3>> colour;  // edges x images
};

// perturb_seed 0: the first frame; otherwise unaries scaled by 1 + kPerturbation * N(0, 1).
Frame SampleFrame(const Scene& scene, std::uint64_t perturb_seed) {
  const std::vector<Triangle> triangles = Triangles();
  const int n = static_cast<int>(triangles.size());
  // W in [0, 1] per triangle and image; each image sees the kVisibleFraction best triangles.
  std::vector<double> w(static_cast<std::size_t>(n) * kNumImages);
  std::vector<double> threshold(kNumImages);
  for (int l = 0; l < kNumImages; ++l) {
    std::vector<double> values(n);
    for (int i = 0; i < n; ++i) {
      values[i] = w[i * kNumImages + l] =
          0.5 + 0.5 * std::tanh(scene.quality[l](triangles[i].cx, triangles[i].cy));
    }
    const int q = static_cast<int>((1.0 - kVisibleFraction) * n);
    std::nth_element(values.begin(), values.begin() + q, values.end());
    threshold[l] = values[q];
  }
  std::mt19937_64 rng(perturb_seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  Frame frame;
  frame.labels.resize(n);
  frame.costs.resize(n);
  for (int i = 0; i < n; ++i) {
    const double* wi = &w[i * kNumImages];
    const int best = static_cast<int>(std::max_element(wi, wi + kNumImages) - wi);
    for (int l = 0; l < kNumImages; ++l) {
      if (wi[l] < threshold[l] && l != best) continue;  // not visible
      double d = kBeta * (1.0 - wi[l]) + (1.0 - kBeta) * scene.age[l];
      if (perturb_seed != 0) d *= 1.0 + kPerturbation * normal(rng);
      frame.labels[i].push_back(l);
      frame.costs[i].push_back(d);
    }
  }
  // Each image's colour at each edge midpoint (the integral of Pi_e reduced to one sample).
  frame.edges = SharedEdges();
  frame.colour.resize(frame.edges.size() * kNumImages);
  for (std::size_t e = 0; e < frame.edges.size(); ++e) {
    for (int l = 0; l < kNumImages; ++l) {
      for (int ch = 0; ch < 3; ++ch) {
        frame.colour[e * kNumImages + l][ch] =
            0.1 * scene.colour[l][ch](frame.edges[e].mx, frame.edges[e].my);
      }
    }
  }
  return frame;
}

MrfProblem BuildProblem(const Frame& frame) {
  MrfProblem problem(kNumImages);
  for (std::size_t i = 0; i < frame.labels.size(); ++i) {
    problem.AddNode(frame.labels[i], frame.costs[i]);
  }
  for (std::size_t e = 0; e < frame.edges.size(); ++e) {
    const std::array<double, 3>* c = &frame.colour[e * kNumImages];
    const SharedEdge& edge = frame.edges[e];
    problem.AddEdge(edge.a, edge.b, edge.length, [c](int a, int b) {
      if (a == b) return 0.0;
      double d2 = 0.0;
      for (int ch = 0; ch < 3; ++ch) d2 += (c[a][ch] - c[b][ch]) * (c[a][ch] - c[b][ch]);
      return (1.0 - kAlpha) * kColourScale * d2 + kAlpha;
    });
  }
  problem.set_smoothness(kLambda);
  return problem;
}

MrfProblem MakeProblem(const Scene& scene, std::uint64_t perturb_seed) {
  return BuildProblem(SampleFrame(scene, perturb_seed));
}

void Report(benchmark::State& state, const MrfProblem& problem, const MrfSummary& summary) {
  state.counters["initial"] = summary.initial_energy;
  state.counters["energy"] = summary.energy;
  state.counters["sweeps"] = summary.iterations;
  if (summary.lower_bound > -std::numeric_limits<double>::infinity()) {
    state.counters["bound"] = summary.lower_bound;
  }
  state.counters["truncated"] = static_cast<double>(summary.truncated_terms);
  state.counters["nodes"] = problem.num_nodes();
  state.counters["edges"] = problem.num_edges();
}

// MrfProblem construction alone (AddNode + AddEdge with its cost callback), scene pre-sampled.
void BM_BuildProblem(benchmark::State& state) {
  const Frame frame = SampleFrame(MakeScene(), 0);
  for (auto _ : state) {
    MrfProblem problem = BuildProblem(frame);
    benchmark::DoNotOptimize(problem.num_edges());
    state.counters["MB"] = problem.MemoryBytes() / 1e6;
  }
}
BENCHMARK(BM_BuildProblem)->Unit(benchmark::kMillisecond);

// Cold start (per-node unary argmin), one solver per argument (MrfSolverType).
void BM_Solve(benchmark::State& state) {
  const MrfProblem problem = MakeProblem(MakeScene(), 0);
  MrfSolverOptions options;
  options.type = static_cast<MrfSolverType>(state.range(0));
  const auto solver = MrfSolver::Create(options);
  state.SetLabel(MrfSolverTypeToString(options.type));
  MrfSummary summary;
  for (auto _ : state) {
    std::vector<int> labels;
    summary = solver->Solve(problem, &labels);
  }
  Report(state, problem, summary);
}
BENCHMARK(BM_Solve)
    ->Arg(static_cast<int>(MrfSolverType::kAlphaExpansion))
    ->Arg(static_cast<int>(MrfSolverType::kAlphaBetaSwap))
    ->Arg(static_cast<int>(MrfSolverType::kIcm))
    ->Arg(static_cast<int>(MrfSolverType::kTrws))
    ->Unit(benchmark::kMillisecond);

// The per-frame case: the next frame's unaries differ by kPerturbation; alpha-expansion starts
// from the previous frame's solution (warm 1) or from the unary argmin (warm 0). kept_solver 1:
// one solver solves every iteration (as the texturer's, whose min-cut graphs then keep their
// arrays from the previous solve); 0: a new solver per iteration (graphs grown from empty, as
// every solve was before the solver kept them).
void BM_ExpansionNextFrame(benchmark::State& state) {
  const Scene scene = MakeScene();
  const MrfProblem first = MakeProblem(scene, 0);
  const MrfProblem next = MakeProblem(scene, kPerturbSeed);
  MrfSolverOptions options;
  options.type = MrfSolverType::kAlphaExpansion;
  options.warm_start = state.range(0) != 0;
  const bool kept = state.range(1) != 0;
  auto solver = MrfSolver::Create(options);
  std::vector<int> previous;
  solver->Solve(first, &previous);
  state.SetLabel(options.warm_start ? "warm" : "cold");
  MrfSummary summary;
  for (auto _ : state) {
    if (!kept) solver = MrfSolver::Create(options);
    std::vector<int> labels = previous;
    summary = solver->Solve(next, &labels);
  }
  Report(state, next, summary);
}
BENCHMARK(BM_ExpansionNextFrame)
    ->ArgNames({"warm", "kept_solver"})
    ->ArgsProduct({{0, 1}, {0, 1}})
    ->Unit(benchmark::kMillisecond);

// TRW-S bound of the next frame, for the gap of the warm-started expansion.
void BM_TrwsNextFrame(benchmark::State& state) {
  const MrfProblem next = MakeProblem(MakeScene(), kPerturbSeed);
  MrfSolverOptions options;
  options.type = MrfSolverType::kTrws;
  const auto solver = MrfSolver::Create(options);
  MrfSummary summary;
  for (auto _ : state) {
    std::vector<int> labels;
    summary = solver->Solve(next, &labels);
  }
  Report(state, next, summary);
}
BENCHMARK(BM_TrwsNextFrame)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace artex
