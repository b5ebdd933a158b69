// Black-box conformance of every MRF solver (in the spirit of OpenGM's blackboxtester): small
// seeded problems solved against brute force, plus problem validation and a medium sanity case.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "models/error.h"
#include "solvers/alpha_expansion.h"
#include "solvers/mrf.h"

namespace artex {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

enum class PairKind { kPotts, kTruncatedLinear, kNonMetric };

// An energy kept independently of MrfProblem, to rebuild it and to recompute energies.
struct Spec {
  int n = 0;
  int num_labels = 0;
  double lambda = 1.0;
  std::vector<double> unary;  // n x L, +inf = forbidden
  struct Edge {
    int i, j;
    double w;
    bool potts;
    std::vector<double> table;  // L x L over global labels
  };
  std::vector<Edge> edges;

  MrfProblem Build() const {
    MrfProblem problem = MrfProblem::FromDenseUnaries(n, num_labels, unary);
    problem.set_smoothness(lambda);
    for (const Edge& edge : edges) {
      if (edge.potts) {
        problem.AddPottsEdge(edge.i, edge.j, edge.w);
      } else {
        const std::vector<double>& table = edge.table;
        const int l = num_labels;
        problem.AddEdge(edge.i, edge.j, edge.w,
                        [&table, l](int a, int b) { return table[a * l + b]; });
      }
    }
    return problem;
  }

  // Tables are stored in single precision by MrfProblem (documented), hence the float cast.
  double Energy(const std::vector<int>& x) const {
    double energy = 0.0;
    for (int i = 0; i < n; ++i) energy += unary[i * num_labels + x[i]];
    for (const Edge& edge : edges) {
      const int a = x[edge.i];
      const int b = x[edge.j];
      const double c =
          edge.potts ? (a != b ? 1.0 : 0.0)
                     : static_cast<double>(static_cast<float>(edge.table[a * num_labels + b]));
      energy += lambda * edge.w * c;
    }
    return energy;
  }
};

struct BruteForce {
  double energy = kInf;
  std::vector<int> labels;
};

BruteForce Solve(const Spec& spec) {
  BruteForce best;
  std::vector<int> x(spec.n, 0);
  while (true) {
    const double e = spec.Energy(x);
    if (e < best.energy) {
      best.energy = e;
      best.labels = x;
    }
    int i = 0;
    while (i < spec.n && ++x[i] == spec.num_labels) x[i++] = 0;
    if (i == spec.n) break;
  }
  return best;
}

std::vector<std::pair<int, int>> GridEdges(int rows, int cols) {
  std::vector<std::pair<int, int>> edges;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      if (c + 1 < cols) edges.emplace_back(r * cols + c, r * cols + c + 1);
      if (r + 1 < rows) edges.emplace_back(r * cols + c, (r + 1) * cols + c);
    }
  }
  return edges;
}

std::vector<std::pair<int, int>> ChainEdges(int n) {
  std::vector<std::pair<int, int>> edges;
  for (int i = 0; i + 1 < n; ++i) edges.emplace_back(i, i + 1);
  return edges;
}

// Random connected-ish graph: a random spanning tree plus extra random edges (one repeated).
std::vector<std::pair<int, int>> RandomGraphEdges(int n, int extra, std::mt19937_64* rng) {
  std::vector<std::pair<int, int>> edges;
  for (int i = 1; i < n; ++i) {
    edges.emplace_back(std::uniform_int_distribution<int>(0, i - 1)(*rng), i);
  }
  for (int k = 0; k < extra; ++k) {
    const int a = std::uniform_int_distribution<int>(0, n - 1)(*rng);
    int b = std::uniform_int_distribution<int>(0, n - 2)(*rng);
    if (b >= a) ++b;
    edges.emplace_back(a, b);
  }
  edges.push_back(edges.front());  // a parallel edge: costs add up
  return edges;
}

Spec MakeSpec(int n, int num_labels, const std::vector<std::pair<int, int>>& edges, PairKind kind,
              double forbidden_probability, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  Spec spec;
  spec.n = n;
  spec.num_labels = num_labels;
  spec.lambda = 0.5 + 1.5 * uniform(rng);
  spec.unary.resize(n * num_labels);
  for (int i = 0; i < n; ++i) {
    bool any = false;
    for (int l = 0; l < num_labels; ++l) {
      const bool forbidden = uniform(rng) < forbidden_probability;
      spec.unary[i * num_labels + l] = forbidden ? kInf : 10.0 * uniform(rng);
      any = any || !forbidden;
    }
    if (!any) {
      spec.unary[i * num_labels + std::uniform_int_distribution<int>(0, num_labels - 1)(rng)] =
          10.0 * uniform(rng);
    }
  }
  for (const auto& [i, j] : edges) {
    Spec::Edge edge{i, j, 0.5 + 4.0 * uniform(rng), kind == PairKind::kPotts, {}};
    if (!edge.potts) {
      edge.table.resize(num_labels * num_labels);
      for (int a = 0; a < num_labels; ++a) {
        for (int b = 0; b < num_labels; ++b) {
          double c = 0.0;
          if (a != b) {
            c = kind == PairKind::kTruncatedLinear ? std::min(std::abs(a - b), 2)
                                                   : 3.0 * uniform(rng);  // asymmetric
          }
          edge.table[a * num_labels + b] = c;
        }
      }
    }
    spec.edges.push_back(edge);
  }
  return spec;
}

