#include "render/rasterizer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "models/error.h"

namespace artex {
namespace {

// fx = fy = 1, cx = cy = 0: a point (u, v, 1) projects exactly to pixel (u, v), so tests can
// place vertices at exact screen positions (e.g. on pixel centres).
PinholeCamera ScreenCamera(int width, int height) {
  PinholeCamera c;
  c.width = width;
  c.height = height;
  c.fx = c.fy = 1.0;
  c.cx = c.cy = 0.0;
  return c;
}

PinholeCamera KinectLikeCamera() {
  PinholeCamera c;  // 640 x 480, f = 525, identity pose
  c.width = 160;
  c.height = 120;
  c.fx = c.fy = 131.25;
  c.cx = 79.5;
  c.cy = 59.5;
  return c;
}

Eigen::MatrixX3i OneTriangle() {
  Eigen::MatrixX3i t(1, 3);
  t << 0, 1, 2;
  return t;
}

// Independent reference: long-double same-side test at the pixel centre of the projected
// triangle. Returns +1 inside, -1 outside, 0 when within `tol` of an edge (ambiguous).
int AnalyticInside(const Eigen::Vector2d p[3], double u, double v, long double tol) {
  long double e[3];
  long double area = 0;
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector2d& a = p[k];
    const Eigen::Vector2d& b = p[(k + 1) % 3];
    e[k] = (static_cast<long double>(b.x()) - a.x()) * (static_cast<long double>(v) - a.y()) -
           (static_cast<long double>(b.y()) - a.y()) * (static_cast<long double>(u) - a.x());
    area += e[k];
  }
  bool all_in = true, near = false;
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector2d& a = p[k];
    const Eigen::Vector2d& b = p[(k + 1) % 3];
    const long double len = std::hypot(b.x() - a.x(), b.y() - a.y());
    const long double dist = (area > 0 ? e[k] : -e[k]) / len;  // signed distance (px)
    if (std::fabs(static_cast<double>(dist)) < tol) near = true;
    if (dist <= 0) all_in = false;
  }
  if (near) return 0;
  return all_in ? 1 : -1;
}

TEST(RasterizerTest, SingleTriangleCoverageMatchesAnalyticTest) {
  const PinholeCamera camera = KinectLikeCamera();
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> px(-20.0, 180.0), py(-20.0, 140.0), pz(0.5, 4.0);
  int checked = 0, covered_total = 0;
  for (int trial = 0; trial < 40; ++trial) {
    Eigen::MatrixX3d v(3, 3);
    Eigen::Vector2d screen[3];
    for (int k = 0; k < 3; ++k) {
      const double z = pz(rng);
      v.row(k) = camera.Unproject(px(rng), py(rng), z).transpose();
      screen[k] = camera.Project(v.row(k).transpose());
    }
    RasterBuffers buffers;
    Rasterize(v, OneTriangle(), camera, RasterOptions(), &buffers);
    ASSERT_EQ(buffers.width, camera.width);
    ASSERT_EQ(buffers.height, camera.height);
    for (int y = 0; y < camera.height; ++y) {
      for (int x = 0; x < camera.width; ++x) {
        const int expected = AnalyticInside(screen, x, y, 1e-9L);
        if (expected == 0) continue;
        const bool covered = buffers.triangle_id[buffers.index(x, y)] == 0;
        ASSERT_EQ(covered, expected > 0) << "trial " << trial << " pixel " << x << "," << y;
        covered_total += covered;
        ++checked;
      }
    }
  }
  EXPECT_EQ(checked, 40 * camera.width * camera.height);  // no ambiguous pixels expected
  EXPECT_GT(covered_total, 1000);
}

