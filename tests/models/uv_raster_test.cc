#include "models/uv_raster.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <string>
#include <utility>
#include <vector>

namespace artex {
namespace {

constexpr int kN = 8;

// A template whose only UV triangle has the given corners, given in cell units of a kN grid
// (the UVs are corner / kN; every corner used below is a multiple of 1/2, so exact).
Template OneUvTriangle(const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                       const Eigen::Vector2d& c) {
  Template t;
  t.uvs.resize(3, 2);
  t.uvs.row(0) = a.transpose() / kN;
  t.uvs.row(1) = b.transpose() / kN;
  t.uvs.row(2) = c.transpose() / kN;
  t.triangles.resize(1, 3);
  t.triangles << 0, 1, 2;
  t.uv_triangles = t.triangles;
  return t;
}

// The cells ForEachCellInside visits, as kN rows of '#' (visited) and '.', row y = 0 first,
// separated by '|'.
std::string CellPicture(const UvTriangleCells& t) {
  std::string picture(kN * (kN + 1) - 1, '.');
  for (int y = 0; y + 1 < kN; ++y) picture[y * (kN + 1) + kN] = '|';
  ForEachCellInside(t, [&](int x, int y) {
    ASSERT_TRUE(x >= 0 && x < kN && y >= 0 && y < kN) << x << ", " << y;
    char& cell = picture[y * (kN + 1) + x];
    EXPECT_EQ(cell, '.') << "cell " << x << ", " << y << " visited twice";
    cell = '#';
  });
  return picture;
}

// The clamped cell box as {x0, x1, y0, y1}.
std::array<int, 4> Box(const UvTriangleCells& t) { return {t.x0, t.x1, t.y0, t.y1}; }

std::vector<std::pair<int, int>> VisitOrder(const UvTriangleCells& t) {
  std::vector<std::pair<int, int>> order;
  ForEachCellInside(t, [&](int x, int y) { order.emplace_back(y, x); });
  return order;
}

TEST(UvRasterTest, RightTriangleCoversKnownCellsWithInclusiveEdges) {
  // Corners on cell centres: the centres on all three edges (x = 0, y = 0, x + y = 5) count.
  const Template tmpl = OneUvTriangle({0.5, 0.5}, {5.5, 0.5}, {0.5, 5.5});
  const UvTriangleCells t = UvTriangleOnGrid(tmpl, 0, kN);
  EXPECT_EQ(t.p[0], Eigen::Vector2d(0.5, 0.5));
  EXPECT_EQ(t.p[1], Eigen::Vector2d(5.5, 0.5));
  EXPECT_EQ(t.p[2], Eigen::Vector2d(0.5, 5.5));
  EXPECT_EQ(t.area2, 25.0);
  EXPECT_EQ(Box(t), (std::array<int, 4>{0, 6, 0, 6}));
  EXPECT_EQ(CellPicture(t),
            "######..|#####...|####....|###.....|##......|#.......|........|........");
  EXPECT_TRUE(CellCentreInside(t, 0, 0));   // a corner
  EXPECT_TRUE(CellCentreInside(t, 3, 2));   // on the hypotenuse
  EXPECT_FALSE(CellCentreInside(t, 3, 3));  // just beyond it
  const std::vector<std::pair<int, int>> order = VisitOrder(t);
  ASSERT_EQ(order.size(), 21u);
  EXPECT_TRUE(std::is_sorted(order.begin(), order.end()));  // row by row, x increasing
}

TEST(UvRasterTest, CellCentresStrictlyInsideAWholeCellTriangle) {
  // Corners on cell corners: the hypotenuse x + y = 5 passes through the centres of x + y = 4.
  const UvTriangleCells t = UvTriangleOnGrid(OneUvTriangle({0, 0}, {5, 0}, {0, 5}), 0, kN);
  EXPECT_EQ(Box(t), (std::array<int, 4>{0, 5, 0, 5}));
  EXPECT_EQ(CellPicture(t),
            "#####...|####....|###.....|##......|#.......|........|........|........");
}

TEST(UvRasterTest, BothOrientationsGiveTheSameCells) {
  const Eigen::Vector2d triangles[][3] = {{{0.5, 0.5}, {5.5, 0.5}, {0.5, 5.5}},
                                          {{1, 0.5}, {7.5, 3}, {2.5, 7.5}},
                                          {{6, 1.5}, {0.5, 2}, {4.5, 7}}};
  for (const auto& c : triangles) {
    const UvTriangleCells ccw = UvTriangleOnGrid(OneUvTriangle(c[0], c[1], c[2]), 0, kN);
    const UvTriangleCells cw = UvTriangleOnGrid(OneUvTriangle(c[0], c[2], c[1]), 0, kN);
    ASSERT_NE(ccw.area2, 0.0);
    EXPECT_EQ(cw.area2, -ccw.area2);
    EXPECT_EQ(Box(cw), Box(ccw));
    const std::string picture = CellPicture(ccw);
    EXPECT_EQ(CellPicture(cw), picture);
    EXPECT_NE(picture.find('#'), std::string::npos) << picture;
  }
}

TEST(UvRasterTest, TrianglePartlyOutsideTheGridIsClamped) {
  // Corners at -4 and 8 cell units (UVs -0.5 and 1): the box is cut to the grid's 0..7.
  const UvTriangleCells t = UvTriangleOnGrid(OneUvTriangle({-4, -4}, {8, -4}, {-4, 8}), 0, kN);
  EXPECT_EQ(Box(t), (std::array<int, 4>{0, kN - 1, 0, kN - 1}));
  EXPECT_EQ(CellPicture(t),
            "####....|###.....|##......|#.......|........|........|........|........");
  // Beyond the far corner of the grid: the lower and right clamps.
  const UvTriangleCells far = UvTriangleOnGrid(OneUvTriangle({4, 4}, {12, 4}, {4, 12}), 0, kN);
  EXPECT_EQ(Box(far), (std::array<int, 4>{4, kN - 1, 4, kN - 1}));
  EXPECT_EQ(VisitOrder(far).size(), 16u);
  // Wholly off the grid: an empty box, no cells.
  const UvTriangleCells off = UvTriangleOnGrid(OneUvTriangle({9, 9}, {12, 9}, {9, 12}), 0, kN);
  EXPECT_LT(off.x1, off.x0);
  EXPECT_TRUE(VisitOrder(off).empty());
}

TEST(UvRasterTest, DegenerateTriangleHasZeroAreaAndNoCells) {
  for (const Template& tmpl : {OneUvTriangle({1, 1}, {3, 3}, {5.5, 5.5}),  // collinear
                               OneUvTriangle({2, 1}, {2, 1}, {6, 4})}) {   // a repeated corner
    const UvTriangleCells t = UvTriangleOnGrid(tmpl, 0, kN);
    EXPECT_EQ(t.area2, 0.0);
    EXPECT_LT(t.x1, t.x0);
    EXPECT_LT(t.y1, t.y0);
    EXPECT_TRUE(VisitOrder(t).empty());
  }
}

TEST(UvRasterTest, PicksTheNamedTriangleOfTheTemplate) {
  Template tmpl = OneUvTriangle({0.5, 0.5}, {5.5, 0.5}, {0.5, 5.5});
  tmpl.uvs.conservativeResize(4, 2);
  tmpl.uvs.row(3) << 1.0, 1.0;
  tmpl.triangles.conservativeResize(2, 3);
  tmpl.triangles.row(1) << 3, 2, 1;
  tmpl.uv_triangles = tmpl.triangles;
  const UvTriangleCells t = UvTriangleOnGrid(tmpl, 1, kN);
  EXPECT_EQ(t.p[0], Eigen::Vector2d(8, 8));
  EXPECT_EQ(t.p[1], Eigen::Vector2d(0.5, 5.5));
  EXPECT_EQ(t.p[2], Eigen::Vector2d(5.5, 0.5));
  EXPECT_EQ(t.area2, (-7.5) * (-7.5) - (-2.5) * (-2.5));
  EXPECT_EQ(Box(t), (std::array<int, 4>{0, kN - 1, 0, kN - 1}));
  EXPECT_EQ(CellPicture(t),
            ".....#..|....##..|...###..|..#####.|.######.|#######.|...#####|......##");
}

}  // namespace
}  // namespace artex