struct Case {
  std::string name;
  Spec spec;
  BruteForce optimum;
};

// The tiny problems: 3x3 grids and random 8-node graphs, every pair kind, some forbidden labels.
std::vector<Case> TinyCases() {
  std::vector<Case> cases;
  const PairKind kinds[] = {PairKind::kPotts, PairKind::kTruncatedLinear, PairKind::kNonMetric};
  const char* kind_names[] = {"potts", "truncated_linear", "non_metric"};
  std::uint64_t seed = 1;
  for (int k = 0; k < 3; ++k) {
    for (int num_labels = 2; num_labels <= 4; ++num_labels) {
      for (int repeat = 0; repeat < 2; ++repeat, ++seed) {
        Case grid;
        grid.name = std::string("grid3x3/") + kind_names[k] + "/L" + std::to_string(num_labels) +
                    "/seed" + std::to_string(seed);
        grid.spec = MakeSpec(9, num_labels, GridEdges(3, 3), kinds[k], 0.2, seed);
        grid.optimum = Solve(grid.spec);
        cases.push_back(grid);

        std::mt19937_64 rng(1000 + seed);
        Case graph;
        graph.name = std::string("random8/") + kind_names[k] + "/L" + std::to_string(num_labels) +
                     "/seed" + std::to_string(seed);
        graph.spec = MakeSpec(8, num_labels, RandomGraphEdges(8, 6, &rng), kinds[k], 0.2, seed);
        graph.optimum = Solve(graph.spec);
        cases.push_back(graph);
      }
    }
  }
  return cases;
}

const std::vector<Case>& Cases() {
  static const std::vector<Case> cases = TinyCases();
  return cases;
}

MrfSolverOptions Options(MrfSolverType type) {
  MrfSolverOptions options;
  options.type = type;
  options.energy_tolerance = 0.0;  // run moves to a true local minimum
  options.trws_max_iterations = 300;
  return options;
}

double Tolerance(double energy) { return 1e-9 * (1.0 + std::abs(energy)); }

class MrfConformanceTest : public ::testing::TestWithParam<MrfSolverType> {};

TEST_P(MrfConformanceTest, FeasibleLabelsConsistentEnergyValidBound) {
  const MrfSolverType type = GetParam();
  for (const Case& c : Cases()) {
    SCOPED_TRACE(c.name);
    const MrfProblem problem = c.spec.Build();
    auto solver = MrfSolver::Create(Options(type));
    std::vector<int> labels;  // cold start
    const MrfSummary summary = solver->Solve(problem, &labels);

    ASSERT_EQ(static_cast<int>(labels.size()), c.spec.n);
    for (int i = 0; i < c.spec.n; ++i) {
      ASSERT_GE(labels[i], 0);
      ASSERT_LT(labels[i], c.spec.num_labels);
      ASSERT_TRUE(std::isfinite(c.spec.unary[i * c.spec.num_labels + labels[i]]))
          << "node " << i << " took forbidden label " << labels[i];
    }
    const double recomputed = c.spec.Energy(labels);
    EXPECT_NEAR(summary.energy, recomputed, Tolerance(recomputed));
    EXPECT_GE(summary.energy, c.optimum.energy - Tolerance(c.optimum.energy));
    EXPECT_LE(summary.energy, summary.initial_energy + Tolerance(summary.initial_energy));
    EXPECT_FALSE(summary.warm_started);
    EXPECT_FALSE(summary.termination.empty());
    EXPECT_EQ(static_cast<int>(summary.trace.size()), summary.iterations);
    EXPECT_GE(summary.iterations, 1);
    EXPECT_LE(summary.lower_bound, c.optimum.energy + Tolerance(c.optimum.energy));
    if (type == MrfSolverType::kTrws) {
      EXPECT_TRUE(std::isfinite(summary.lower_bound));
      EXPECT_EQ(summary.bound_trace.size(), summary.trace.size());
    } else {
      EXPECT_EQ(summary.lower_bound, -kInf);
    }
    // Move-making solvers and ICM never raise the energy between iterations; TRW-S reports the
    // best energy so far, which cannot rise either.
    double previous = summary.initial_energy;
    for (double e : summary.trace) {
      EXPECT_LE(e, previous + Tolerance(previous));
      previous = e;
    }
    EXPECT_NEAR(summary.trace.back(), summary.energy, Tolerance(summary.energy));
  }
}