TEST(RasterizerTest, PlaneGivesExactPerspectiveCorrectDepth) {
  const PinholeCamera camera = KinectLikeCamera();
  // Fronto-parallel plane at z = 2.25 (two triangles larger than the view).
  // Then a slanted plane n . X = d in camera coordinates, spanning the view.
  struct Plane {
    Eigen::Vector3d n;
    double d;
  };
  const Plane planes[] = {{Eigen::Vector3d(0, 0, 1), 2.25},
                          {Eigen::Vector3d(0.4, -0.3, 1.0).normalized(), 1.7}};
  for (const Plane& plane : planes) {
    // Corners: pixels beyond the image unprojected onto the plane.
    auto on_plane = [&](double u, double v) {
      const Eigen::Vector3d ray((u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, 1.0);
      return Eigen::Vector3d(ray * (plane.d / plane.n.dot(ray)));
    };
    Eigen::MatrixX3d vertices(4, 3);
    vertices.row(0) = on_plane(-10, -10).transpose();
    vertices.row(1) = on_plane(camera.width + 10, -10).transpose();
    vertices.row(2) = on_plane(camera.width + 10, camera.height + 10).transpose();
    vertices.row(3) = on_plane(-10, camera.height + 10).transpose();
    Eigen::MatrixX3i triangles(2, 3);
    triangles << 0, 1, 2, 0, 2, 3;
    RasterBuffers buffers;
    Rasterize(vertices, triangles, camera, RasterOptions(), &buffers);
    for (int y = 0; y < camera.height; ++y) {
      for (int x = 0; x < camera.width; ++x) {
        const int i = buffers.index(x, y);
        ASSERT_GE(buffers.triangle_id[i], 0) << x << "," << y;
        const double expected = on_plane(x, y).z();
        ASSERT_NEAR(buffers.depth[i], expected, 1e-6 * expected) << x << "," << y;
      }
    }
  }
}

TEST(RasterizerTest, BarycentricsReproduceTheHitPoint) {
  PinholeCamera camera = KinectLikeCamera();
  camera.world_to_camera = PinholeCamera::LookAt(
      Eigen::Vector3d(0.3, 1.2, 2.5), Eigen::Vector3d(0, 0.9, 0), Eigen::Vector3d::UnitY());
  Eigen::MatrixX3d v(3, 3);
  v << -0.6, 0.2, -0.4,  //
      0.5, 0.4, 0.6,     //
      -0.1, 1.8, 0.1;
  RasterBuffers buffers;
  Rasterize(v, OneTriangle(), camera, RasterOptions(), &buffers);
  int hits = 0;
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      const int i = buffers.index(x, y);
      if (buffers.triangle_id[i] < 0) continue;
      ++hits;
      const Eigen::Vector2f b = buffers.barycentric[i];
      ASSERT_GE(b.x(), -1e-6f);
      ASSERT_GE(b.y(), -1e-6f);
      ASSERT_LE(b.x() + b.y(), 1.0f + 1e-6f);
      const Eigen::Vector3d hit = (1.0 - b.x() - b.y()) * v.row(0).transpose() +
                                  b.x() * v.row(1).transpose() + b.y() * v.row(2).transpose();
      double z = 0;
      const Eigen::Vector2d uv = camera.Project(hit, &z);
      ASSERT_NEAR(uv.x(), x, 1e-4);
      ASSERT_NEAR(uv.y(), y, 1e-4);
      ASSERT_NEAR(z, buffers.depth[i], 1e-5);
    }
  }
  EXPECT_GT(hits, 500);
}

TEST(RasterizerTest, NearerTriangleWinsWhateverTheOrder) {
  const PinholeCamera camera = KinectLikeCamera();
  auto quad_at = [&](double z, double shift, Eigen::MatrixX3d* v, int offset) {
    const double u[4] = {20 + shift, 120 + shift, 120 + shift, 20 + shift};
    const double w[4] = {20, 20, 100, 100};
    for (int k = 0; k < 4; ++k) v->row(offset + k) = camera.Unproject(u[k], w[k], z).transpose();
  };
  for (int order = 0; order < 2; ++order) {
    Eigen::MatrixX3d v(8, 3);
    // The near quad (depth 1) is listed first (order 0) or last (order 1); the far quad
    // (depth 2) is shifted right by 30 pixels.
    quad_at(1.0, 0, &v, order == 0 ? 0 : 4);
    quad_at(2.0, 30, &v, order == 0 ? 4 : 0);
    Eigen::MatrixX3i t(4, 3);
    t << 0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7;
    RasterBuffers buffers;
    Rasterize(v, t, camera, RasterOptions(), &buffers);
    const int near_first = order == 0 ? 0 : 2;  // triangles of the nearer quad
    // Overlap region (u in (50, 120)): the nearer quad wins.
    for (int y = 25; y < 95; ++y) {
      for (int x = 55; x < 115; ++x) {
        const int i = buffers.index(x, y);
        ASSERT_TRUE(buffers.triangle_id[i] == near_first ||
                    buffers.triangle_id[i] == near_first + 1);
        ASSERT_NEAR(buffers.depth[i], 1.0, 1e-6);
      }
      // Only the far quad: depth 2.
      for (int x = 125; x < 145; ++x) ASSERT_NEAR(buffers.depth[buffers.index(x, y)], 2.0, 1e-6);
    }
  }
}

