// Alpha-expansion (Boykov, Veksler & Zabih 2001): for each label alpha in turn, the best move
// letting any node switch to alpha is one s-t min cut (Kolmogorov's maxflow). Non-submodular
// move terms are majorised (off-diagonal entries raised, the current state kept exact; a
// truncation in the sense of Rother et al. 2005), so an accepted move never raises the energy.
// Within 2x of the optimum on Potts energies; exact on submodular two-label energies.
#pragma once

#include <array>
#include <memory>
#include <vector>

#include "solvers/mrf.h"

namespace artex {

namespace mrf_internal {
class BinaryMoveCut;
}  // namespace mrf_internal

class AlphaExpansionSolver : public MrfSolver {
 public:
  explicit AlphaExpansionSolver(const MrfSolverOptions& options);
  ~AlphaExpansionSolver() override;
  MrfSummary Solve(const MrfProblem& problem, std::vector<int>* labels) override;

 private:
  MrfSolverOptions options_;
  // The min-cut graphs of the sweeps (all nodes, the two halves, the separator), kept from
  // solve to solve: a graph grows its node and arc arrays to the largest move it has cut, so
  // later solves of similar problems (the next frame's) reallocate nothing.
  std::array<std::unique_ptr<mrf_internal::BinaryMoveCut>, 4> cuts_;
};

namespace mrf_internal {

// A binary energy sum_v U_v(y_v) + sum P_uv(y_u, y_v) over move variables y in {0, 1}
// (0 = keep the current label), minimised exactly by one s-t min cut. Pair terms that are not
// submodular (A + D > B + C) are replaced by a majoriser that is exact at the current state
// (cur_u, cur_v): the off-diagonal entries not equal to the current state are raised by the
// excess, so the cut's optimum never has a higher true energy than the current state.
class BinaryMoveCut {
 public:
  BinaryMoveCut();
  ~BinaryMoveCut();
  // Starts a new move with num_vars variables (all-zero unaries, no pair terms).
  void Reset(int num_vars);
  void AddUnary(int v, double cost0, double cost1);
  // Pair term with E(0,0) = a, E(0,1) = b, E(1,0) = c, E(1,1) = d. Returns true when the term
  // was not submodular and had to be majorised.
  bool AddPair(int u, int v, double a, double b, double c, double d, bool cur_u, bool cur_v);
  // Minimises; (*y)[v] = 1 for variables on the sink side (switch), 0 otherwise (ties keep 0).
  void Solve(std::vector<char>* y);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// A two-label move shared by expansion and swap: move variable v is node vars[v], which takes
// local label label0[v] for y_v = 0 and label1[v] for y_v = 1 and is now at y_v = current[v]
// (its current local label x[vars[v]] is the one of that state). Other nodes keep x.
struct BinaryMove {
  std::vector<int> vars, label0, label1;
  std::vector<char> current;

  void Clear() {
    vars.clear();
    label0.clear();
    label1.clear();
    current.clear();
  }
  void Add(int node, int l0, int l1, bool now) {
    vars.push_back(node);
    label0.push_back(l0);
    label1.push_back(l1);
    current.push_back(now);
  }
  int size() const { return static_cast<int>(vars.size()); }
  int Label(int v, bool y) const { return y ? label1[v] : label0[v]; }
};

// Builds the move's cut (var_of[i]: node i's move variable or -1), solves it, and applies the
// result to x when its true energy change is negative (the cut minimised a majoriser of it):
// then adds the change to *energy and counts the move in summary->accepted_moves. Majorised pair
// terms are counted in summary->truncated_terms. Returns whether the move was applied.
bool ApplyBinaryMove(const MrfProblem& problem, const MrfAdjacency& adjacency,
                     const BinaryMove& move, const std::vector<int>& var_of, BinaryMoveCut* cut,
                     std::vector<char>* y, std::vector<int>* x, double* energy,
                     MrfSummary* summary);

// Parallel sweeps (MrfSolverOptions::expansion_parallel_min_nodes): part[i] is 0 or 1 for the two
// halves, kSeparatorPart for the separator; no edge joins the halves. Breadth-first levels from
// node 0 (components one after another, from their lowest node); the level at which the
// cumulative work (candidates per node) reaches half is the separator. Deterministic.
constexpr char kSeparatorPart = 2;
std::vector<char> BisectByLevels(const MrfProblem& problem, const MrfAdjacency& adjacency);

}  // namespace mrf_internal

}  // namespace artex