TEST_P(MrfConformanceTest, WarmStartFromOptimumStaysOptimal) {
  for (const Case& c : Cases()) {
    SCOPED_TRACE(c.name);
    const MrfProblem problem = c.spec.Build();
    auto solver = MrfSolver::Create(Options(GetParam()));
    std::vector<int> labels = c.optimum.labels;
    const MrfSummary summary = solver->Solve(problem, &labels);
    EXPECT_TRUE(summary.warm_started);
    EXPECT_NEAR(summary.initial_energy, c.optimum.energy, Tolerance(c.optimum.energy));
    EXPECT_NEAR(summary.energy, c.optimum.energy, Tolerance(c.optimum.energy));
    EXPECT_NEAR(c.spec.Energy(labels), c.optimum.energy, Tolerance(c.optimum.energy));
  }
}

TEST_P(MrfConformanceTest, InfeasibleWarmStartFallsBackToUnaryArgmin) {
  const Case& c = Cases()[4];
  const MrfProblem problem = c.spec.Build();
  // Find a node with a forbidden label and put it there.
  std::vector<int> labels = c.optimum.labels;
  bool planted = false;
  for (int i = 0; i < c.spec.n && !planted; ++i) {
    for (int l = 0; l < c.spec.num_labels && !planted; ++l) {
      if (!std::isfinite(c.spec.unary[i * c.spec.num_labels + l])) {
        labels[i] = l;
        planted = true;
      }
    }
  }
  ASSERT_TRUE(planted);
  auto solver = MrfSolver::Create(Options(GetParam()));
  const MrfSummary summary = solver->Solve(problem, &labels);
  EXPECT_FALSE(summary.warm_started);
  EXPECT_NEAR(summary.initial_energy, c.spec.Energy(problem.UnaryArgmin()), 1e-9);
  EXPECT_TRUE(std::isfinite(c.spec.Energy(labels)));

  std::vector<int> wrong_size(3, 0);
  const MrfSummary summary2 = solver->Solve(problem, &wrong_size);
  EXPECT_FALSE(summary2.warm_started);
  EXPECT_EQ(static_cast<int>(wrong_size.size()), c.spec.n);
}

TEST_P(MrfConformanceTest, Deterministic) {
  const Case& c = Cases().back();
  const MrfProblem problem = c.spec.Build();
  std::vector<int> first, second;
  const MrfSummary a = MrfSolver::Create(Options(GetParam()))->Solve(problem, &first);
  const MrfSummary b = MrfSolver::Create(Options(GetParam()))->Solve(problem, &second);
  EXPECT_EQ(first, second);
  EXPECT_EQ(a.trace, b.trace);
  EXPECT_EQ(a.lower_bound, b.lower_bound);
}

// A solver that solved other problems before (solvers may keep buffers from solve to solve)
// gives what a new one gives: the same labels, trace and bound, for problems of growing and
// shrinking size, parallel sweeps included.
TEST_P(MrfConformanceTest, ReusedSolverMatchesNewOne) {
  MrfSolverOptions options = Options(GetParam());
  options.expansion_parallel_min_nodes = 1;
  const auto reused = MrfSolver::Create(options);
  std::mt19937_64 rng(5);
  const Spec specs[] = {
      MakeSpec(1200, 5, GridEdges(30, 40), PairKind::kPotts, 0.1, 21), Cases().back().spec,
      MakeSpec(400, 4, RandomGraphEdges(400, 300, &rng), PairKind::kNonMetric, 0.1, 22),
      Cases().front().spec};
  for (const Spec& spec : specs) {
    const MrfProblem problem = spec.Build();
    std::vector<int> fresh_labels, reused_labels;
    const MrfSummary a = MrfSolver::Create(options)->Solve(problem, &fresh_labels);
    const MrfSummary b = reused->Solve(problem, &reused_labels);
    EXPECT_EQ(fresh_labels, reused_labels) << spec.n << " nodes";
    EXPECT_EQ(a.trace, b.trace) << spec.n << " nodes";
    EXPECT_EQ(a.lower_bound, b.lower_bound) << spec.n << " nodes";
  }
}

TEST_P(MrfConformanceTest, NoEdgesGivesUnaryArgmin) {
  Spec spec = MakeSpec(6, 4, {}, PairKind::kPotts, 0.3, 77);
  const MrfProblem problem = spec.Build();
  std::vector<int> labels;
  const MrfSummary summary = MrfSolver::Create(Options(GetParam()))->Solve(problem, &labels);
  EXPECT_EQ(labels, problem.UnaryArgmin());
  EXPECT_NEAR(summary.energy, Solve(spec).energy, 1e-12);
}

