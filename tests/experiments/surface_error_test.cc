// The output stage's vertex error (experiments/surface_error.h): the nearest point of its grid
// (NearestGrid with its automatic cell) is the brute-force nearest (the same index and squared
// distance, bit for bit), also for query points far outside the points' bounding box,
// degenerate (flat, single-point) sets and duplicates; SurfaceErrors equals the same
// computation by brute force, with or without a guess of the nearest vertices, whatever the
// guess holds.
#include "experiments/surface_error.h"
#include "solvers/nearest_grid.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace artex {
namespace {

int BruteNearest(const Eigen::MatrixX3d& points, const Eigen::Vector3d& p, double* d2) {
  int best = -1;
  *d2 = std::numeric_limits<double>::infinity();
  for (int i = 0; i < points.rows(); ++i) {
    const double dx = p[0] - points(i, 0), dy = p[1] - points(i, 1), dz = p[2] - points(i, 2);
    const double d = dx * dx + dy * dy + dz * dz;
    if (d < *d2) {
      *d2 = d;
      best = i;
    }
  }
  return best;
}

// Points on a sphere-ish surface (like a body's vertices), optionally flattened.
Eigen::MatrixX3d SurfacePoints(int n, std::mt19937* rng, double flatten) {
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::MatrixX3d points(n, 3);
  for (int i = 0; i < n; ++i) {
    Eigen::Vector3d v(g(*rng), g(*rng), g(*rng));
    v = v.normalized().cwiseProduct(Eigen::Vector3d(0.3, 0.9, 0.2 * flatten));
    points.row(i) = v.transpose();
  }
  return points;
}

TEST(SurfaceErrorTest, GridNearestIsBruteForceNearest) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  for (const double flatten : {1.0, 0.0}) {
    for (const int n : {1, 2, 50, 3000}) {
      Eigen::MatrixX3d points = SurfacePoints(n, &rng, flatten);
      if (n >= 50) points.row(7) = points.row(3);  // a duplicate: the lower index wins
      const NearestGrid grid(points, NearestGrid::AutoCell(points));
      for (int q = 0; q < 2000; ++q) {
        // Near the surface, and anywhere in a box three times its size.
        Eigen::Vector3d p = q % 2 ? Eigen::Vector3d(u(rng), u(rng), u(rng))
                                  : Eigen::Vector3d(points.row(q % n).transpose() +
                                                    0.01 * Eigen::Vector3d(u(rng), u(rng), u(rng)));
        double d2 = 0.0, brute_d2 = 0.0;
        const int index = grid.Nearest(p, &d2);
        const int brute = BruteNearest(points, p, &brute_d2);
        ASSERT_EQ(index, brute) << "n " << n << " query " << q;
        ASSERT_EQ(d2, brute_d2);
      }
    }
  }
  const Eigen::MatrixX3d none(0, 3);
  double d2 = 0.0;
  EXPECT_EQ(NearestGrid(none, NearestGrid::AutoCell(none)).Nearest(Eigen::Vector3d::Zero(), &d2),
            -1);
}

TEST(SurfaceErrorTest, SurfaceErrorsEqualBruteForce) {
  std::mt19937 rng(4);
  std::normal_distribution<double> g(0.0, 0.005);
  const Eigen::MatrixX3d truth = SurfacePoints(5000, &rng, 1.0);
  Eigen::MatrixX3d normals = truth.rowwise().normalized();
  normals.row(11).setZero();  // no normal: the vertex distance
  Eigen::MatrixX3d tracked = SurfacePoints(1500, &rng, 1.0);
  for (int i = 0; i < tracked.rows(); ++i) tracked.row(i) += Eigen::RowVector3d(g(rng), g(rng), g(rng));
  tracked.row(0) = truth.row(11) + Eigen::RowVector3d(0.001, 0.0, 0.0);
  double mean = 0.0, max = 0.0;
  SurfaceErrors(tracked, truth, normals, &mean, &max);
  double sum = 0.0, worst = 0.0;
  for (int t = 0; t < tracked.rows(); ++t) {
    const Eigen::Vector3d p = tracked.row(t);
    double d2 = 0.0;
    const int i = BruteNearest(truth, p, &d2);
    const Eigen::Vector3d q = truth.row(i), n = normals.row(i);
    const double plane = n.squaredNorm() > 0.5 ? std::abs(n.dot(p - q)) : std::sqrt(d2);
    const double d = std::min(std::sqrt(d2), plane);
    sum += d;
    worst = std::max(worst, d);
  }
  EXPECT_EQ(mean, sum / tracked.rows());
  EXPECT_EQ(max, worst);
  EXPECT_GT(mean, 0.0);
}

