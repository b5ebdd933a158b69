// Internal to the E-step (solvers/estep.cc, estep_dense.cc): the pair loop of one template
// vertex against its scan candidates, p_st of eq. 4 (energies/one_to_many_correspondence.h)
// accumulated into the vertex's sums; scalar, SSE2 and AVX (chosen at run time) variants with
// bit-identical sums; and the checks and target writing both E-steps share.
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Core>
#include <vector>

#include "energies/one_to_many_correspondence.h"
#include "sensors/scan.h"

namespace artex {

struct PosedTemplateView;  // solvers/estep.h

namespace estep_internal {

// Values per point of the packed clouds of the pair loops: x y z nx ny nz count (unused).
// The clouds start on cache lines (64 bytes), so every packed point is one cache line.
constexpr int kPackedStride = 8;

// Sums relative to the template vertex x_t (numerically stable):
//   a = sum p, b = sum p (v_s - x_t), c = sum p |v_s - x_t|^2
// so that P_t = a, mu_t = x_t + b / a and c_t = c - |b|^2 / a.
struct VertexSums {
  double a = 0.0;
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  double c = 0.0;
  long long pairs = 0;

  void Add(double p, const Eigen::Vector3d& d, double d2) {
    a += p;
    b += p * d;
    c += p * d2;
    ++pairs;
  }
};

// One template vertex as the pair loops see it: posed position x, normal n, colour c, the
// squared search radius, eps and lambda_c of eq. 4.
struct VertexQuery {
  double x[3], n[3], c[3];
  double radius2;
  double epsilon, lambda_color;
};

// Adds p_st (multiplicity-weighted) of `count` candidates s = index[i] to *sums: rows of
// `packed` (kPackedStride values each, the array aligned to 64 bytes) and of `packed_colors`
// (4 per row: r g b valid; null without colour), truncated to d2 < radius2 when `truncate`,
// with the squared distances taken from `known_d2` when non-null. With `store_s` non-null the
// pairs (s, p) are appended instead of summed (per-scan-point normalisation).
void WeighVertex(bool color, bool truncate, const VertexQuery& q, const double* packed,
                 const double* packed_colors, const int* index, int count, const double* known_d2,
                 VertexSums* sums, std::vector<int>* store_s, std::vector<double>* store_p);

// The variants of the candidate-list loop (truncated, distances computed, sums, no colour):
// kAuto is WeighVertex's own choice (AVX if the CPU has it, else SSE2, else branch-free
// scalar); kBranching is the loop that skips rejected candidates (WeighVertex's for the other
// cases).
enum class PairKernel { kAuto, kBranching, kBranchFree, kSse2, kAvx };
// Whether `kernel` is compiled in and runs on this CPU.
bool PairKernelAvailable(PairKernel kernel);
// That loop by the given kernel (for tests: all kernels give bit-identical sums). Throws
// std::invalid_argument for an unavailable kernel.
void WeighCandidateListWith(PairKernel kernel, const VertexQuery& q, const double* packed,
                            const int* index, int count, VertexSums* sums);

// Writes vertex t of the targets (P_t, mu_t; zero without a positive finite weight); returns
// c_t.
double Finish(const VertexSums& sums, const Eigen::Vector3d& x, int t,
              CorrespondenceTargets* targets);
// Zero targets for t_count template vertices.
void ResizeTargets(int t_count, CorrespondenceTargets* targets);
// Throw artex::Error (naming `where`) on a posed template without vertices or normals or with
// mismatched rows, and on a scan with mismatched normals, colours or colour flags.
void CheckPosed(const PosedTemplateView& posed, const char* where);
void CheckScan(const Scan& scan, const char* where);

// body(begin, end) over [0, count), on TBB workers in ranges of `grain` when parallel.
template <typename Body>
void ForRange(int count, int grain, bool parallel, const Body& body) {
  if (!parallel || count <= grain) {
    body(0, count);
    return;
  }
  tbb::parallel_for(tbb::blocked_range<int>(0, count, grain),
                    [&](const tbb::blocked_range<int>& r) { body(r.begin(), r.end()); });
}

}  // namespace estep_internal
}  // namespace artex
