// E-step on point sets: the dense E-step against a straightforward double loop, the truncated
// variants against the dense one (huge radius / k = all), truncation semantics, the key
// identity Q = sum_t P_t |x_t - mu_t|^2 + constant, and the nearest-neighbour gating.
#include "solvers/estep.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "models/error.h"
#include "solvers/estep_pairs.h"

namespace artex {
namespace {

struct PointSets {
  Scan scan;
  Eigen::MatrixX3d vertices, normals, colors;
};

Eigen::MatrixX3d RandomUnit(int n, std::mt19937_64* rng, const Eigen::Vector3d& bias) {
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::MatrixX3d m(n, 3);
  for (int i = 0; i < n; ++i) {
    m.row(i) = (Eigen::Vector3d(g(*rng), g(*rng), g(*rng)) + bias).normalized().transpose();
  }
  return m;
}

PointSets MakePointSets(int scan_points, int template_points, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-0.3, 0.3), c(0.0, 1.0);
  PointSets sets;
  sets.scan.points.resize(scan_points, 3);
  sets.scan.colors.resize(scan_points, 3);
  for (int s = 0; s < scan_points; ++s) {
    sets.scan.points.row(s) = Eigen::RowVector3d(u(rng), u(rng), 2.0 + 0.2 * u(rng));
    sets.scan.colors.row(s) = Eigen::RowVector3d(c(rng), c(rng), c(rng));
    sets.scan.color_valid.push_back(s % 5 == 0 ? 0 : 1);
  }
  // Mostly facing +Z, some facing away (their weights must vanish).
  sets.scan.normals = RandomUnit(scan_points, &rng, Eigen::Vector3d(0, 0, 1.5));
  sets.vertices.resize(template_points, 3);
  sets.colors.resize(template_points, 3);
  for (int t = 0; t < template_points; ++t) {
    sets.vertices.row(t) = Eigen::RowVector3d(u(rng), u(rng), 2.0 + 0.2 * u(rng));
    sets.colors.row(t) = Eigen::RowVector3d(c(rng), c(rng), c(rng));
  }
  sets.normals = RandomUnit(template_points, &rng, Eigen::Vector3d(0, 0, 1.0));
  return sets;
}

// The straightforward computation of eq. 4 and of P_t, mu_t.
void BruteForce(const PointSets& sets, const OneToManyOptions& o, bool color, double radius,
                CorrespondenceTargets* out, Eigen::MatrixXd* p_matrix = nullptr) {
  const int n = sets.scan.size(), t_count = static_cast<int>(sets.vertices.rows());
  Eigen::MatrixXd p = Eigen::MatrixXd::Zero(n, t_count);
  for (int s = 0; s < n; ++s) {
    for (int t = 0; t < t_count; ++t) {
      const Eigen::Vector3d d = (sets.scan.points.row(s) - sets.vertices.row(t)).transpose();
      if (d.norm() > radius) continue;
      const double dot = sets.scan.normals.row(s).dot(sets.normals.row(t));
      double c2 = 0.0;
      if (color && sets.scan.color_valid[s]) {
        c2 = (sets.scan.colors.row(s) - sets.colors.row(t)).squaredNorm();
      }
      p(s, t) = std::max(0.0, dot) / (d.squaredNorm() + o.lambda_color * c2 + o.epsilon);
    }
  }
  if (o.normalize_per_scan_point) {
    for (int s = 0; s < n; ++s) {
      const double sum = p.row(s).sum();
      if (sum > 0.0) p.row(s) /= sum;
    }
  }
  out->weight = p.colwise().sum().transpose();
  out->mean.setZero(t_count, 3);
  out->constant = 0.0;
  for (int t = 0; t < t_count; ++t) {
    if (out->weight[t] <= 0.0) continue;
    out->mean.row(t) = (p.col(t).transpose() * sets.scan.points) / out->weight[t];
    for (int s = 0; s < n; ++s) {
      out->constant += p(s, t) * (sets.scan.points.row(s) - out->mean.row(t)).squaredNorm();
    }
  }
  if (p_matrix) *p_matrix = p;
}

void ExpectTargetsNear(const CorrespondenceTargets& a, const CorrespondenceTargets& b, double rel) {
  ASSERT_EQ(a.size(), b.size());
  const double w_scale = b.weight.cwiseAbs().maxCoeff();
  EXPECT_LT((a.weight - b.weight).cwiseAbs().maxCoeff(), rel * w_scale);
  for (int t = 0; t < a.size(); ++t) {
    if (b.weight[t] < 1e-6 * w_scale) continue;
    EXPECT_LT((a.mean.row(t) - b.mean.row(t)).norm(), rel) << "vertex " << t;
  }
  EXPECT_NEAR(a.constant, b.constant, rel * (1.0 + std::abs(b.constant)));
}

PosedTemplateView View(const PointSets& sets, bool color) {
  PosedTemplateView view;
  view.vertices = &sets.vertices;
  view.normals = &sets.normals;
  view.colors = color ? &sets.colors : nullptr;
  return view;
}

// Both E-steps' targets at `radius` agree to 1e-12, with the same pairs (at least one).
void ExpectSameTargets(EStep* x, EStep* y, const PosedTemplateView& view, double radius) {
  CorrespondenceTargets a, b;
  x->Compute(view, radius, &a);
  y->Compute(view, radius, &b);
  ExpectTargetsNear(a, b, 1e-12);
  EXPECT_EQ(a.num_pairs, b.num_pairs);
  EXPECT_GT(a.num_pairs, 0);
}

// Candidate-list E-step options of the tests below: voxel cloud, 2 cm margin, small grains.
EStepOptions ListOptions(bool normalize) {
  EStepOptions options;
  options.voxel_fraction = 0.25;
  options.candidate_margin = 0.02;
  options.grain_size = 16;
  options.weights.normalize_per_scan_point = normalize;
  options.weights.lambda_color = 0.01;
  return options;
}

class EStepVariantsTest : public ::testing::TestWithParam<std::tuple<bool, bool>> {};

TEST_P(EStepVariantsTest, DenseEqualsBruteForce) {
  const auto [normalize, color] = GetParam();
  const PointSets sets = MakePointSets(300, 120, 11);
  OneToManyOptions o;
  o.normalize_per_scan_point = normalize;
  o.lambda_color = 0.01;
  CorrespondenceTargets dense, brute;
  DenseEStep(sets.scan, View(sets, color), o, &dense);
  BruteForce(sets, o, color, std::numeric_limits<double>::infinity(), &brute);
  ExpectTargetsNear(dense, brute, 1e-9);
  EXPECT_GT(dense.num_pairs, 0);
  EXPECT_LT(dense.num_pairs, 300LL * 120LL);  // back-facing pairs have zero weight
  // The colour term changes the weights (so the test above exercises it).
  if (color) {
    CorrespondenceTargets no_color;
    DenseEStep(sets.scan, View(sets, false), o, &no_color);
    EXPECT_GT((no_color.weight - dense.weight).cwiseAbs().maxCoeff(),
              1e-3 * dense.weight.maxCoeff());
  }
  // Serial and parallel agree.
  CorrespondenceTargets serial;
  DenseEStep(sets.scan, View(sets, color), o, &serial, false);
  ExpectTargetsNear(serial, dense, 1e-12);
}

TEST_P(EStepVariantsTest, TruncatedWithHugeRadiusEqualsDense) {
  const auto [normalize, color] = GetParam();
  const PointSets sets = MakePointSets(400, 150, 12);
  EStepOptions options;
  options.mode = EStepMode::kRadius;
  options.voxel_fraction = 0.0;
  options.weights.normalize_per_scan_point = normalize;
  options.weights.lambda_color = 0.01;
  options.grain_size = 16;
  EStep estep(sets.scan, options);
  CorrespondenceTargets radius, dense;
  estep.Compute(View(sets, color), 10.0, &radius);
  DenseEStep(sets.scan, View(sets, color), options.weights, &dense);
  ExpectTargetsNear(radius, dense, 1e-9);
  EXPECT_EQ(radius.num_pairs, dense.num_pairs);

  options.mode = EStepMode::kKNearest;
  options.k = sets.scan.size();
  EStep knn(sets.scan, options);
  CorrespondenceTargets all;
  knn.Compute(View(sets, color), 0.0, &all);
  ExpectTargetsNear(all, dense, 1e-9);
}

INSTANTIATE_TEST_SUITE_P(NormalizeColor, EStepVariantsTest,
                         ::testing::Combine(::testing::Bool(), ::testing::Bool()));

TEST(EStepTest, RadiusTruncationMatchesTruncatedBruteForce) {
  const PointSets sets = MakePointSets(500, 100, 13);
  for (bool normalize : {false, true}) {
    EStepOptions options;
    options.voxel_fraction = 0.0;
    options.weights.normalize_per_scan_point = normalize;
    EStep estep(sets.scan, options);
    CorrespondenceTargets radius, brute;
    estep.Compute(View(sets, false), 0.08, &radius);
    BruteForce(sets, options.weights, false, 0.08, &brute);
    ExpectTargetsNear(radius, brute, 1e-9);
    // Truncation drops far pairs: fewer pairs than dense, fewer than all.
    CorrespondenceTargets dense;
    DenseEStep(sets.scan, View(sets, false), options.weights, &dense);
    EXPECT_LT(radius.num_pairs, dense.num_pairs);
  }
}

TEST(EStepTest, CandidateListsEqualAFreshRadiusSearch) {
  // Successive E-steps at the same radius re-weight the candidates gathered within
  // radius + margin; moves below and beyond the margin must give the result of a fresh search.
  const PointSets sets = MakePointSets(600, 150, 17);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> g(0.0, 1.0);
  for (bool normalize : {false, true}) {
    for (bool color : {false, true}) {
      const EStepOptions cached_options = ListOptions(normalize);
      EStepOptions fresh_options = cached_options;
      fresh_options.candidate_margin = 0.0;
      EStep cached(sets.scan, cached_options), fresh(sets.scan, fresh_options);
      PointSets moved = sets;
      // Steps of ~3 mm (inside the margin), then ~4 cm (outside), alternating radii.
      for (double step : {0.0, 0.003, 0.003, 0.04, 0.003}) {
        for (int i = 0; i < moved.vertices.size(); ++i) moved.vertices.data()[i] += step * g(rng);
        for (double radius : {0.08, 0.05}) {
          ExpectSameTargets(&cached, &fresh, View(moved, color), radius);
        }
      }
    }
  }
}

TEST(EStepTest, SharedCloudAndListsEqualAFreshSearchOfThatCloud) {
  // One cloud (voxel_cell) and lists gathered at list_radius serve the narrower radii: the same
  // targets as a kd-tree search of that cloud per E-step, for moves inside the margin, inside
  // the wider margin the narrower radius gets (list_radius + margin - radius), and beyond it.
  // Without voxel_cell every radius has its own cloud, and so its own lists.
  const PointSets sets = MakePointSets(600, 150, 19);
  std::mt19937_64 rng(7);
  std::normal_distribution<double> g(0.0, 1.0);
  for (double cell : {0.02, 0.0}) {
    for (bool normalize : {false, true}) {
      for (bool color : {false, true}) {
        EStepOptions shared_options = ListOptions(normalize);
        shared_options.voxel_cell = cell;
        shared_options.list_radius = 0.08;
        EStepOptions fresh_options = shared_options;
        fresh_options.candidate_margin = 0.0;
        fresh_options.list_radius = 0.0;
        EStep shared(sets.scan, shared_options), fresh(sets.scan, fresh_options);
        PointSets moved = sets;
        long long queries = 0;
        for (double step : {0.0, 0.003, 0.015, 0.003, 0.05, 0.003}) {
          for (int i = 0; i < moved.vertices.size(); ++i)
            moved.vertices.data()[i] += step * g(rng);
          for (double radius : {0.08, 0.05, 0.05}) {
            if (radius < 0.08) {
              // ~1 cm a move, ~1.5 cm after both: some vertices beyond the margin, none
              // beyond the 5 cm the narrower radius leaves (0.08 + 0.02 - 0.05).
              for (int i = 0; i < moved.vertices.size(); ++i)
                moved.vertices.data()[i] += 0.006 * g(rng);
            }
            ExpectSameTargets(&shared, &fresh, View(moved, color), radius);
            // With one cloud the narrower radius never gathers: the wider one's lists serve it.
            if (cell > 0.0 && radius < 0.08) {
              EXPECT_EQ(shared.neighbor_queries(), queries);
            }
            queries = shared.neighbor_queries();
          }
        }
      }
    }
  }
  // The shared cloud is not the per-radius one: a radius of 0.05 alone subsamples finer.
  EStepOptions per_radius;
  per_radius.candidate_margin = 0.02;
  EStepOptions one_cell = per_radius;
  one_cell.voxel_cell = 0.02;
  CorrespondenceTargets a, b;
  EStep(sets.scan, per_radius).Compute(View(sets, false), 0.05, &a);
  EStep(sets.scan, one_cell).Compute(View(sets, false), 0.05, &b);
  EXPECT_NE(a.num_pairs, b.num_pairs);
}

TEST(EStepTest, KeyIdentityOfTheMStep) {
  // sum_s sum_t p_st |v_s - x_t|^2 == sum_t P_t |x_t - mu_t|^2 + constant for any x (p fixed).
  const PointSets sets = MakePointSets(200, 80, 14);
  OneToManyOptions o;
  CorrespondenceTargets targets;
  DenseEStep(sets.scan, View(sets, false), o, &targets);
  Eigen::MatrixXd p;
  CorrespondenceTargets unused;
  BruteForce(sets, o, false, std::numeric_limits<double>::infinity(), &unused, &p);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> g(0.0, 0.05);
  for (int trial = 0; trial < 3; ++trial) {
    Eigen::MatrixX3d x = sets.vertices;
    if (trial > 0) {
      for (int i = 0; i < x.size(); ++i) x.data()[i] += g(rng);
    }
    double q = 0.0, reduced = targets.constant;
    for (int t = 0; t < x.rows(); ++t) {
      for (int s = 0; s < sets.scan.size(); ++s) {
        q += p(s, t) * (sets.scan.points.row(s) - x.row(t)).squaredNorm();
      }
      reduced += targets.weight[t] * (x.row(t) - targets.mean.row(t)).squaredNorm();
    }
    EXPECT_NEAR(reduced, q, 1e-9 * q);
  }
}

TEST(EStepTest, VoxelSubsamplingApproximatesFullScan) {
  // A dense planar patch: subsampled cells carry their counts, so P_t and mu_t stay close.
  Scan scan;
  const int side = 120;
  scan.points.resize(side * side, 3);
  scan.normals.resize(side * side, 3);
  for (int i = 0; i < side; ++i) {
    for (int j = 0; j < side; ++j) {
      scan.points.row(i * side + j) = Eigen::RowVector3d(i * 0.004, j * 0.004, 2.0);
      scan.normals.row(i * side + j) = Eigen::RowVector3d(0, 0, 1);
    }
  }
  Eigen::MatrixX3d vertices(5, 3), normals(5, 3);
  for (int t = 0; t < 5; ++t) {
    vertices.row(t) = Eigen::RowVector3d(0.15 + 0.04 * t, 0.2 + 0.01 * t, 2.02);
    normals.row(t) = Eigen::RowVector3d(0, 0.3, 1).normalized();
  }
  PosedTemplateView view;
  view.vertices = &vertices;
  view.normals = &normals;
  EStepOptions options;
  options.voxel_fraction = 0.0;
  CorrespondenceTargets full, voxel;
  EStep(scan, options).Compute(view, 0.12, &full);
  options.voxel_fraction = 0.25;
  EStep(scan, options).Compute(view, 0.12, &voxel);
  for (int t = 0; t < 5; ++t) {
    EXPECT_NEAR(voxel.weight[t], full.weight[t], 0.05 * full.weight[t]);
    EXPECT_LT((voxel.mean.row(t) - full.mean.row(t)).norm(), 0.005);
  }
  EXPECT_LT(voxel.num_pairs, full.num_pairs / 4);
}

TEST(EStepTest, NearestNeighbourGating) {
  Scan scan;
  scan.points.resize(3, 3);
  scan.normals.resize(3, 3);
  scan.points << 0, 0, 0, 1, 0, 0, 0, 0.05, 0;
  scan.normals << 0, 0, 1, 0, 0, 1, 0, 0, -1;
  Eigen::MatrixX3d vertices(3, 3), normals(3, 3);
  vertices << 0.01, 0, 0, 0.5, 0, 0, 0, 0.049, 0;  // near s0; far from all; near s2 (flipped)
  normals << 0, 0, 1, 0, 0, 1, 0, 0, 1;
  PosedTemplateView view;
  view.vertices = &vertices;
  view.normals = &normals;
  EStep estep(scan, EStepOptions());
  OneToOneOptions o;
  o.max_distance = 0.1;
  o.min_normal_dot = 0.5;
  NearestTargets nn;
  estep.FindNearest(view, o, &nn);
  EXPECT_EQ(nn.index[0], 0);
  EXPECT_EQ(nn.weight[0], 1.0);
  EXPECT_EQ(nn.index[1], -1);  // beyond max_distance
  EXPECT_EQ(nn.index[2], -1);  // incompatible normal
  EXPECT_EQ(nn.num_matched, 1);
}

TEST(EStepTest, PointCloudIndexMatchesBruteForce) {
  const PointSets sets = MakePointSets(700, 50, 15);
  PointCloudIndex index(sets.scan.points, 4);
  for (int t = 0; t < 50; ++t) {
    const Eigen::Vector3d q = sets.vertices.row(t).transpose();
    Eigen::Index best;
    const double best_d2 =
        (sets.scan.points.rowwise() - q.transpose()).rowwise().squaredNorm().minCoeff(&best);
    double d2 = 0.0;
    EXPECT_EQ(index.Nearest(q, &d2), best);
    EXPECT_NEAR(d2, best_d2, 1e-15);
    std::vector<std::pair<int, double>> found;
    index.Radius(q, 0.1, &found);
    int expected = 0;
    for (int s = 0; s < sets.scan.size(); ++s)
      expected += (sets.scan.points.row(s) - q.transpose()).norm() < 0.1;
    EXPECT_EQ(static_cast<int>(found.size()), expected);
  }
}

TEST(EStepTest, NearestWithinABoundFindsTheNearestOrNone) {
  const PointSets sets = MakePointSets(700, 50, 17);
  PointCloudIndex index(sets.scan.points, 10);
  int found_within = 0, found_none = 0;
  for (int t = 0; t < 50; ++t) {
    const Eigen::Vector3d q = sets.vertices.row(t).transpose();
    // The nearest point by brute force; its squared distance as the index computes it
    // (Nearest is NearestWithin without a bound).
    Eigen::Index nearest = -1;
    (sets.scan.points.rowwise() - q.transpose()).rowwise().squaredNorm().minCoeff(&nearest);
    double nearest_d2 = 0.0;
    ASSERT_EQ(index.Nearest(q, &nearest_d2), nearest);
    // Bounds below, at and above the nearest distance; a bound at another point's distance (as
    // the ICP's previous nearest point gives it) finds the nearest too.
    const Eigen::Vector3d other = sets.scan.points.row((7 * t) % sets.scan.size()).transpose();
    for (const double bound2 : {0.5 * nearest_d2, nearest_d2, nearest_d2 * (1.0 + 1e-9),
                                4.0 * nearest_d2, (other - q).squaredNorm() * (1.0 + 1e-9)}) {
      double d2 = -1.0;
      const int i = index.NearestWithin(q, bound2, &d2);
      if (nearest_d2 < bound2) {
        EXPECT_EQ(i, nearest) << "query " << t << ", bound " << bound2;
        EXPECT_EQ(d2, nearest_d2);
        ++found_within;
      } else {
        EXPECT_EQ(i, -1) << "query " << t << ", bound " << bound2;
        EXPECT_TRUE(std::isinf(d2));
        ++found_none;
      }
    }
  }
  EXPECT_GT(found_within, 100);
  EXPECT_GT(found_none, 50);
  double d2 = 0.0;
  EXPECT_EQ(index.NearestWithin(Eigen::Vector3d::Zero(), 0.0, &d2), -1);
  const PointCloudIndex empty{Eigen::MatrixX3d(0, 3)};
  EXPECT_EQ(empty.NearestWithin(Eigen::Vector3d::Zero(), 1.0, &d2), -1);
  EXPECT_TRUE(std::isinf(d2));
  EXPECT_THROW(PointCloudIndex(sets.scan.points, 0), Error);  // no leaf
}

TEST(EStepTest, RejectsBadInput) {
  const PointSets sets = MakePointSets(10, 5, 16);
  EStepOptions options;
  options.k = 0;
  EXPECT_THROW(EStep(sets.scan, options), Error);
  options.k = 8;
  options.candidate_margin = -0.01;
  EXPECT_THROW(EStep(sets.scan, options), Error);
  options.candidate_margin = 0.01;
  options.voxel_cell = -0.01;
  EXPECT_THROW(EStep(sets.scan, options), Error);
  options.voxel_cell = 0.0;
  options.list_radius = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(EStep(sets.scan, options), Error);
  options.list_radius = 0.0;
  Scan broken = sets.scan;
  broken.normals.resize(3, 3);
  EXPECT_THROW(EStep(broken, EStepOptions()), Error);
  EStep estep(sets.scan, EStepOptions());
  CorrespondenceTargets targets;
  EXPECT_THROW(estep.Compute(View(sets, false), -1.0, &targets), Error);
  Eigen::MatrixX3d wrong(2, 3);
  PosedTemplateView view = View(sets, false);
  view.normals = &wrong;
  EXPECT_THROW(estep.Compute(view, 0.1, &targets), Error);
}

TEST(EStepTest, PairKernelsGiveBitIdenticalSums) {
  // The branch-free and SIMD candidate-list loops compute each candidate as the branching
  // loop does and add the candidates in list order: their sums must equal its sums exactly,
  // for every list length (the 2- and 4-wide loops leave a remainder) and mix of rejected
  // candidates.
  using estep_internal::PairKernel;
  using estep_internal::PairKernelAvailable;
  using estep_internal::VertexQuery;
  using estep_internal::VertexSums;
  using estep_internal::WeighCandidateListWith;
  struct alignas(64) Row {
    double v[estep_internal::kPackedStride];
  };
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  constexpr int kPoints = 200;
  std::vector<Row> rows(kPoints);
  for (Row& row : rows) {
    // Within ~4.5 cm of the origin, normals mostly along +z (a quarter face away),
    // multiplicity 1..4 (voxel cells): runs of kept and of rejected candidates.
    for (int d = 0; d < 3; ++d) row.v[d] = 0.045 * u(rng);
    Eigen::Vector3d n(u(rng), u(rng), u(rng) + 0.6);
    n.normalize();
    for (int d = 0; d < 3; ++d) row.v[3 + d] = n[d];
    row.v[6] = 1.0 + std::floor(4.0 * (0.5 + 0.5 * u(rng)));
    row.v[7] = 0.0;
  }
  const std::vector<PairKernel> kernels = {PairKernel::kAuto, PairKernel::kBranchFree,
                                           PairKernel::kSse2, PairKernel::kAvx};
  int compared = 0;
  long long kept = 0, candidates = 0;
  for (int trial = 0; trial < 80; ++trial) {
    VertexQuery q;
    Eigen::Vector3d n(0.3 * u(rng), 0.3 * u(rng), 1.0);
    n.normalize();
    for (int d = 0; d < 3; ++d) {
      q.x[d] = 0.02 * u(rng);
      q.n[d] = n[d];
      q.c[d] = 0.0;
    }
    q.radius2 = 0.04 * 0.04;
    q.epsilon = 1e-4;
    q.lambda_color = 1.0;
    const int count = trial % 40;  // 0 .. 39 candidates
    std::vector<int> index(count);
    for (int& i : index) i = static_cast<int>(rng() % kPoints);
    VertexSums scalar;  // the branching loop (the E-step's before the SIMD kernels)
    WeighCandidateListWith(PairKernel::kBranching, q, rows[0].v, index.data(), count, &scalar);
    kept += scalar.pairs;
    candidates += count;
    for (PairKernel kernel : kernels) {
      if (!PairKernelAvailable(kernel)) continue;
      VertexSums sums;
      WeighCandidateListWith(kernel, q, rows[0].v, index.data(), count, &sums);
      EXPECT_EQ(sums.a, scalar.a) << "trial " << trial << " kernel " << static_cast<int>(kernel);
      for (int d = 0; d < 3; ++d) EXPECT_EQ(sums.b[d], scalar.b[d]) << "trial " << trial;
      EXPECT_EQ(sums.c, scalar.c) << "trial " << trial;
      EXPECT_EQ(sums.pairs, scalar.pairs) << "trial " << trial;
      ++compared;
    }
  }
  EXPECT_GE(compared, 160);  // at least the automatic and the branch-free loop every trial
  // The fixture mixes kept and rejected candidates.
  EXPECT_GT(kept, candidates / 4);
  EXPECT_LT(kept, candidates - candidates / 10);
}

}  // namespace
}  // namespace artex