TEST_P(MrfConformanceTest, EmptyProblem) {
  MrfProblem problem(3);
  std::vector<int> labels = {1, 2};
  const MrfSummary summary = MrfSolver::Create(Options(GetParam()))->Solve(problem, &labels);
  EXPECT_TRUE(labels.empty());
  EXPECT_EQ(summary.energy, 0.0);
}

TEST_P(MrfConformanceTest, CallbackStopsAfterFirstIteration) {
  const Case& c = Cases()[10];
  const MrfProblem problem = c.spec.Build();
  MrfSolverOptions options = Options(GetParam());
  int calls = 0;
  options.callback = [&calls](const MrfIterationInfo& info) {
    ++calls;
    EXPECT_EQ(info.iteration, calls);
    return false;
  };
  std::vector<int> labels;
  const MrfSummary summary = MrfSolver::Create(options)->Solve(problem, &labels);
  EXPECT_EQ(calls, 1);
  EXPECT_EQ(summary.iterations, 1);
  EXPECT_EQ(summary.termination, "callback");
  EXPECT_TRUE(problem.IsFeasible(labels));
}

INSTANTIATE_TEST_SUITE_P(AllSolvers, MrfConformanceTest, ::testing::ValuesIn(AllMrfSolverTypes()),
                         [](const ::testing::TestParamInfo<MrfSolverType>& info) {
                           return std::string(MrfSolverTypeToString(info.param));
                         });

TEST(MrfGuaranteesTest, AlphaExpansionWithinTwiceOptimumOnPotts) {
  int checked = 0;
  for (const Case& c : Cases()) {
    if (!c.spec.edges.front().potts) continue;
    SCOPED_TRACE(c.name);
    std::vector<int> labels;
    const MrfSummary summary =
        MrfSolver::Create(Options(MrfSolverType::kAlphaExpansion))->Solve(c.spec.Build(), &labels);
    EXPECT_EQ(summary.termination, "converged");
    EXPECT_LE(summary.energy, 2.0 * c.optimum.energy + Tolerance(c.optimum.energy));
    ++checked;
  }
  EXPECT_GE(checked, 10);
}

TEST(MrfGuaranteesTest, GraphCutsExactOnSubmodularTwoLabelProblems) {
  // Zero diagonal and non-negative off-diagonal costs make every two-label pair term submodular.
  for (int seed = 0; seed < 12; ++seed) {
    std::mt19937_64 rng(500 + seed);
    const PairKind kind = seed % 2 ? PairKind::kPotts : PairKind::kNonMetric;
    const Spec spec = seed % 3 ? MakeSpec(9, 2, GridEdges(3, 3), kind, 0.15, 500 + seed)
                               : MakeSpec(10, 2, RandomGraphEdges(10, 8, &rng), kind, 0.15, seed);
    const BruteForce optimum = Solve(spec);
    const MrfProblem problem = spec.Build();
    for (MrfSolverType type : {MrfSolverType::kAlphaExpansion, MrfSolverType::kAlphaBetaSwap}) {
      SCOPED_TRACE(std::string(MrfSolverTypeToString(type)) + " seed " + std::to_string(seed));
      std::vector<int> labels;
      const MrfSummary summary = MrfSolver::Create(Options(type))->Solve(problem, &labels);
      EXPECT_NEAR(summary.energy, optimum.energy, Tolerance(optimum.energy));
      EXPECT_EQ(summary.truncated_terms, 0);
    }
  }
}

TEST(MrfGuaranteesTest, TrwsExactOnChains) {
  const PairKind kinds[] = {PairKind::kPotts, PairKind::kTruncatedLinear, PairKind::kNonMetric};
  for (int seed = 0; seed < 9; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    const Spec spec = MakeSpec(9, 2 + seed % 3, ChainEdges(9), kinds[seed % 3], 0.2, 900 + seed);
    const BruteForce optimum = Solve(spec);
    std::vector<int> labels;
    const MrfSummary summary =
        MrfSolver::Create(Options(MrfSolverType::kTrws))->Solve(spec.Build(), &labels);
    EXPECT_NEAR(summary.energy, optimum.energy, Tolerance(optimum.energy));
    EXPECT_NEAR(summary.lower_bound, optimum.energy, 1e-7 * (1.0 + optimum.energy));
    EXPECT_EQ(summary.termination, "optimal");
  }
}

TEST(MrfGuaranteesTest, NonMetricExpansionTruncatesAndStaysMonotone) {
  long truncated = 0;
  for (const Case& c : Cases()) {
    if (c.spec.edges.front().potts || c.spec.num_labels < 3) continue;
    std::vector<int> labels;
    const MrfSummary summary =
        MrfSolver::Create(Options(MrfSolverType::kAlphaExpansion))->Solve(c.spec.Build(), &labels);
    truncated += summary.truncated_terms;
    EXPECT_LE(summary.energy, summary.initial_energy);
  }
  EXPECT_GT(truncated, 0);  // the non-metric cases do exercise the truncation
}