// Counts how many of the triangles cover each pixel, rasterising them one at a time.
std::vector<int> CoverageCount(const Eigen::MatrixX3d& v, const Eigen::MatrixX3i& t,
                               const PinholeCamera& camera) {
  std::vector<int> count(camera.width * camera.height, 0);
  for (int f = 0; f < t.rows(); ++f) {
    RasterBuffers buffers;
    Rasterize(v, t.row(f), camera, RasterOptions(), &buffers);
    for (size_t i = 0; i < count.size(); ++i) count[i] += buffers.triangle_id[i] >= 0;
  }
  return count;
}

TEST(RasterizerTest, SharedEdgesOnPixelCentresFollowTheTopLeftRule) {
  // A square with integer corners split along its diagonal: the diagonal and the square's
  // border pass exactly through pixel centres. Top-left rule: columns [2, 30), rows [3, 21).
  const PinholeCamera camera = ScreenCamera(40, 30);
  for (int diagonal = 0; diagonal < 2; ++diagonal) {
    Eigen::MatrixX3d v(4, 3);
    v << 2, 3, 1, 30, 3, 1, 30, 21, 1, 2, 21, 1;
    Eigen::MatrixX3i t(2, 3);
    if (diagonal == 0) {
      t << 0, 1, 2, 0, 2, 3;
    } else {
      t << 0, 1, 3, 1, 2, 3;
    }
    const std::vector<int> count = CoverageCount(v, t, camera);
    for (int y = 0; y < camera.height; ++y) {
      for (int x = 0; x < camera.width; ++x) {
        const bool inside = x >= 2 && x < 30 && y >= 3 && y < 21;
        ASSERT_EQ(count[y * camera.width + x], inside ? 1 : 0) << x << "," << y;
      }
    }
  }
}

TEST(RasterizerTest, JitteredMeshHasNoCracksAndNoDoubleCoverage) {
  // A jittered grid of triangles, some vertices snapped to pixel centres so that many edges
  // pass exactly through samples. Interior pixels must be covered exactly once.
  const PinholeCamera camera = ScreenCamera(64, 48);
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> jitter(-2.4, 2.4);
  std::bernoulli_distribution snap(0.5);
  const int n = 6;  // n x n cells spanning [-4, 68] x [-4, 52]
  Eigen::MatrixX3d v((n + 1) * (n + 1), 3);
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) {
      double x = -4.0 + 72.0 * i / n, y = -4.0 + 56.0 * j / n;
      if (i > 0 && i < n && j > 0 && j < n) {
        x += jitter(rng);
        y += jitter(rng);
        if (snap(rng)) x = std::round(x), y = std::round(y);
      }
      v.row(j * (n + 1) + i) << x, y, 1.0;
    }
  }
  Eigen::MatrixX3i t(2 * n * n, 3);
  int f = 0;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      if ((i + j) % 2) {
        t.row(f++) << a, b, d;
        t.row(f++) << a, d, c;
      } else {
        t.row(f++) << a, b, c;
        t.row(f++) << b, d, c;
      }
    }
  }
  const std::vector<int> count = CoverageCount(v, t, camera);
  for (int i = 0; i < camera.width * camera.height; ++i) {
    ASSERT_EQ(count[i], 1) << "pixel " << i % camera.width << "," << i / camera.width;
  }
  // The same pixels through one call: every pixel hit.
  RasterBuffers buffers;
  Rasterize(v, t, camera, RasterOptions(), &buffers);
  for (int id : buffers.triangle_id) ASSERT_GE(id, 0);
}

