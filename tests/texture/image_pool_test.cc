// The image pool against straightforward recomputations: the colours stored per entry equal
// pointwise PoolEntry::SampleSurface calls, the visibility z-buffer equals the rasteriser's
// full-image depth, the one-pass pruning test equals the per-slot definition, and pruning keeps
// the pool bounded. Scene: two spheres, the smaller partly in front of the larger (occlusion
// borders and silhouettes), seen by orbiting cameras in a random-coloured image.
#include "texture/image_pool.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "models/error.h"
#include "render/rasterizer.h"
#include "tests/texture/sphere_mesh.h"
#include "texture/view_selection.h"
#include "texture/visibility.h"

namespace artex {
namespace {

// Appends a closed UV sphere (its atlas is not used here).
void AddSphere(int rings, int segments, double r, const Eigen::Vector3d& c,
               std::vector<Eigen::Vector3d>* vertices, std::vector<Eigen::Vector3i>* triangles) {
  std::vector<Eigen::Vector2d> uvs;
  std::vector<Eigen::Vector3i> uv_triangles;
  testing::AddUvSphere(rings, segments, r, c, 0.0, 1.0, 0.0, 1.0, vertices, triangles, &uvs,
                       &uv_triangles);
}

struct Scene {
  Eigen::MatrixX3d vertices;
  Eigen::MatrixX3i triangles;
  TextureMesh mesh;
  cv::Mat image;