TEST(SurfaceErrorTest, GuessesOfTheNearestVertexChangeNothing) {
  std::mt19937 rng(5);
  std::normal_distribution<double> g(0.0, 0.005);
  const Eigen::MatrixX3d truth = SurfacePoints(5000, &rng, 1.0);
  const Eigen::MatrixX3d normals = truth.rowwise().normalized();
  Eigen::MatrixX3d tracked = SurfacePoints(1500, &rng, 1.0);
  for (int i = 0; i < tracked.rows(); ++i) {
    tracked.row(i) += Eigen::RowVector3d(g(rng), g(rng), g(rng));
  }
  // The next frame: the truth and the tracked points moved by a few mm.
  Eigen::MatrixX3d truth_next = truth, tracked_next = tracked;
  truth_next.rowwise() += Eigen::RowVector3d(0.004, -0.002, 0.001);
  for (int i = 0; i < tracked.rows(); ++i) tracked_next(i, 0) += g(rng);
  const Eigen::MatrixX3d normals_next = normals;

  const auto brute = [](const Eigen::MatrixX3d& points, const Eigen::MatrixX3d& queries) {
    std::vector<int> nearest(queries.rows());
    double d2 = 0.0;
    for (int t = 0; t < queries.rows(); ++t) {
      nearest[t] = BruteNearest(points, queries.row(t).transpose(), &d2);
    }
    return nearest;
  };
  double mean = 0.0, max = 0.0;
  SurfaceErrors(tracked, truth, normals, &mean, &max);
  std::vector<int> nearest;  // empty: no guess; filled with the nearest vertices
  double guessed_mean = 0.0, guessed_max = 0.0;
  SurfaceErrors(tracked, truth, normals, &guessed_mean, &guessed_max, &nearest);
  EXPECT_EQ(guessed_mean, mean);
  EXPECT_EQ(guessed_max, max);
  EXPECT_EQ(nearest, brute(truth, tracked));

  // The previous frame's answer as the guess, and guesses that are wrong in every way.
  double next_mean = 0.0, next_max = 0.0;
  SurfaceErrors(tracked_next, truth_next, normals_next, &next_mean, &next_max);
  const std::vector<int> next_nearest = brute(truth_next, tracked_next);
  std::uniform_int_distribution<int> any(-3, 6000);
  std::vector<int> wrong(tracked.rows());
  for (int& w : wrong) w = any(rng);
  wrong[0] = std::numeric_limits<int>::max();
  wrong[1] = std::numeric_limits<int>::min();
  const std::vector<std::vector<int>> guesses = {
      nearest, next_nearest, wrong, std::vector<int>(tracked.rows(), -1),
      std::vector<int>(tracked.rows(), 0), std::vector<int>(7, 3)};
  for (size_t k = 0; k < guesses.size(); ++k) {
    std::vector<int> guess = guesses[k];
    double m = 0.0, x = 0.0;
    SurfaceErrors(tracked_next, truth_next, normals_next, &m, &x, &guess);
    EXPECT_EQ(m, next_mean) << "guess " << k;
    EXPECT_EQ(x, next_max) << "guess " << k;
    EXPECT_EQ(guess, next_nearest) << "guess " << k;
  }

  // A non-finite tracked point ends the search, as without a guess: -1 from it on.
  Eigen::MatrixX3d broken = tracked_next;
  broken(5, 1) = std::numeric_limits<double>::quiet_NaN();
  double broken_mean = 0.0, broken_max = 0.0, m = 0.0, x = 0.0;
  SurfaceErrors(broken, truth_next, normals_next, &broken_mean, &broken_max);
  std::vector<int> guess = next_nearest;
  SurfaceErrors(broken, truth_next, normals_next, &m, &x, &guess);
  EXPECT_EQ(m, broken_mean);
  EXPECT_EQ(x, broken_max);
  ASSERT_EQ(guess.size(), next_nearest.size());
  for (int t = 0; t < 5; ++t) EXPECT_EQ(guess[t], next_nearest[t]);
  for (size_t t = 5; t < guess.size(); ++t) EXPECT_EQ(guess[t], -1) << t;
}

}  // namespace
}  // namespace artex
