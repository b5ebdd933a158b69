#include "solvers/estep_pairs.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

#include "models/error.h"
#include "solvers/estep.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

namespace artex {
namespace estep_internal {

namespace {

// The sums of one template vertex over candidate lists (kTruncate, no known distances, no
// storing): branch-free, since whether a candidate lies within the radius and faces the vertex
// is unpredictable. A rejected candidate contributes p = 0, which leaves every sum unchanged
// (x + 0 * d == x for finite d), so the sums are bit for bit those of the branching loop.
template <bool kColor>
void WeighCandidateList(const VertexQuery& q, const double* packed, const double* packed_colors,
                        const int* index, int count, VertexSums* sums) {
  constexpr int kP = kPackedStride;
  // Continues *sums candidate after candidate (the SIMD loops hand over their remainder;
  // a vertex starts from zero sums, where this is the branching loop's order).
  double a = sums->a, b0 = sums->b[0], b1 = sums->b[1], b2 = sums->b[2], c = sums->c;
  long long pairs = sums->pairs;
  for (int i = 0; i < count; ++i) {
    const int s = index[i];
    const double* v = packed + kP * s;
    const double d0 = v[0] - q.x[0], d1 = v[1] - q.x[1], d2c = v[2] - q.x[2];
    const double d2 = d0 * d0 + d1 * d1 + d2c * d2c;
    const double dot = v[3] * q.n[0] + v[4] * q.n[1] + v[5] * q.n[2];
    double denominator = d2 + q.epsilon;
    if (kColor) {
      const double* rgb = packed_colors + 4 * s;
      const double e0 = rgb[0] - q.c[0], e1 = rgb[1] - q.c[1], e2 = rgb[2] - q.c[2];
      const double color = q.lambda_color * (e0 * e0 + e1 * e1 + e2 * e2);
      denominator += rgb[3] > 0.0 ? color : 0.0;
    }
    const double weight = v[6] * dot / denominator;
    const double p = d2 < q.radius2 && dot > 0.0 && weight > 0.0 ? weight : 0.0;
    a += p;
    b0 += p * d0;
    b1 += p * d1;
    b2 += p * d2c;
    c += p * d2;
    pairs += p > 0.0;
  }
  sums->a = a;
  sums->b = Eigen::Vector3d(b0, b1, b2);
  sums->c = c;
  sums->pairs = pairs;
}

// The vector loops' ending: the candidates from `done` on by the scalar loop, continuing the
// candidate-ordered sums in *total, then *total added to *sums.
[[maybe_unused]] void FinishCandidateList(const VertexQuery& q, const double* packed,
                                          const int* index, int done, int count, VertexSums* total,
                                          VertexSums* sums) {
  if (done < count) {
    WeighCandidateList<false>(q, packed, nullptr, index + done, count - done, total);
  }
  sums->a += total->a;
  sums->b += total->b;
  sums->c += total->c;
  sums->pairs += total->pairs;
}

#if defined(__SSE2__)
// WeighCandidateList<false> two candidates at a time (SSE2): the same operations in the same
// order per candidate (sums accumulated candidate after candidate), so bit for bit its sums,
// with one division per two candidates and no branches, which the compiler re-introduces in
// the scalar loop to skip the division.
void WeighCandidateListSse2(const VertexQuery& q, const double* packed, const int* index, int count,
                            VertexSums* sums) {
  constexpr int kP = kPackedStride;
  const __m128d x01 = _mm_loadu_pd(q.x), x2 = _mm_set1_pd(q.x[2]);
  const __m128d n01 = _mm_loadu_pd(q.n), n2 = _mm_set1_pd(q.n[2]);
  const __m128d r2 = _mm_set1_pd(q.radius2), eps = _mm_set1_pd(q.epsilon);
  const __m128d zero = _mm_setzero_pd();
  __m128d acc_a = zero, acc_b01 = zero, acc_b2c = zero;  // (a, -), (b0, b1), (b2, c)
  long long pairs = 0;
  int i = 0;
  for (; i + 1 < count; i += 2) {
    const double* va = packed + kP * index[i];
    const double* vb = packed + kP * index[i + 1];
    const __m128d da = _mm_sub_pd(_mm_load_pd(va), x01);  // (d0, d1) of candidate a
    const __m128d db = _mm_sub_pd(_mm_load_pd(vb), x01);
    const __m128d dz = _mm_sub_pd(_mm_unpacklo_pd(_mm_load_sd(va + 2), _mm_load_sd(vb + 2)), x2);
    const __m128d sa = _mm_mul_pd(da, da), sb = _mm_mul_pd(db, db);
    const __m128d d2 = _mm_add_pd(_mm_add_pd(_mm_unpacklo_pd(sa, sb), _mm_unpackhi_pd(sa, sb)),
                                  _mm_mul_pd(dz, dz));  // (d2 of a, d2 of b)
    const __m128d na = _mm_mul_pd(_mm_load_pd(va + 4), _mm_shuffle_pd(n01, n2, 1));
    const __m128d nb = _mm_mul_pd(_mm_load_pd(vb + 4), _mm_shuffle_pd(n01, n2, 1));
    // v[3] n0 + v[4] n1 + v[5] n2: v[3] n0 first (v[4], v[5] are loaded as a pair).
    const __m128d n0 = _mm_unpacklo_pd(n01, n01);
    const __m128d dot = _mm_add_pd(
        _mm_add_pd(_mm_mul_pd(_mm_unpacklo_pd(_mm_load_sd(va + 3), _mm_load_sd(vb + 3)), n0),
                   _mm_unpacklo_pd(na, nb)),
        _mm_unpackhi_pd(na, nb));
    const __m128d multiplicity = _mm_unpacklo_pd(_mm_load_sd(va + 6), _mm_load_sd(vb + 6));
    const __m128d w = _mm_div_pd(_mm_mul_pd(multiplicity, dot), _mm_add_pd(d2, eps));
    const __m128d keep = _mm_and_pd(_mm_and_pd(_mm_cmplt_pd(d2, r2), _mm_cmpgt_pd(dot, zero)),
                                    _mm_cmpgt_pd(w, zero));
    const __m128d p = _mm_and_pd(keep, w);
    const int kept = _mm_movemask_pd(keep);  // bit per candidate
    pairs += (kept & 1) + (kept >> 1);
    const __m128d pa = _mm_unpacklo_pd(p, p), pb = _mm_unpackhi_pd(p, p);
    acc_a = _mm_add_sd(acc_a, pa);
    acc_b01 = _mm_add_pd(acc_b01, _mm_mul_pd(pa, da));
    acc_b2c = _mm_add_pd(acc_b2c, _mm_mul_pd(pa, _mm_unpacklo_pd(dz, d2)));
    acc_a = _mm_add_sd(acc_a, pb);
    acc_b01 = _mm_add_pd(acc_b01, _mm_mul_pd(pb, db));
    acc_b2c = _mm_add_pd(acc_b2c, _mm_mul_pd(pb, _mm_unpackhi_pd(dz, d2)));
  }
  // Candidate-ordered sums so far, then the odd last candidate (the scalar loop adds it).
  VertexSums total;
  double b01[2], b2c[2];
  _mm_storeu_pd(b01, acc_b01);
  _mm_storeu_pd(b2c, acc_b2c);
  total.a = _mm_cvtsd_f64(acc_a);
  total.b = Eigen::Vector3d(b01[0], b01[1], b2c[0]);
  total.c = b2c[1];
  total.pairs = pairs;
  FinishCandidateList(q, packed, index, i, count, &total, sums);
}
#endif

#if defined(__x86_64__) && defined(__GNUC__)
#define ARTEX_ESTEP_AVX 1
// WeighCandidateList<false> four candidates at a time (AVX, chosen at run time when the CPU
// has it; no FMA, so every product and sum rounds as in the scalar loop): the candidates'
// packed rows are transposed to coordinates, weighed together, transposed back and
// accumulated candidate after candidate, so the sums are bit for bit the scalar loop's.
__attribute__((target("avx"))) void WeighCandidateListAvx(const VertexQuery& q,
                                                          const double* packed, const int* index,
                                                          int count, VertexSums* sums) {
  constexpr int kP = kPackedStride;
  const __m256d x0 = _mm256_set1_pd(q.x[0]), x1 = _mm256_set1_pd(q.x[1]),
                x2 = _mm256_set1_pd(q.x[2]);
  const __m256d n0 = _mm256_set1_pd(q.n[0]), n1 = _mm256_set1_pd(q.n[1]),
                n2 = _mm256_set1_pd(q.n[2]);
  const __m256d r2 = _mm256_set1_pd(q.radius2), eps = _mm256_set1_pd(q.epsilon);
  const __m256d zero = _mm256_setzero_pd();
  __m128d acc_a = _mm_setzero_pd();
  __m256d acc = _mm256_setzero_pd();  // b0 b1 b2 c
  long long pairs = 0;
  int i = 0;
  for (; i + 3 < count; i += 4) {
    const double* v0 = packed + kP * index[i];
    const double* v1 = packed + kP * index[i + 1];
    const double* v2 = packed + kP * index[i + 2];
    const double* v3 = packed + kP * index[i + 3];
    // x y z nx | ny nz count - of each candidate -> one register per value.
    const __m256d l0 = _mm256_load_pd(v0), l1 = _mm256_load_pd(v1), l2 = _mm256_load_pd(v2),
                  l3 = _mm256_load_pd(v3);
    const __m256d h0 = _mm256_load_pd(v0 + 4), h1 = _mm256_load_pd(v1 + 4),
                  h2 = _mm256_load_pd(v2 + 4), h3 = _mm256_load_pd(v3 + 4);
    const __m256d xz01 = _mm256_unpacklo_pd(l0, l1), xz23 = _mm256_unpacklo_pd(l2, l3);
    const __m256d yn01 = _mm256_unpackhi_pd(l0, l1), yn23 = _mm256_unpackhi_pd(l2, l3);
    const __m256d nc01 = _mm256_unpacklo_pd(h0, h1), nc23 = _mm256_unpacklo_pd(h2, h3);
    const __m256d nz01 = _mm256_unpackhi_pd(h0, h1), nz23 = _mm256_unpackhi_pd(h2, h3);
    const __m256d px = _mm256_permute2f128_pd(xz01, xz23, 0x20);
    const __m256d pz = _mm256_permute2f128_pd(xz01, xz23, 0x31);
    const __m256d py = _mm256_permute2f128_pd(yn01, yn23, 0x20);
    const __m256d nx = _mm256_permute2f128_pd(yn01, yn23, 0x31);
    const __m256d ny = _mm256_permute2f128_pd(nc01, nc23, 0x20);
    const __m256d multiplicity = _mm256_permute2f128_pd(nc01, nc23, 0x31);
    const __m256d nz = _mm256_permute2f128_pd(nz01, nz23, 0x20);
    const __m256d d0 = _mm256_sub_pd(px, x0), d1 = _mm256_sub_pd(py, x1),
                  dz = _mm256_sub_pd(pz, x2);
    const __m256d d2 = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(d0, d0), _mm256_mul_pd(d1, d1)),
                                     _mm256_mul_pd(dz, dz));
    const __m256d dot = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(nx, n0), _mm256_mul_pd(ny, n1)),
                                      _mm256_mul_pd(nz, n2));
    const __m256d w = _mm256_div_pd(_mm256_mul_pd(multiplicity, dot), _mm256_add_pd(d2, eps));
    const __m256d keep = _mm256_and_pd(
        _mm256_and_pd(_mm256_cmp_pd(d2, r2, _CMP_LT_OQ), _mm256_cmp_pd(dot, zero, _CMP_GT_OQ)),
        _mm256_cmp_pd(w, zero, _CMP_GT_OQ));
    const __m256d p = _mm256_and_pd(keep, w);
    const int kept = _mm256_movemask_pd(keep);  // bit per candidate
    pairs += (kept & 1) + ((kept >> 1) & 1) + ((kept >> 2) & 1) + (kept >> 3);
    // Back to one register per candidate: d0 d1 d2c d2.
    const __m256d a01 = _mm256_unpacklo_pd(d0, d1), b01 = _mm256_unpackhi_pd(d0, d1);
    const __m256d a23 = _mm256_unpacklo_pd(dz, d2), b23 = _mm256_unpackhi_pd(dz, d2);
    const __m256d e0 = _mm256_permute2f128_pd(a01, a23, 0x20);
    const __m256d e1 = _mm256_permute2f128_pd(b01, b23, 0x20);
    const __m256d e2 = _mm256_permute2f128_pd(a01, a23, 0x31);
    const __m256d e3 = _mm256_permute2f128_pd(b01, b23, 0x31);
    const __m256d p01 = _mm256_permute2f128_pd(p, p, 0x00),
                  p23 = _mm256_permute2f128_pd(p, p, 0x11);
    const __m256d q0 = _mm256_permute_pd(p01, 0x0), q1 = _mm256_permute_pd(p01, 0xf);
    const __m256d q2 = _mm256_permute_pd(p23, 0x0), q3 = _mm256_permute_pd(p23, 0xf);
    acc_a = _mm_add_sd(acc_a, _mm256_castpd256_pd128(q0));
    acc = _mm256_add_pd(acc, _mm256_mul_pd(q0, e0));
    acc_a = _mm_add_sd(acc_a, _mm256_castpd256_pd128(q1));
    acc = _mm256_add_pd(acc, _mm256_mul_pd(q1, e1));
    acc_a = _mm_add_sd(acc_a, _mm256_castpd256_pd128(q2));
    acc = _mm256_add_pd(acc, _mm256_mul_pd(q2, e2));
    acc_a = _mm_add_sd(acc_a, _mm256_castpd256_pd128(q3));
    acc = _mm256_add_pd(acc, _mm256_mul_pd(q3, e3));
  }
  // Candidate-ordered sums so far, then the last count % 4 candidates (the scalar loop).
  VertexSums total;
  double bc[4];
  _mm256_storeu_pd(bc, acc);
  total.a = _mm_cvtsd_f64(acc_a);
  total.b = Eigen::Vector3d(bc[0], bc[1], bc[2]);
  total.c = bc[3];
  total.pairs = pairs;
  FinishCandidateList(q, packed, index, i, count, &total, sums);
}