  Scene() {
    std::vector<Eigen::Vector3d> v;
    std::vector<Eigen::Vector3i> t;
    AddSphere(16, 32, 0.3, Eigen::Vector3d(0, 1, 0), &v, &t);
    AddSphere(10, 20, 0.12, Eigen::Vector3d(0.12, 1.05, 0.35), &v, &t);
    vertices.resize(static_cast<int>(v.size()), 3);
    for (std::size_t k = 0; k < v.size(); ++k) vertices.row(k) = v[k].transpose();
    triangles.resize(static_cast<int>(t.size()), 3);
    for (std::size_t k = 0; k < t.size(); ++k) triangles.row(k) = t[k].transpose();
    mesh = TextureMesh::Build(triangles);
    image = cv::Mat(kSize, kSize, CV_8UC3);
    cv::RNG rng(5);
    rng.fill(image, cv::RNG::UNIFORM, 0, 256);
  }
  static constexpr int kSize = 160;
};

PinholeCamera OrbitCamera(double angle) {
  PinholeCamera cam;
  cam.width = cam.height = Scene::kSize;
  cam.fx = cam.fy = Scene::kSize * 1.3;
  cam.cx = cam.cy = (Scene::kSize - 1) / 2.0;
  const Eigen::Vector3d target(0, 1, 0);
  const Eigen::Vector3d eye = target + 1.3 * Eigen::Vector3d(std::sin(angle), 0.3, std::cos(angle));
  cam.world_to_camera = PinholeCamera::LookAt(eye, target, Eigen::Vector3d::UnitY());
  return cam;
}

// Equal colours, NaN exactly where the reference is NaN.
void ExpectSameColor(const Eigen::Vector3f& expected, bool sampled, const float* actual,
                     const std::string& where) {
  for (int c = 0; c < 3; ++c) {
    if (!sampled) {
      EXPECT_TRUE(std::isnan(actual[c])) << where;
    } else {
      EXPECT_NEAR(actual[c], expected[c], 1e-6) << where;
    }
  }
}

class ImagePoolTest : public ::testing::TestWithParam<bool> {};

// Vertex and edge colours as ImagePoolOptions and PoolEntry document them, one SampleSurface
// call per point; with and without surface-aware sampling.
TEST_P(ImagePoolTest, ColorsEqualPointwiseSampling) {
  const Scene scene;
  ImagePoolOptions options;
  options.surface_aware_sampling = GetParam();
  options.vertex_colors_need_full_ring = GetParam();
  ImagePool pool(&scene.mesh, options, VisibilityOptions());
  const PinholeCamera camera = OrbitCamera(0.4);
  const PoolEntry& e = pool.entry(pool.Add(3, scene.image, camera, scene.vertices));
  EXPECT_EQ(e.surface.depth.empty(), !GetParam());
  const TriangleVisibility& vis = e.visibility;
  const int v_count = static_cast<int>(scene.vertices.rows());
  const auto camera_point = [&](int v) -> Eigen::Vector3d {
    return camera.world_to_camera * scene.vertices.row(v).transpose();
  };

  // Vertices: the lowest quality of the visible triangles around; none when a triangle around
  // is hidden (full ring) or none is visible.
  std::vector<float> quality(v_count, 2.0f);
  std::vector<bool> hidden_ring(v_count, false);
  for (int f = 0; f < scene.triangles.rows(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const int v = scene.triangles(f, c);
      if (vis.visible[f])
        quality[v] = std::min(quality[v], vis.quality[f]);
      else
        hidden_ring[v] = true;
    }
  }
  int vertex_colors = 0;
  for (int v = 0; v < v_count; ++v) {
    Eigen::Vector3f expected;
    const bool seen =
        quality[v] <= 1.0f && !(options.vertex_colors_need_full_ring && hidden_ring[v]);
    const bool sampled = seen && e.SampleSurface(camera_point(v), quality[v], false, &expected);
    vertex_colors += sampled;
    ExpectSameColor(expected, sampled, e.vertex_colors.row(v).data(),
                    "vertex " + std::to_string(v));
    ASSERT_EQ(e.vertex_coloured.at(v), sampled ? 1 : 0) << "vertex " << v;
  }
  EXPECT_EQ(static_cast<int>(e.vertex_coloured.size()), v_count);
  EXPECT_GT(vertex_colors, v_count / 10);
  EXPECT_LT(vertex_colors, v_count);  // some vertices without a colour: both flags occur

  // Edges: edge_samples points (k + 0.5) / samples along the edge, at the lower quality of its
  // visible sides; none when neither side is visible.
  const int samples = options.edge_samples;
  int edge_colors = 0, mixed = 0;
  for (int k = 0; k < scene.mesh.edges.rows(); ++k) {
    const int f0 = scene.mesh.edge_faces(k, 0), f1 = scene.mesh.edge_faces(k, 1);
    const bool seen = vis.visible[f0] || vis.visible[f1];
    const float q = std::min(vis.visible[f0] ? vis.quality[f0] : 1.0f,
                             vis.visible[f1] ? vis.quality[f1] : 1.0f);
    const Eigen::Vector3d a = camera_point(scene.mesh.edges(k, 0));
    const Eigen::Vector3d b = camera_point(scene.mesh.edges(k, 1));
    for (int s = 0; s < samples; ++s) {
      const double t = (s + 0.5) / samples;
      Eigen::Vector3f expected;
      const bool sampled = seen && e.SampleSurface((1 - t) * a + t * b, q, false, &expected);
      edge_colors += sampled;
      // Samples whose bilinear footprint straddles a depth discontinuity.
      Eigen::Vector3f plain;
      if (sampled &&
          e.Sample(camera.Project(e.camera.world_to_camera.inverse() * ((1 - t) * a + t * b)),
                   &plain))
        mixed += (plain - expected).cwiseAbs().maxCoeff() > 1e-4f;
      // Stored in 16-bit fixed point: within half a step of the sample.
      const Eigen::Vector3f stored = EdgeColor(e.edge_colors, k * samples + s);
      const std::string where = "edge " + std::to_string(k) + " sample " + std::to_string(s);
      for (int c = 0; c < 3; ++c) {
        if (!sampled) {
          EXPECT_TRUE(std::isnan(stored[c])) << where;
        } else {
          EXPECT_NEAR(stored[c], expected[c], 0.5f / kEdgeColorScale + 1e-6f) << where;
        }
      }
    }
  }
  EXPECT_GT(edge_colors, scene.mesh.edges.rows());
  // Surface-aware sampling leaves out the taps off the surface near occlusion borders.
  if (GetParam()) {
    EXPECT_GT(mixed, 0);
  } else {
    EXPECT_EQ(mixed, 0);
  }
}

INSTANTIATE_TEST_SUITE_P(SurfaceAware, ImagePoolTest, ::testing::Bool());

// The kept z-buffer is the rasteriser's full-image depth (bit for bit) wherever it is defined,
// and nothing is hit outside it; RasterizeDepth equals Rasterize's depth.
TEST(ImagePoolTest, SurfaceDepthIsTheFullImageZBuffer) {
  const Scene scene;
  const PinholeCamera camera = OrbitCamera(-0.7);
  RasterBuffers full;
  Rasterize(scene.vertices, scene.triangles, camera, RasterOptions(), &full);
  std::vector<float> depth_only;
  RasterizeDepth(scene.vertices, scene.triangles, camera, RasterOptions(), &depth_only);
  ASSERT_EQ(depth_only.size(), full.depth.size());
  for (std::size_t i = 0; i < full.depth.size(); ++i)
    ASSERT_EQ(depth_only[i], full.depth[i]) << "pixel " << i;

  SurfaceDepth surface;
  ComputeVisibility(scene.vertices, scene.triangles, camera, VisibilityOptions(), &surface);
  ASSERT_GT(surface.width, 0);
  ASSERT_LT(surface.width * surface.height, camera.width * camera.height);
  int hits = 0;
  for (int v = 0; v < camera.height; ++v) {
    for (int u = 0; u < camera.width; ++u) {
      const float expected = full.depth[full.index(u, v)];
      const float actual = surface.At(u, v);
      hits += std::isfinite(expected);
      if (std::isinf(expected)) {
        EXPECT_TRUE(std::isinf(actual)) << u << ", " << v;
      } else {
        EXPECT_EQ(actual, expected) << u << ", " << v;
      }
    }
  }
  EXPECT_GT(hits, camera.width * camera.height / 20);
}

// Pool of views around the scene: the one-pass pruning test agrees with the per-slot
// definition, and pruning keeps the pool within its bounds.
TEST(ImagePoolTest, PruningFollowsTheHistogramRuleAndStaysBounded) {
  const Scene scene;
  ImagePoolOptions options;
  options.max_images = 4;
  options.hard_max_images = 7;
  options.histogram_bins = 3;
  ImagePool pool(&scene.mesh, options, VisibilityOptions());
  int kept_above_max = 0;
  for (int frame = 0; frame < 16; ++frame) {
    pool.Add(frame, scene.image, OrbitCamera(0.9 * frame), scene.vertices);
    const std::vector<uint8_t> keep = pool.UniquelyBestSlots();
    ASSERT_EQ(static_cast<int>(keep.size()), pool.size());
    for (int s = 0; s < pool.size(); ++s)
      EXPECT_EQ(keep[s] != 0, pool.IsUniquelyBest(s)) << "frame " << frame << " slot " << s;
    const std::vector<int> dropped = pool.Prune();
    for (int d : dropped) EXPECT_EQ(pool.SlotOfFrame(d), -1);
    EXPECT_LE(pool.size(), options.hard_max_images);
    if (pool.size() > options.max_images) {
      ++kept_above_max;
      // Above max_images the rule keeps only images uniquely best somewhere (unless the hard
      // cap dropped the oldest).
      if (pool.size() < options.hard_max_images) {
        for (int s = 0; s < pool.size(); ++s) EXPECT_TRUE(pool.IsUniquelyBest(s));
      }
    }
  }
  EXPECT_GT(kept_above_max, 0);
}

// Every triangle once; each one after the first of its component shares an edge with an earlier
// one, and the second sphere's triangles (another component) all come after the first's.
TEST(ImagePoolTest, TriangleOrderIsBreadthFirstOverSharedEdges) {
  const Scene scene;
  const TextureMesh& mesh = scene.mesh;
  const int f_count = static_cast<int>(scene.triangles.rows());
  ASSERT_EQ(static_cast<int>(mesh.triangle_order.size()), f_count);
  std::vector<int> position(f_count, -1);
  for (int k = 0; k < f_count; ++k) {
    const int f = mesh.triangle_order[k];
    ASSERT_GE(f, 0);
    ASSERT_LT(f, f_count);
    ASSERT_EQ(position[f], -1) << "triangle " << f << " twice";
    position[f] = k;
  }
  std::vector<int> earliest_neighbour(f_count, f_count);
  for (int e = 0; e < mesh.edges.rows(); ++e) {
    const int a = mesh.edge_faces(e, 0), b = mesh.edge_faces(e, 1);
    earliest_neighbour[a] = std::min(earliest_neighbour[a], position[b]);
    earliest_neighbour[b] = std::min(earliest_neighbour[b], position[a]);
  }
  const int first_sphere = 2 * 32 * (16 - 1);  // triangles of the 16 x 32 sphere
  int roots = 0;
  for (int f = 0; f < f_count; ++f) {
    if (earliest_neighbour[f] > position[f]) ++roots;
    if (f < first_sphere) {
      EXPECT_LT(position[f], first_sphere);
    }
  }
  EXPECT_EQ(roots, 2);  // one per sphere
  EXPECT_EQ(mesh.triangle_order[0], 0);
  EXPECT_EQ(mesh.triangle_order[first_sphere], first_sphere);
}

// View selection orders the MRF's edges by their lower node: already so for the edges of
// TextureMesh::Build (the shortcut), sorted otherwise. The same pool with the edges reversed
// gives the same problem up to the order of its edges.
TEST(ImagePoolTest, ViewSelectionDoesNotDependOnTheEdgeOrder) {
  const Scene scene;
  TextureMesh reversed = scene.mesh;
  reversed.edges = scene.mesh.edges.colwise().reverse();
  reversed.edge_faces = scene.mesh.edge_faces.colwise().reverse();
  ImagePool pool(&scene.mesh, ImagePoolOptions(), VisibilityOptions());
  ImagePool reversed_pool(&reversed, ImagePoolOptions(), VisibilityOptions());
  for (int frame = 0; frame < 5; ++frame) {
    pool.Add(frame, scene.image, OrbitCamera(0.7 * frame), scene.vertices);
    reversed_pool.Add(frame, scene.image, OrbitCamera(0.7 * frame), scene.vertices);
  }
  MrfSolverOptions solver_options;
  solver_options.type = MrfSolverType::kIcm;  // visits nodes in order: edge order is irrelevant
  const std::unique_ptr<MrfSolver> solver = MrfSolver::Create(solver_options);
  ViewSelectionInput input;
  input.current_frame = 5;
  input.mesh = &scene.mesh;
  input.pool = &pool;
  const ViewSelectionResult forward = SelectViews(input, ViewSelectionOptions(), solver.get());
  input.mesh = &reversed;
  input.pool = &reversed_pool;
  const ViewSelectionResult backward = SelectViews(input, ViewSelectionOptions(), solver.get());
  EXPECT_EQ(forward.frames, backward.frames);
  EXPECT_NEAR(forward.mrf.energy, backward.mrf.energy, 1e-9 * std::abs(forward.mrf.energy));
  EXPECT_EQ(forward.num_candidates, backward.num_candidates);
  int textured = 0;
  for (int f : forward.frames) textured += f >= 0;
  EXPECT_GT(textured, 100);
}

// EdgeColorValue is std::lround(clamp(c, 0, 1) * kEdgeColorScale) cast to 16 bits: at and next
// to every integer and halfway value of the scale, and at a million random channels.
TEST(ImagePoolTest, EdgeColorValueRoundsAsLround) {
  const auto reference = [](float c) {
    return static_cast<std::uint16_t>(std::lround(std::clamp(c, 0.0f, 1.0f) * kEdgeColorScale));
  };
  int checked = 0;
  for (int t = 0; t <= static_cast<int>(kEdgeColorScale); ++t) {
    for (const float x : {static_cast<float>(t), t + 0.5f}) {
      for (const float y : {std::nextafter(x, -1.0f), x, std::nextafter(x, 1e9f)}) {
        // The channel whose scaled value is y, and its neighbours.
        const float c = y / kEdgeColorScale;
        for (const float z : {std::nextafter(c, -1.0f), c, std::nextafter(c, 2.0f)}) {
          ASSERT_EQ(EdgeColorValue(z), reference(z)) << "channel " << z;
          ++checked;
        }
      }
    }
  }
  cv::RNG rng(3);
  for (int k = 0; k < 1000000; ++k) {
    const float c = rng.uniform(-0.1f, 1.1f);
    ASSERT_EQ(EdgeColorValue(c), reference(c)) << "channel " << c;
  }
  EXPECT_EQ(EdgeColorValue(std::numeric_limits<float>::quiet_NaN()),
            reference(std::numeric_limits<float>::quiet_NaN()));
  EXPECT_GT(checked, 1000000);
}

TEST(ImagePoolTest, BadOptionsAreRejected) {
  const Scene scene;
  ImagePoolOptions options;
  options.histogram_bins = 256;
  std::string why;
  EXPECT_FALSE(options.IsValid(&why));
  EXPECT_NE(why.find("pool.histogram_bins"), std::string::npos);
  EXPECT_THROW(ImagePool(&scene.mesh, options, VisibilityOptions()), Error);
}

}  // namespace
}  // namespace artex