// Rasterize against the definition it implements, whatever order it draws in: each triangle
// rasterised alone, then per pixel the smallest depth and, among equal depths, the smallest
// triangle index (depth, id and barycentrics bit for bit). The mesh: two interpenetrating
// octahedra seen from several directions (front and back faces, occlusion in both index
// orders), plus exact ties: every third triangle again with the same corners in the same order
// (the same depths bit for bit; the first copy must win), every fifth reversed (facing the
// other way), and a sheet's triangles each followed by its reversed copy.
TEST(RasterizerTest, EqualDepthsGoToTheSmallerIndexWhateverTheFacing) {
  Eigen::MatrixX3d octahedron(6, 3);
  octahedron << 0.5, 0, 0, -0.5, 0, 0, 0, 0.5, 0, 0, -0.5, 0, 0, 0, 0.5, 0, 0, -0.5;
  Eigen::MatrixX3i faces(8, 3);
  faces << 0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5;
  Eigen::MatrixX3d v(16, 3);
  v.topRows(6) = octahedron.rowwise() + Eigen::RowVector3d(0.0, 0.0, 2.0);
  v.middleRows(6, 6) = (octahedron * 0.8).rowwise() + Eigen::RowVector3d(0.25, 0.1, 2.1);
  // A square sheet beside them, seen from either side.
  v.bottomRows(4) << -0.9, -0.4, 1.9, -0.5, -0.4, 1.9, -0.5, 0.4, 1.9, -0.9, 0.4, 1.9;
  std::vector<Eigen::RowVector3i> list;
  for (int f = 0; f < 16; ++f) {
    const Eigen::RowVector3i tri = faces.row(f % 8).array() + (f < 8 ? 0 : 6);
    list.push_back(tri);
    if (f % 3 == 0) list.push_back(tri);
    if (f % 5 == 0) list.emplace_back(tri[0], tri[2], tri[1]);
  }
  // The sheet's triangles each followed by its reversed copy: from one side the smaller index
  // faces away and must still win the tie.
  for (const Eigen::RowVector3i& tri :
       {Eigen::RowVector3i(12, 13, 14), Eigen::RowVector3i(12, 14, 15)}) {
    list.push_back(tri);
    list.emplace_back(tri[0], tri[2], tri[1]);
  }
  Eigen::MatrixX3i t(static_cast<int>(list.size()), 3);
  for (int f = 0; f < t.rows(); ++f) t.row(f) = list[f];
  const PinholeCamera base = KinectLikeCamera();
  int ties = 0, covered = 0;
  for (const double yaw : {0.0, 0.7, 2.0, 3.1}) {
    PinholeCamera camera = base;
    const Eigen::Vector3d centre(0.1, 0.05, 2.05);
    const Eigen::Vector3d eye =
        centre + 1.9 * Eigen::Vector3d(std::sin(yaw), 0.3, -std::cos(yaw)).normalized();
    camera.world_to_camera = PinholeCamera::LookAt(eye, centre, Eigen::Vector3d::UnitY());
    RasterBuffers all;
    Rasterize(v, t, camera, RasterOptions(), &all);
    const std::size_t n = all.depth.size();
    std::vector<float> depth(n, std::numeric_limits<float>::infinity());
    std::vector<int32_t> id(n, -1);
    std::vector<Eigen::Vector2f> bary(n, Eigen::Vector2f::Zero());
    std::vector<int> hits(n, 0);
    for (int f = 0; f < t.rows(); ++f) {
      RasterBuffers one;
      Rasterize(v, t.row(f), camera, RasterOptions(), &one);
      for (std::size_t i = 0; i < n; ++i) {
        if (one.triangle_id[i] < 0) continue;
        if (one.depth[i] == depth[i]) ++hits[i];
        if (one.depth[i] < depth[i]) {  // f ascending: an equal depth keeps the smaller index
          depth[i] = one.depth[i];
          id[i] = f;
          bary[i] = one.barycentric[i];
          hits[i] = 1;
        }
      }
    }
    for (std::size_t i = 0; i < n; ++i) {
      ASSERT_EQ(all.depth[i], depth[i]) << "pixel " << i << ", yaw " << yaw;
      ASSERT_EQ(all.triangle_id[i], id[i]) << "pixel " << i << ", yaw " << yaw;
      ASSERT_EQ(all.barycentric[i], bary[i]) << "pixel " << i << ", yaw " << yaw;
      covered += id[i] >= 0;
      ties += hits[i] > 1;
    }
  }
  EXPECT_GT(covered, 1000);
  EXPECT_GT(ties, 100);  // the duplicated triangles tie where they are in front
}