bool CpuHasAvx() {
  static const bool has = __builtin_cpu_supports("avx");
  return has;
}
#endif

template <bool kColor, bool kTruncate>
void WeighCandidates(const VertexQuery& q, const double* packed, const double* packed_colors,
                     const int* index, int count, const double* known_d2, VertexSums* sums,
                     std::vector<int>* store_s, std::vector<double>* store_p) {
  constexpr int kP = kPackedStride;
  double a = 0.0, b0 = 0.0, b1 = 0.0, b2 = 0.0, c = 0.0;
  long long pairs = 0;
  for (int i = 0; i < count; ++i) {
    const int s = index[i];
    const double* v = packed + kP * s;
    const double d0 = v[0] - q.x[0], d1 = v[1] - q.x[1], d2c = v[2] - q.x[2];
    const double d2 = known_d2 ? known_d2[i] : d0 * d0 + d1 * d1 + d2c * d2c;
    if (kTruncate && !(d2 < q.radius2)) continue;  // as the kd-tree radius search
    const double dot = v[3] * q.n[0] + v[4] * q.n[1] + v[5] * q.n[2];
    if (!(dot > 0.0)) continue;
    double denominator = d2 + q.epsilon;
    if (kColor) {
      const double* rgb = packed_colors + 4 * s;
      if (rgb[3] > 0.0) {
        const double e0 = rgb[0] - q.c[0], e1 = rgb[1] - q.c[1], e2 = rgb[2] - q.c[2];
        denominator += q.lambda_color * (e0 * e0 + e1 * e1 + e2 * e2);
      }
    }
    const double p = v[6] * dot / denominator;
    if (!(p > 0.0)) continue;
    if (store_s != nullptr) {
      store_s->push_back(s);
      store_p->push_back(p);
      continue;
    }
    a += p;
    b0 += p * d0;
    b1 += p * d1;
    b2 += p * d2c;
    c += p * d2;
    ++pairs;
  }
  sums->a += a;
  sums->b += Eigen::Vector3d(b0, b1, b2);
  sums->c += c;
  sums->pairs += pairs;
}

}  // namespace