// 5000 nodes, 6 labels, Potts: noisy observations of a piecewise-constant labelling.
TEST(MrfGuaranteesTest, MediumPottsExpansionBeatsIcmAndIsNearTrwsBound) {
  const int rows = 50, cols = 100, num_labels = 6;
  std::mt19937_64 rng(4242);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::vector<std::pair<double, double>> seeds(24);
  for (auto& s : seeds) s = {rows * uniform(rng), cols * uniform(rng)};
  MrfProblem problem(num_labels);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      int nearest = 0;
      double best = kInf;
      for (int k = 0; k < static_cast<int>(seeds.size()); ++k) {
        const double d = std::hypot(r - seeds[k].first, c - seeds[k].second);
        if (d < best) best = d, nearest = k;
      }
      std::vector<double> costs(num_labels);
      for (int l = 0; l < num_labels; ++l) {
        costs[l] = (l == nearest % num_labels ? 0.0 : 1.0) + 3.0 * uniform(rng);
      }
      problem.AddNodeDense(costs);
    }
  }
  for (const auto& [i, j] : GridEdges(rows, cols)) problem.AddPottsEdge(i, j, 1.0);
  problem.set_smoothness(1.0);

  std::vector<int> expansion, icm, trws;
  const MrfSummary e =
      MrfSolver::Create(Options(MrfSolverType::kAlphaExpansion))->Solve(problem, &expansion);
  const MrfSummary i = MrfSolver::Create(Options(MrfSolverType::kIcm))->Solve(problem, &icm);
  const MrfSummary t = MrfSolver::Create(Options(MrfSolverType::kTrws))->Solve(problem, &trws);
  EXPECT_LT(e.energy, i.energy);
  EXPECT_LE(t.lower_bound, e.energy + Tolerance(e.energy));
  EXPECT_LE(t.lower_bound, t.energy + Tolerance(t.energy));
  EXPECT_LE(e.energy - t.lower_bound, 0.03 * std::abs(t.lower_bound));
  EXPECT_NEAR(e.energy, problem.Energy(expansion), Tolerance(e.energy));
}

TEST(MrfGuaranteesTest, BisectionSeparatesTheHalves) {
  // A 30 x 40 grid and a random graph (small diameter, so large levels) with two components (the
  // second: a 12-node chain).
  std::mt19937_64 rng(77);
  std::vector<std::pair<int, int>> random_edges = RandomGraphEdges(300, 200, &rng);
  for (const auto& [i, j] : ChainEdges(12)) random_edges.emplace_back(300 + i, 300 + j);
  const std::pair<int, std::vector<std::pair<int, int>>> graphs[] = {{1200, GridEdges(30, 40)},
                                                                     {312, random_edges}};
  for (const auto& [n, edges] : graphs) {
    const MrfProblem problem = MakeSpec(n, 3, edges, PairKind::kPotts, 0.0, 5).Build();
    const std::vector<char> part =
        mrf_internal::BisectByLevels(problem, BuildMrfAdjacency(problem));
    ASSERT_EQ(static_cast<int>(part.size()), n);
    int count[3] = {0, 0, 0};
    for (char p : part) {
      ASSERT_TRUE(p == 0 || p == 1 || p == mrf_internal::kSeparatorPart);
      ++count[static_cast<int>(p)];
    }
    for (const auto& [i, j] : edges) {
      EXPECT_FALSE((part[i] == 0 && part[j] == 1) || (part[i] == 1 && part[j] == 0))
          << "edge " << i << "-" << j << " joins the halves";
    }
    EXPECT_GT(count[0], 0);
    EXPECT_GT(count[1], 0);
    if (n == 1200) {  // on the grid: balanced, with a separator much smaller than the halves
      EXPECT_GT(count[0], n / 3);
      EXPECT_GT(count[1], n / 3);
      EXPECT_LT(count[2], n / 16);
    }
  }
}

