// The exact dense E-step over all (scan point, template vertex) pairs (solvers/estep.h).
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <vector>

#include "solvers/estep.h"
#include "solvers/estep_pairs.h"

namespace artex {

using estep_internal::CheckPosed;
using estep_internal::CheckScan;
using estep_internal::Finish;
using estep_internal::ForRange;
using estep_internal::ResizeTargets;
using estep_internal::VertexSums;

void DenseEStep(const Scan& scan, const PosedTemplateView& posed, const OneToManyOptions& options,
                CorrespondenceTargets* targets, bool parallel) {
  CheckScan(scan, "dense E-step");
  CheckPosed(posed, "dense E-step");
  const int t_count = static_cast<int>(posed.vertices->rows());
  const int n = scan.size();
  ResizeTargets(t_count, targets);
  if (n == 0 || t_count == 0) return;
  const bool color = options.use_color && posed.colors != nullptr && scan.colors.rows() == n;
  // Structure of arrays over the scan.
  Eigen::ArrayXd sx = scan.points.col(0), sy = scan.points.col(1), sz = scan.points.col(2);
  Eigen::ArrayXd nx = scan.normals.col(0), ny = scan.normals.col(1), nz = scan.normals.col(2);
  Eigen::ArrayXd cr, cg, cb, cvalid;
  if (color) {
    cr = scan.colors.col(0);
    cg = scan.colors.col(1);
    cb = scan.colors.col(2);
    cvalid = Eigen::ArrayXd::Ones(n);
    for (int s = 0; s < n && !scan.color_valid.empty(); ++s) {
      cvalid[s] = scan.color_valid[s] ? 1.0 : 0.0;
    }
  }
  const double eps = options.epsilon;
  const double lambda = options.lambda_color;
  // p_st for one template vertex against all scan points (into `p`), with d = v_s - x_t.
  auto weights_for = [&](int t, Eigen::ArrayXd* p, Eigen::ArrayXd* dx, Eigen::ArrayXd* dy,
                         Eigen::ArrayXd* dz, Eigen::ArrayXd* d2) {
    const Eigen::RowVector3d x = posed.vertices->row(t);
    const Eigen::RowVector3d nt = posed.normals->row(t);
    *dx = sx - x[0];
    *dy = sy - x[1];
    *dz = sz - x[2];
    *d2 = dx->square() + dy->square() + dz->square();
    Eigen::ArrayXd denom = *d2 + eps;
    if (color) {
      const Eigen::RowVector3d ct = posed.colors->row(t);
      denom +=
          lambda * cvalid * ((cr - ct[0]).square() + (cg - ct[1]).square() + (cb - ct[2]).square());
    }
    *p = (nx * nt[0] + ny * nt[1] + nz * nt[2]).max(0.0) / denom;
  };

  Eigen::ArrayXd inv_scan_sum;
  if (options.normalize_per_scan_point) {
    // sum_t p_st per scan point, accumulated per template vertex block (thread-local arrays).
    inv_scan_sum = tbb::parallel_reduce(
        tbb::blocked_range<int>(0, t_count, parallel ? 64 : t_count),
        Eigen::ArrayXd(Eigen::ArrayXd::Zero(n)),
        [&](const tbb::blocked_range<int>& r, Eigen::ArrayXd acc) {
          Eigen::ArrayXd p, dx, dy, dz, d2;
          for (int t = r.begin(); t != r.end(); ++t) {
            weights_for(t, &p, &dx, &dy, &dz, &d2);
            acc += p;
          }
          return acc;
        },
        [](Eigen::ArrayXd a, const Eigen::ArrayXd& b) {
          a += b;
          return a;
        });
    inv_scan_sum = (inv_scan_sum > 0.0).select(inv_scan_sum.inverse(), 0.0);
  }
  std::vector<double> constants(t_count, 0.0);
  std::vector<long long> pairs(t_count, 0);
  ForRange(t_count, 64, parallel, [&](int begin, int end) {
    Eigen::ArrayXd p, dx, dy, dz, d2;
    for (int t = begin; t < end; ++t) {
      weights_for(t, &p, &dx, &dy, &dz, &d2);
      if (options.normalize_per_scan_point) p *= inv_scan_sum;
      VertexSums sums;
      sums.a = p.sum();
      sums.b = Eigen::Vector3d((p * dx).sum(), (p * dy).sum(), (p * dz).sum());
      sums.c = (p * d2).sum();
      pairs[t] = (p > 0.0).count();
      constants[t] = Finish(sums, posed.vertices->row(t).transpose(), t, targets);
    }
  });
  for (int t = 0; t < t_count; ++t) {
    targets->constant += constants[t];
    targets->num_pairs += pairs[t];
  }
}

}  // namespace artex