void WeighVertex(bool color, bool truncate, const VertexQuery& q, const double* packed,
                 const double* packed_colors, const int* index, int count, const double* known_d2,
                 VertexSums* sums, std::vector<int>* store_s, std::vector<double>* store_p) {
  if (truncate && known_d2 == nullptr && store_s == nullptr) {
    if (color) {
      WeighCandidateList<true>(q, packed, packed_colors, index, count, sums);
    } else {
#if defined(ARTEX_ESTEP_AVX)
      if (CpuHasAvx()) {
        WeighCandidateListAvx(q, packed, index, count, sums);
        return;
      }
#endif
#if defined(__SSE2__)
      WeighCandidateListSse2(q, packed, index, count, sums);
#else
      WeighCandidateList<false>(q, packed, packed_colors, index, count, sums);
#endif
    }
    return;
  }
  if (color) {
    if (truncate) {
      WeighCandidates<true, true>(q, packed, packed_colors, index, count, known_d2, sums, store_s,
                                  store_p);
    } else {
      WeighCandidates<true, false>(q, packed, packed_colors, index, count, known_d2, sums, store_s,
                                   store_p);
    }
  } else if (truncate) {
    WeighCandidates<false, true>(q, packed, packed_colors, index, count, known_d2, sums, store_s,
                                 store_p);
  } else {
    WeighCandidates<false, false>(q, packed, packed_colors, index, count, known_d2, sums, store_s,
                                  store_p);
  }
}