TEST(RasterizerTest, BackfaceCullingKeepsTheFrontOfAClosedMesh) {
  // Octahedron, counter-clockwise from outside, 2 m in front of the camera.
  Eigen::MatrixX3d v(6, 3);
  v << 0.5, 0, 2, -0.5, 0, 2, 0, 0.5, 2, 0, -0.5, 2, 0, 0, 2.5, 0, 0, 1.5;
  Eigen::MatrixX3i t(8, 3);
  t << 0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5;
  const PinholeCamera camera = KinectLikeCamera();
  RasterBuffers all, culled;
  Rasterize(v, t, camera, RasterOptions(), &all);
  RasterOptions cull;
  cull.cull_backfaces = true;
  Rasterize(v, t, camera, cull, &culled);
  int hits = 0;
  for (size_t i = 0; i < all.depth.size(); ++i) {
    ASSERT_EQ(all.triangle_id[i], culled.triangle_id[i]);
    ASSERT_EQ(all.depth[i], culled.depth[i]);
    if (all.triangle_id[i] >= 0) {
      ++hits;
      ASSERT_GE(all.triangle_id[i], 4);  // the faces around vertex 5 (z = 1.5) face the camera
    }
  }
  EXPECT_GT(hits, 100);
  // The back faces alone are all culled.
  Rasterize(v, t.topRows(4), camera, cull, &culled);
  for (int id : culled.triangle_id) ASSERT_EQ(id, -1);
}

TEST(RasterizerTest, TrianglesCrossingTheNearPlaneAreRejected) {
  const PinholeCamera camera = KinectLikeCamera();
  Eigen::MatrixX3d v(3, 3);
  v << -0.5, -0.5, 1.0, 0.5, -0.5, 1.0, 0.0, 0.5, 0.01;
  RasterBuffers buffers;
  Rasterize(v, OneTriangle(), camera, RasterOptions(), &buffers);
  for (int id : buffers.triangle_id) ASSERT_EQ(id, -1);
  v(2, 2) = 1.0;
  Rasterize(v, OneTriangle(), camera, RasterOptions(), &buffers);
  int hits = 0;
  for (int id : buffers.triangle_id) hits += id == 0;
  EXPECT_GT(hits, 0);
}

TEST(RasterizerTest, LookAtCameraShowsWorldUpAsImageUp) {
  // A camera in front of the body (+z) looking at it: world +y appears upwards in the image
  // and world +x (the body's left) to the right; projection and unprojection agree.
  PinholeCamera camera = KinectLikeCamera();
  camera.world_to_camera = PinholeCamera::LookAt(Eigen::Vector3d(0, 1, 3), Eigen::Vector3d(0, 1, 0),
                                                 Eigen::Vector3d::UnitY());
  const Eigen::Vector2d centre = camera.Project(Eigen::Vector3d(0, 1, 0));
  const Eigen::Vector2d above = camera.Project(Eigen::Vector3d(0, 1.5, 0));
  const Eigen::Vector2d right = camera.Project(Eigen::Vector3d(0.5, 1, 0));
  EXPECT_NEAR(centre.x(), camera.cx, 1e-9);
  EXPECT_NEAR(centre.y(), camera.cy, 1e-9);
  EXPECT_LT(above.y(), centre.y() - 10);
  EXPECT_GT(right.x(), centre.x() + 10);
  EXPECT_NEAR(camera.world_to_camera.linear().determinant(), 1.0, 1e-12);
  const Eigen::Vector3d back = camera.Unproject(right.x(), right.y(), 3.0);
  EXPECT_NEAR((back - Eigen::Vector3d(0.5, 1, 0)).norm(), 0, 1e-9);
}

TEST(RasterizerTest, BadIndicesThrow) {
  Eigen::MatrixX3d v(3, 3);
  v.setOnes();
  Eigen::MatrixX3i t(1, 3);
  t << 0, 1, 3;
  RasterBuffers buffers;
  EXPECT_THROW(Rasterize(v, t, KinectLikeCamera(), RasterOptions(), &buffers), Error);
}

}  // namespace
}  // namespace artex
