#include "models/normals.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <utility>
#include <vector>

#include "models/error.h"

namespace artex {
namespace {

struct Mesh {
  Eigen::MatrixX3d vertices;
  Eigen::MatrixX3i triangles;
};

// Icosphere of the given radius and centre: an icosahedron (counter-clockwise from outside)
// subdivided `levels` times, new vertices projected onto the sphere.
Mesh Icosphere(int levels, double radius, const Eigen::Vector3d& center) {
  const double g = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> v = {{-1, g, 0}, {1, g, 0}, {-1, -g, 0}, {1, -g, 0},
                                    {0, -1, g}, {0, 1, g}, {0, -1, -g}, {0, 1, -g},
                                    {g, 0, -1}, {g, 0, 1}, {-g, 0, -1}, {-g, 0, 1}};
  for (auto& p : v) p.normalize();
  std::vector<Eigen::Vector3i> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                    {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                    {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                    {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int level = 0; level < levels; ++level) {
    std::map<std::pair<int, int>, int> midpoint;
    auto mid = [&](int a, int b) {
      const std::pair<int, int> key(std::min(a, b), std::max(a, b));
      auto it = midpoint.find(key);
      if (it != midpoint.end()) return it->second;
      v.push_back((v[a] + v[b]).normalized());
      const int index = static_cast<int>(v.size()) - 1;
      midpoint[key] = index;
      return index;
    };
    std::vector<Eigen::Vector3i> next;
    for (const auto& t : f) {
      const int a = mid(t[0], t[1]), b = mid(t[1], t[2]), c = mid(t[2], t[0]);
      next.push_back({t[0], a, c});
      next.push_back({t[1], b, a});
      next.push_back({t[2], c, b});
      next.push_back({a, b, c});
    }
    f = next;
  }
  Mesh mesh;
  mesh.vertices.resize(v.size(), 3);
  for (size_t i = 0; i < v.size(); ++i) mesh.vertices.row(i) = (center + radius * v[i]).transpose();
  mesh.triangles.resize(f.size(), 3);
  for (size_t i = 0; i < f.size(); ++i) mesh.triangles.row(i) = f[i].transpose();
  return mesh;
}

TEST(NormalsTest, ClosedConvexMeshNormalsPointOutwards) {
  const Eigen::Vector3d center(0.5, -1.0, 2.0);
  const Mesh mesh = Icosphere(2, 0.3, center);
  ASSERT_EQ(mesh.vertices.rows(), 162);
  ASSERT_EQ(mesh.triangles.rows(), 320);
  Eigen::MatrixX3d vertex_normals, triangle_normals;
  ComputeVertexNormals(mesh.vertices, mesh.triangles, &vertex_normals);
  ComputeTriangleNormals(mesh.vertices, mesh.triangles, &triangle_normals);
  ASSERT_EQ(vertex_normals.rows(), mesh.vertices.rows());
  ASSERT_EQ(triangle_normals.rows(), mesh.triangles.rows());
  for (int i = 0; i < mesh.vertices.rows(); ++i) {
    const Eigen::Vector3d radial = (mesh.vertices.row(i).transpose() - center).normalized();
    EXPECT_NEAR(vertex_normals.row(i).norm(), 1.0, 1e-12);
    // On a fine icosphere the mean of incident face normals is close to radial.
    EXPECT_GT(vertex_normals.row(i).dot(radial), 0.99) << "vertex " << i;
  }
  for (int f = 0; f < mesh.triangles.rows(); ++f) {
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    for (int c = 0; c < 3; ++c) centroid += mesh.vertices.row(mesh.triangles(f, c)).transpose();
    centroid /= 3.0;
    EXPECT_NEAR(triangle_normals.row(f).norm(), 1.0, 1e-12);
    EXPECT_GT(triangle_normals.row(f).dot((centroid - center).normalized()), 0.9) << f;
  }
}

TEST(NormalsTest, ReversedOrientationFlipsNormals) {
  const Mesh mesh = Icosphere(1, 1.0, Eigen::Vector3d::Zero());
  Eigen::MatrixX3i reversed = mesh.triangles;
  reversed.col(1).swap(reversed.col(2));
  Eigen::MatrixX3d n, m;
  ComputeVertexNormals(mesh.vertices, mesh.triangles, &n);
  ComputeVertexNormals(mesh.vertices, reversed, &m);
  EXPECT_LT((n + m).cwiseAbs().maxCoeff(), 1e-14);
}

TEST(NormalsTest, MeanOfUnitNormalsIgnoresArea) {
  // Two triangles sharing vertex 0: a large one in the z = 0 plane (normal +z) and a tiny
  // one in the x = 0 plane (normal +x). Unit (not area) weighting gives (1, 0, 1)/sqrt(2).
  Eigen::MatrixX3d vertices(5, 3);
  vertices << 0, 0, 0,  //
      10, 0, 0,         //
      0, 10, 0,         //
      0, 0.01, 0,       //
      0, 0, 0.01;
  Eigen::MatrixX3i triangles(2, 3);
  triangles << 0, 1, 2,  //
      0, 3, 4;
  Eigen::MatrixX3d normals;
  ComputeVertexNormals(vertices, triangles, &normals);
  EXPECT_LT((normals.row(0).transpose() - Eigen::Vector3d(1, 0, 1) / std::sqrt(2.0)).norm(), 1e-12);
  EXPECT_LT((normals.row(1).transpose() - Eigen::Vector3d(0, 0, 1)).norm(), 1e-12);
  EXPECT_LT((normals.row(3).transpose() - Eigen::Vector3d(1, 0, 0)).norm(), 1e-12);
}

TEST(NormalsTest, DegenerateAndIsolatedGiveZero) {
  Eigen::MatrixX3d vertices(6, 3);
  vertices << 0, 0, 0,  //
      1, 0, 0,          //
      2, 0, 0,          // collinear with the first two
      0, 1, 0,          //
      5, 5, 5,          // isolated
      1, 1, 0;
  Eigen::MatrixX3i triangles(2, 3);
  triangles << 0, 1, 2,  // degenerate
      1, 5, 3;           // normal +z
  Eigen::MatrixX3d vertex_normals, triangle_normals;
  ComputeTriangleNormals(vertices, triangles, &triangle_normals);
  EXPECT_EQ(triangle_normals.row(0).norm(), 0.0);
  EXPECT_LT((triangle_normals.row(1).transpose() - Eigen::Vector3d(0, 0, 1)).norm(), 1e-15);
  ComputeVertexNormals(vertices, triangles, &vertex_normals);
  EXPECT_EQ(vertex_normals.row(0).norm(), 0.0);  // only the degenerate triangle
  EXPECT_EQ(vertex_normals.row(2).norm(), 0.0);
  EXPECT_EQ(vertex_normals.row(4).norm(), 0.0);  // isolated
  EXPECT_LT((vertex_normals.row(1).transpose() - Eigen::Vector3d(0, 0, 1)).norm(), 1e-15);
}

TEST(NormalsTest, RejectsOutOfRangeIndices) {
  const Mesh mesh = Icosphere(0, 1.0, Eigen::Vector3d::Zero());
  Eigen::MatrixX3i bad = mesh.triangles;
  bad(3, 1) = static_cast<int>(mesh.vertices.rows());
  Eigen::MatrixX3d normals;
  EXPECT_THROW(ComputeVertexNormals(mesh.vertices, bad, &normals), Error);
  bad(3, 1) = -1;
  EXPECT_THROW(ComputeTriangleNormals(mesh.vertices, bad, &normals), Error);
}

// A subset's normals from its incident triangles alone are the whole mesh's at those vertices,
// bit for bit: on a noisy icosphere (random triangle shapes, some degenerate) and with the
// degenerate and isolated vertices of the test above.
TEST(NormalsTest, SubsetNormalsEqualTheWholeMeshsBitForBit) {
  Mesh mesh = Icosphere(3, 0.7, Eigen::Vector3d(0.1, 1.0, 2.0));
  std::mt19937_64 rng(3);
  std::normal_distribution<double> g(0.0, 0.01);
  for (Eigen::Index v = 0; v < mesh.vertices.rows(); ++v) {
    for (int d = 0; d < 3; ++d) mesh.vertices(v, d) += g(rng);
  }
  mesh.vertices.row(17) = mesh.vertices.row(5);  // degenerate triangles at vertex 5
  Eigen::MatrixX3d whole, some;
  ComputeVertexNormals(mesh.vertices, mesh.triangles, &whole);
  std::vector<int> which;
  for (int v = static_cast<int>(mesh.vertices.rows()) - 1; v >= 0; v -= 3) which.push_back(v);
  ASSERT_NE(std::find(which.begin(), which.end(), 5), which.end());  // the degenerate ones'
  const IncidentTriangles incident =
      FindIncidentTriangles(mesh.triangles, which, static_cast<int>(mesh.vertices.rows()));
  // Each vertex's triangles, ascending, as a brute-force search lists them.
  for (size_t i = 0; i < which.size(); ++i) {
    std::vector<int> expected;
    for (int f = 0; f < mesh.triangles.rows(); ++f) {
      if ((mesh.triangles.row(f).array() == which[i]).any()) expected.push_back(f);
    }
    const std::vector<int> found(incident.triangles.begin() + incident.offset[i],
                                 incident.triangles.begin() + incident.offset[i + 1]);
    ASSERT_EQ(found, expected) << "vertex " << which[i];
  }
  ComputeVertexNormalsOf(mesh.vertices, mesh.triangles, incident, &some);
  ASSERT_EQ(some.rows(), static_cast<Eigen::Index>(which.size()));
  for (size_t i = 0; i < which.size(); ++i) {
    for (int d = 0; d < 3; ++d) ASSERT_EQ(some(i, d), whole(which[i], d)) << "vertex " << which[i];
  }

  Eigen::MatrixX3d vertices(6, 3);
  vertices << 0, 0, 0, 1, 0, 0, 2, 0, 0, 0, 1, 0, 5, 5, 5, 1, 1, 0;
  Eigen::MatrixX3i triangles(2, 3);
  triangles << 0, 1, 2, 1, 5, 3;
  ComputeVertexNormals(vertices, triangles, &whole);
  const std::vector<int> all = {4, 0, 1, 2, 3, 5};
  ComputeVertexNormalsOf(vertices, triangles, FindIncidentTriangles(triangles, all, 6), &some);
  for (size_t i = 0; i < all.size(); ++i) {
    for (int d = 0; d < 3; ++d) EXPECT_EQ(some(i, d), whole(all[i], d)) << "vertex " << all[i];
  }
}

TEST(NormalsTest, SubsetNormalsRejectBadInput) {
  const Mesh mesh = Icosphere(1, 1.0, Eigen::Vector3d::Zero());
  const int n = static_cast<int>(mesh.vertices.rows());
  EXPECT_THROW(FindIncidentTriangles(mesh.triangles, {0, n}, n), Error);
  EXPECT_THROW(FindIncidentTriangles(mesh.triangles, {-1}, n), Error);
  EXPECT_THROW(FindIncidentTriangles(mesh.triangles, {3, 4, 3}, n), Error);  // listed twice
  EXPECT_THROW(FindIncidentTriangles(mesh.triangles, {0}, n - 1), Error);     // triangles
  const IncidentTriangles incident = FindIncidentTriangles(mesh.triangles, {0, 1}, n);
  Eigen::MatrixX3d normals;
  EXPECT_THROW(ComputeVertexNormalsOf(mesh.vertices.topRows(n - 1), mesh.triangles, incident,
                                      &normals),
               Error);
  EXPECT_THROW(ComputeVertexNormalsOf(mesh.vertices, mesh.triangles.topRows(3), incident, &normals),
               Error);
  ComputeVertexNormalsOf(Eigen::MatrixX3d(0, 3), Eigen::MatrixX3i(0, 3), IncidentTriangles(),
                         &normals);  // nothing listed, an empty mesh
  EXPECT_EQ(normals.rows(), 0);
}

}  // namespace
}  // namespace artex