bool PairKernelAvailable(PairKernel kernel) {
  switch (kernel) {
    case PairKernel::kAuto:
    case PairKernel::kBranching:
    case PairKernel::kBranchFree:
      return true;
    case PairKernel::kSse2:
#if defined(__SSE2__)
      return true;
#else
      return false;
#endif
    case PairKernel::kAvx:
#if defined(ARTEX_ESTEP_AVX)
      return CpuHasAvx();
#else
      return false;
#endif
  }
  return false;
}

void WeighCandidateListWith(PairKernel kernel, const VertexQuery& q, const double* packed,
                            const int* index, int count, VertexSums* sums) {
  if (!PairKernelAvailable(kernel)) {
    throw std::invalid_argument("E-step pair kernel not available on this build or CPU");
  }
  switch (kernel) {
    case PairKernel::kAuto:
      WeighVertex(false, true, q, packed, nullptr, index, count, nullptr, sums, nullptr, nullptr);
      return;
    case PairKernel::kBranching:
      WeighCandidates<false, true>(q, packed, nullptr, index, count, nullptr, sums, nullptr,
                                   nullptr);
      return;
    case PairKernel::kBranchFree:
      WeighCandidateList<false>(q, packed, nullptr, index, count, sums);
      return;
    case PairKernel::kSse2:
#if defined(__SSE2__)
      WeighCandidateListSse2(q, packed, index, count, sums);
#endif
      return;
    case PairKernel::kAvx:
#if defined(ARTEX_ESTEP_AVX)
      WeighCandidateListAvx(q, packed, index, count, sums);
#endif
      return;
  }
}