// A parallel first sweep (two halves concurrently, then the separator): the energy never rises, the
// result does not depend on the number of threads, and "converged" still means that no
// expansion move over the whole problem lowers the energy.
TEST(MrfGuaranteesTest, ParallelExpansionSweepsAreMonotoneDeterministicAndConverge) {
  std::mt19937_64 rng(91);
  const Spec specs[] = {
      MakeSpec(1200, 5, GridEdges(30, 40), PairKind::kPotts, 0.1, 11),
      MakeSpec(1200, 4, GridEdges(40, 30), PairKind::kTruncatedLinear, 0.1, 12),
      MakeSpec(400, 4, RandomGraphEdges(400, 300, &rng), PairKind::kNonMetric, 0.1, 13)};
  for (const Spec& spec : specs) {
    const MrfProblem problem = spec.Build();
    MrfSolverOptions options = Options(MrfSolverType::kAlphaExpansion);
    options.expansion_parallel_min_nodes = 1;
    std::vector<double> energies;
    options.callback = [&energies](const MrfIterationInfo& info) {
      energies.push_back(info.energy);
      return true;
    };
    std::vector<int> labels;
    const MrfSummary summary = MrfSolver::Create(options)->Solve(problem, &labels);
    EXPECT_EQ(summary.termination, "converged");
    ASSERT_GE(energies.size(), 2u);  // at least one parallel sweep and one whole sweep
    EXPECT_LE(energies.front(), summary.initial_energy + Tolerance(summary.initial_energy));
    for (std::size_t k = 1; k < energies.size(); ++k)
      EXPECT_LE(energies[k], energies[k - 1] + Tolerance(energies[k - 1]));
    EXPECT_NEAR(summary.energy, spec.Energy(labels), Tolerance(summary.energy));

    // One sequential sweep from the result changes nothing.
    MrfSolverOptions sequential = Options(MrfSolverType::kAlphaExpansion);
    sequential.expansion_parallel_min_nodes = 0;
    sequential.max_iterations = 1;
    std::vector<int> again = labels;
    const MrfSummary check = MrfSolver::Create(sequential)->Solve(problem, &again);
    EXPECT_EQ(check.accepted_moves, 0);
    EXPECT_EQ(again, labels);

    // The same labelling on one thread, and for one parallel sweep.
    options.callback = nullptr;
    options.max_iterations = 1;
    std::vector<int> one_sweep, one_sweep_single_thread, single_thread;
    MrfSolver::Create(options)->Solve(problem, &one_sweep);
    {
      const tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
      MrfSolver::Create(options)->Solve(problem, &one_sweep_single_thread);
      options.max_iterations = 50;
      MrfSolver::Create(options)->Solve(problem, &single_thread);
    }
    EXPECT_EQ(one_sweep, one_sweep_single_thread);
    EXPECT_EQ(single_thread, labels);
    EXPECT_LT(problem.Energy(one_sweep), summary.initial_energy);
  }
}

TEST(MrfProblemTest, SparseCandidatesMatchDenseConstruction) {
  // Dense rows with forbidden labels vs the same candidates given sparsely (unsorted).
  MrfProblem dense = MrfProblem::FromDenseUnaries(3, 4,
                                                  {1.0, kInf, 2.0, kInf,  //
                                                   kInf, 0.5, kInf, 3.0,  //
                                                   4.0, 1.0, 2.0, 0.0});
  MrfProblem sparse(4);
  sparse.AddNode({2, 0}, {2.0, 1.0});
  sparse.AddNode({3, 1}, {3.0, 0.5});
  sparse.AddNode({0, 1, 2, 3}, {4.0, 1.0, 2.0, 0.0});
  auto cost = [](int a, int b) { return a == b ? 0.0 : 0.25 * (a + 2 * b + 1); };
  for (MrfProblem* p : {&dense, &sparse}) {
    p->AddEdge(0, 1, 2.0, cost);
    p->AddEdge(1, 2, 1.0, cost);
    p->AddPottsEdge(0, 2, 0.7);
    p->set_smoothness(1.3);
  }
  EXPECT_EQ(sparse.num_candidates(0), 2);
  EXPECT_EQ(sparse.candidate_labels(1)[0], 1);
  EXPECT_EQ(sparse.candidate_unaries(1)[1], 3.0);
  EXPECT_EQ(sparse.CandidateIndex(1, 2), -1);
  EXPECT_EQ(sparse.UnaryCost(1, 2), kInf);
  EXPECT_EQ(dense.MemoryBytes(), sparse.MemoryBytes());
  for (int a : {0, 2}) {
    for (int b : {1, 3}) {
      for (int c = 0; c < 4; ++c) {
        const std::vector<int> x = {a, b, c};
        const double expected = dense.UnaryCost(0, a) + dense.UnaryCost(1, b) +
                                dense.UnaryCost(2, c) +
                                1.3 * (2.0 * static_cast<float>(cost(a, b)) +
                                       static_cast<float>(cost(b, c)) + (a != c ? 0.7 : 0.0));
        EXPECT_NEAR(dense.Energy(x), expected, 1e-12);
        EXPECT_NEAR(sparse.Energy(x), expected, 1e-12);
      }
    }
  }
  EXPECT_EQ(dense.Energy({1, 1, 0}), kInf);  // label 1 is forbidden at node 0
  EXPECT_FALSE(dense.IsFeasible({1, 1, 0}));
  EXPECT_EQ(dense.UnaryArgmin(), (std::vector<int>{0, 1, 3}));
}

