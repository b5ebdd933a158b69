// NearestGrid against PointCloudIndex (the kd-tree it stands in for) and the ICP run on
// either index.
#include "solvers/nearest_grid.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "models/error.h"
#include "models/template_generator.h"
#include "solvers/estep.h"
#include "solvers/icp_init.h"
#include "tests/solvers/fitting_test_util.h"

namespace artex {
namespace {

// Points on a wavy sheet (a surface, as template vertices lie) with a few scattered ones.
Eigen::MatrixX3d SheetPoints(int n, std::mt19937_64* rng) {
  std::uniform_real_distribution<double> u(-0.4, 0.4);
  Eigen::MatrixX3d points(n, 3);
  for (int i = 0; i < n; ++i) {
    const double x = u(*rng), y = 2.0 * u(*rng);
    const double z = i % 50 == 0 ? u(*rng) : 0.05 * std::sin(8.0 * x) * std::cos(3.0 * y);
    points.row(i) = Eigen::RowVector3d(x, y, z);
  }
  return points;
}

TEST(NearestGridTest, FindsWhatTheKdTreeFindsBitForBit) {
  std::mt19937_64 rng(7);
  const Eigen::MatrixX3d points = SheetPoints(3000, &rng);
  const PointCloudIndex tree(points, 24);
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (const double cell : {0.01, 0.03, 0.1}) {
    const NearestGrid grid(points, cell);
    ASSERT_EQ(grid.size(), 3000);
    int found = 0, none = 0;
    for (int q = 0; q < 2000; ++q) {
      // Near the sheet, off it, outside the grid's box and far away.
      const double spread = q % 4 == 0 ? 0.005 : q % 4 == 1 ? 0.05 : q % 4 == 2 ? 0.5 : 5.0;
      const Eigen::Vector3d offset(g(rng), g(rng), g(rng));
      const Eigen::Vector3d query = points.row(q % points.rows()).transpose() + spread * offset;
      double nearest2 = 0.0;
      const int nearest = tree.Nearest(query, &nearest2);
      // Bounds around the nearest distance (below, at, just above, wider) and unbounded.
      for (const double bound2 : {0.5 * nearest2, nearest2, nearest2 * (1.0 + 1e-9),
                                  nearest2 * (1.0 + 10.0 * u(rng)), 0.05 * 0.05,
                                  std::numeric_limits<double>::infinity()}) {
        double tree2 = 0.0, grid2 = 0.0;
        const int expected = tree.NearestWithin(query, bound2, &tree2);
        const int got = grid.NearestWithin(query, bound2, &grid2);
        ASSERT_EQ(got, expected) << "cell " << cell << ", query " << q << ", bound2 " << bound2;
        ASSERT_EQ(grid2, tree2) << "cell " << cell << ", query " << q;
        if (got >= 0) {
          EXPECT_EQ(got, nearest);
          ++found;
        } else {
          EXPECT_TRUE(std::isinf(grid2));
          ++none;
        }
      }
    }
    EXPECT_GT(found, 5000);
    EXPECT_GT(none, 1000);
  }
}

TEST(NearestGridTest, EmptyAndBadInput) {
  double d2 = 0.0;
  const NearestGrid empty(Eigen::MatrixX3d(0, 3), 0.03);
  EXPECT_EQ(empty.NearestWithin(Eigen::Vector3d::Zero(), 1.0, &d2), -1);
  EXPECT_TRUE(std::isinf(d2));
  const Eigen::MatrixX3d one = Eigen::RowVector3d(1.0, 2.0, 3.0);
  const NearestGrid single(one, 0.03);
  EXPECT_EQ(single.NearestWithin(Eigen::Vector3d(1.0, 2.0, 3.01), 1.0, &d2), 0);
  EXPECT_EQ(single.NearestWithin(Eigen::Vector3d(1.0, 2.0, 3.01), 0.0, &d2), -1);  // no bound
  const Eigen::Vector3d nan(std::nan(""), 0.0, 0.0);
  EXPECT_EQ(single.NearestWithin(nan, 1.0, &d2), -1);
  for (const double cell : {0.0, -0.03, std::nan(""), std::numeric_limits<double>::infinity()}) {
    EXPECT_THROW(NearestGrid(one, cell), Error) << cell;
  }
  Eigen::MatrixX3d spread(2, 3);
  spread << 0.0, 0.0, 0.0, 100.0, 100.0, 100.0;
  try {
    NearestGrid(spread, 0.01);  // 10^12 cells
    ADD_FAILURE() << "expected a throw";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cell"), std::string::npos) << e.what();
  }
  spread(1, 2) = std::numeric_limits<double>::infinity();
  EXPECT_THROW(NearestGrid(spread, 0.03), Error);
}

// The ICP on the grid gives the kd-tree's similarity bit for bit: the scale sample's start (the
// fitted pose, pairs within 5 cm) and the first frame's (coarse alignment, 25 cm).
TEST(NearestGridTest, IcpOnTheGridEqualsTheKdTree) {
  const Template model = GenerateTemplate(BodyShapeOptions());
  const Skinning skinning(model);
  std::mt19937_64 rng(11);
  const Pose truth = testing_util::RandomPose(model.num_joints(), 0.25, 0.15, 0.05, &rng);
  Eigen::MatrixX3d posed;
  skinning.Apply(truth, &posed);
  const Scan scan = testing_util::SampleScan(posed, model.triangles, Eigen::Vector3d(0, 1, 2.5),
                                             5000.0, 0.004, &rng);
  ASSERT_GT(scan.size(), 3000);
  Pose start = truth;
  start.scale *= 1.03;
  start.translation += Eigen::Vector3d(0.01, -0.02, 0.015);
  for (const bool coarse : {false, true}) {
    IcpInitOptions options;
    options.coarse_alignment = coarse;
    options.max_distance = coarse ? 0.25 : 0.05;
    options.max_scan_points = 1500;
    const IcpInitResult tree = AlignByIcp(skinning, start, scan, options);
    options.grid_cell = 0.03;
    const IcpInitResult grid = AlignByIcp(skinning, start, scan, options);
    EXPECT_GT(tree.iterations, 2);
    EXPECT_EQ(grid.iterations, tree.iterations);
    EXPECT_EQ(grid.num_pairs, tree.num_pairs);
    EXPECT_EQ(grid.rms, tree.rms);
    EXPECT_EQ(grid.pose.scale, tree.pose.scale);
    EXPECT_TRUE(grid.pose.rotation == tree.pose.rotation);
    EXPECT_TRUE(grid.pose.translation == tree.pose.translation);
    EXPECT_NEAR(tree.pose.scale, truth.scale, 0.01);
  }
  IcpInitOptions bad;
  bad.grid_cell = -0.01;
  EXPECT_THROW(AlignByIcp(skinning, start, scan, bad), Error);
}

}  // namespace
}  // namespace artex