// Writes vertex t of the targets; returns c_t.
double Finish(const VertexSums& sums, const Eigen::Vector3d& x, int t,
              CorrespondenceTargets* targets) {
  if (!(sums.a > 0.0) || !std::isfinite(sums.a)) {
    targets->weight[t] = 0.0;
    targets->mean.row(t).setZero();
    return 0.0;
  }
  targets->weight[t] = sums.a;
  targets->mean.row(t) = (x + sums.b / sums.a).transpose();
  return std::max(0.0, sums.c - sums.b.squaredNorm() / sums.a);
}

void ResizeTargets(int t_count, CorrespondenceTargets* targets) {
  targets->weight.setZero(t_count);
  targets->mean.setZero(t_count, 3);
  targets->constant = 0.0;
  targets->num_pairs = 0;
}

void CheckPosed(const PosedTemplateView& posed, const char* where) {
  if (posed.vertices == nullptr || posed.normals == nullptr) {
    throw Error(std::string(where) + ": posed template vertices and normals are required");
  }
  const Eigen::Index t = posed.vertices->rows();
  if (posed.normals->rows() != t || (posed.colors != nullptr && posed.colors->rows() != t)) {
    std::ostringstream msg;
    msg << where << ": expected " << t << " template normals/colours (one per vertex), found "
        << posed.normals->rows() << "/" << (posed.colors ? posed.colors->rows() : t);
    throw Error(msg.str());
  }
}

void CheckScan(const Scan& scan, const char* where) {
  const Eigen::Index n = scan.points.rows();
  std::ostringstream msg;
  if (scan.normals.rows() != n) {
    msg << where << ": scan.normals: expected " << n << " rows, found " << scan.normals.rows();
  } else if (scan.colors.rows() != 0 && scan.colors.rows() != n) {
    msg << where << ": scan.colors: expected 0 or " << n << " rows, found " << scan.colors.rows();
  } else if (!scan.color_valid.empty() && static_cast<Eigen::Index>(scan.color_valid.size()) != n) {
    msg << where << ": scan.color_valid: expected 0 or " << n << " entries, found "
        << scan.color_valid.size();
  } else {
    return;
  }
  throw Error(msg.str());
}

}  // namespace estep_internal
}  // namespace artex