TEST(MrfProblemTest, EdgeTablesMatchCostCallbacks) {
  // The same problem built with AddEdge callbacks and with AddEdgeTable / array AddNode.
  const auto cost = [](int a, int b) { return a == b ? 0.0 : 0.1 * (3 * a + b + 1); };
  MrfProblem with_callbacks(4), with_tables(4);
  const std::vector<std::vector<int>> labels = {{0, 2, 3}, {1, 2}, {0, 1, 3}};
  const std::vector<std::vector<double>> costs = {{0.5, 0.0, 1.0}, {0.2, 0.4}, {1.0, 0.3, 0.6}};
  for (std::size_t i = 0; i < labels.size(); ++i) {
    with_callbacks.AddNode(labels[i], costs[i]);
    with_tables.AddNode(labels[i].data(), costs[i].data(), static_cast<int>(labels[i].size()));
  }
  const std::vector<std::pair<int, int>> edges = {{0, 1}, {1, 2}, {2, 0}};
  for (const auto& [i, j] : edges) {
    with_callbacks.AddEdge(i, j, 1.5, cost);
    std::vector<float> table;
    for (int a : labels[i])
      for (int b : labels[j]) table.push_back(static_cast<float>(cost(a, b)));
    with_tables.AddEdgeTable(i, j, 1.5, table.data());
  }
  for (int a : labels[0])
    for (int b : labels[1])
      for (int c : labels[2])
        EXPECT_EQ(with_callbacks.Energy({a, b, c}), with_tables.Energy({a, b, c}));
  EXPECT_EQ(with_callbacks.MemoryBytes(), with_tables.MemoryBytes());
  // Unsorted arrays are sorted like the vector overload; +inf drops a label.
  const int unsorted[] = {3, 0, 1};
  const double unsorted_costs[] = {0.3, kInf, 0.1};
  const int node = with_tables.AddNode(unsorted, unsorted_costs, 3);
  EXPECT_EQ(with_tables.num_candidates(node), 2);
  EXPECT_EQ(with_tables.candidate_labels(node)[0], 1);
  EXPECT_EQ(with_tables.candidate_unaries(node)[1], 0.3);
  const float bad[] = {0.0f, std::numeric_limits<float>::quiet_NaN(), 0.0f, 0.0f, 0.0f, 0.0f};
  EXPECT_THROW(with_tables.AddEdgeTable(0, 1, 1.0, bad), Error);
  EXPECT_THROW(with_tables.AddEdgeTable(0, 0, 1.0, bad), Error);
  const int duplicate[] = {2, 2};
  EXPECT_THROW(with_tables.AddNode(duplicate, unsorted_costs, 2), Error);
}

TEST(MrfProblemTest, BulkEdgeTablesMatchOneByOne) {
  const auto cost = [](int a, int b) { return a == b ? 0.0 : 0.1 * (3 * a + b + 1); };
  const std::vector<std::vector<int>> labels = {{0, 2, 3}, {1, 2}, {0, 1, 3}};
  const std::vector<std::vector<double>> costs = {{0.5, 0.0, 1.0}, {0.2, 0.4}, {1.0, 0.3, 0.6}};
  const std::vector<std::pair<int, int>> edges = {{0, 1}, {1, 2}, {2, 0}};
  const std::vector<double> weights = {1.5, 0.5, 2.0};
  const auto table_of = [&](int i, int j) {
    std::vector<float> table;
    for (int a : labels[i])
      for (int b : labels[j]) table.push_back(static_cast<float>(cost(a, b)));
    return table;
  };
  const auto nodes = [&](MrfProblem* p) {
    for (std::size_t i = 0; i < labels.size(); ++i) p->AddNode(labels[i], costs[i]);
  };
  MrfProblem one_by_one(4), bulk(4), appended(4);
  nodes(&one_by_one);
  nodes(&bulk);
  nodes(&appended);
  for (std::size_t k = 0; k < edges.size(); ++k) {
    one_by_one.AddEdgeTable(edges[k].first, edges[k].second, weights[k],
                            table_of(edges[k].first, edges[k].second).data());
  }
  std::vector<int> first, second;
  std::vector<float> tables;
  for (const auto& [i, j] : edges) {
    first.push_back(i);
    second.push_back(j);
    const std::vector<float> t = table_of(i, j);
    tables.insert(tables.end(), t.begin(), t.end());
  }
  bulk.AddEdgeTables(first, second, weights, tables);  // taken over (no tables yet)
  // Appended after an edge added one by one (copied).
  appended.AddEdgeTable(edges[0].first, edges[0].second, weights[0],
                        table_of(edges[0].first, edges[0].second).data());
  appended.AddEdgeTables({first[1], first[2]}, {second[1], second[2]}, {weights[1], weights[2]},
                         std::vector<float>(tables.begin() + 6, tables.end()));
  ASSERT_EQ(bulk.num_edges(), 3);
  ASSERT_EQ(appended.num_edges(), 3);
  for (int a : labels[0]) {
    for (int b : labels[1]) {
      for (int c : labels[2]) {
        EXPECT_EQ(bulk.Energy({a, b, c}), one_by_one.Energy({a, b, c}));
        EXPECT_EQ(appended.Energy({a, b, c}), one_by_one.Energy({a, b, c}));
      }
    }
  }
  EXPECT_EQ(bulk.MemoryBytes(), one_by_one.MemoryBytes());
  // Bad input throws and adds nothing.
  std::vector<float> nan_table = tables;
  nan_table[7] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(bulk.AddEdgeTables(first, second, weights, nan_table), Error);
  EXPECT_THROW(bulk.AddEdgeTables(first, second, weights,
                                  std::vector<float>(tables.begin(), tables.end() - 1)),
               Error);
  std::vector<float> longer = tables;
  longer.push_back(0.0f);
  EXPECT_THROW(bulk.AddEdgeTables(first, second, weights, longer), Error);
  EXPECT_THROW(bulk.AddEdgeTables(first, {1, 2}, weights, tables), Error);
  EXPECT_THROW(bulk.AddEdgeTables(first, {1, 2, 0}, {1.5, -1.0, 2.0}, tables), Error);
  EXPECT_THROW(bulk.AddEdgeTables({0, 1, 2}, {1, 2, 2}, weights, tables), Error);
  EXPECT_EQ(bulk.num_edges(), 3);
  EXPECT_EQ(bulk.MemoryBytes(), one_by_one.MemoryBytes());
}

TEST(MrfProblemTest, RejectsBadInput) {
  MrfProblem p(3);
  EXPECT_THROW(MrfProblem(0), Error);
  EXPECT_THROW(p.AddNodeDense({kInf, kInf, kInf}), Error);  // no feasible label
  EXPECT_THROW(p.AddNodeDense({1.0, std::nan(""), 0.0}), Error);
  EXPECT_THROW(p.AddNodeDense({1.0, -kInf, 0.0}), Error);
  EXPECT_THROW(p.AddNodeDense({1.0, 2.0}), Error);
  EXPECT_THROW(p.AddNode({0, 3}, {1.0, 1.0}), Error);
  EXPECT_THROW(p.AddNode({1, 1}, {1.0, 2.0}), Error);
  EXPECT_THROW(p.AddNode({0, 1}, {1.0}), Error);
  EXPECT_EQ(p.num_nodes(), 0);
  p.AddNode({0, 1}, {0.0, 1.0});
  p.AddNode({1, 2}, {0.0, 1.0});
  EXPECT_THROW(p.AddPottsEdge(0, 2, 1.0), Error);
  EXPECT_THROW(p.AddPottsEdge(1, 1, 1.0), Error);
  EXPECT_THROW(p.AddPottsEdge(0, 1, -1.0), Error);
  EXPECT_THROW(p.AddPottsEdge(0, 1, kInf), Error);
  EXPECT_THROW(p.AddEdge(0, 1, 1.0, [](int, int) { return kInf; }), Error);
  EXPECT_THROW(p.AddEdge(0, 1, 1.0, nullptr), Error);
  EXPECT_EQ(p.num_edges(), 0);
  EXPECT_THROW(p.set_smoothness(-1.0), Error);
  EXPECT_THROW(p.Energy({0}), Error);
  EXPECT_THROW(p.Energy({0, 5}), Error);
  EXPECT_EQ(p.Energy({0, 2}), 1.0);
  EXPECT_THROW(MrfProblem::FromDenseUnaries(2, 3, {0.0, 1.0}), Error);
  try {
    MrfProblem::FromDenseUnaries(2, 2, {0.0, 1.0, kInf, kInf});
    ADD_FAILURE() << "expected artex::Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("node 1"), std::string::npos) << e.what();
  }
}

TEST(MrfSolverFactoryTest, NamesOptionsAndErrors) {
  for (MrfSolverType type : AllMrfSolverTypes()) {
    EXPECT_EQ(ParseMrfSolverType(MrfSolverTypeToString(type)), type);
    MrfSolverOptions options;
    options.type = type;
    EXPECT_NE(MrfSolver::Create(options), nullptr);
  }
  try {
    ParseMrfSolverType("graphcut");
    ADD_FAILURE() << "expected artex::Error";
  } catch (const Error& e) {
    const std::string message = e.what();
    for (const char* name : {"alpha_expansion", "swap", "icm", "trws", "graphcut"}) {
      EXPECT_NE(message.find(name), std::string::npos) << message;
    }
  }
  MrfSolverOptions bad;
  bad.max_iterations = 0;
  std::string error;
  EXPECT_FALSE(bad.IsValid(&error));
  EXPECT_NE(error.find("max_iterations"), std::string::npos);
  EXPECT_THROW(MrfSolver::Create(bad), Error);
  bad = MrfSolverOptions();
  bad.trws_bound_tolerance = -1.0;
  EXPECT_THROW(MrfSolver::Create(bad), Error);
  bad = MrfSolverOptions();
  bad.max_seconds = 0.0;
  EXPECT_THROW(MrfSolver::Create(bad), Error);
}

}  // namespace
}  // namespace artex
