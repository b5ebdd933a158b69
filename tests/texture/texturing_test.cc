// End-to-end texturing on a synthetic textured sphere seen by an orbiting colour camera with
// per-frame exposure changes: the texture built on the fly is compared against ground truth.
// Also: surface-aware sampling at a silhouette, the reduced-resolution z-buffer, the seam
// leveller against a dense least-squares solve, and the switch cost.
#include <gtest/gtest.h>

#include <Eigen/SparseCholesky>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <vector>

#include "energies/texture_terms.h"
#include "models/error.h"
#include "models/template.h"
#include "solvers/seam_levelling.h"
#include "texture/texturer.h"
#include "texture/visibility.h"

namespace artex {
namespace {

// A UV sphere (radius r, centred at c) with a latitude-longitude atlas; the UV seam at
// longitude 0 and the poles use split UV corners, the mesh itself stays closed.
Template UvSphere(int rings, int segments, double r, const Eigen::Vector3d& c) {
  Template t;
  const int v_count = 2 + (rings - 1) * segments;
  t.vertices.resize(v_count, 3);
  t.vertices.row(0) = (c + Eigen::Vector3d(0, r, 0)).transpose();
  t.vertices.row(1) = (c - Eigen::Vector3d(0, r, 0)).transpose();
  const auto ring_vertex = [&](int i, int j) { return 2 + (i - 1) * segments + (j % segments); };
  for (int i = 1; i < rings; ++i) {
    const double phi = M_PI * i / rings;
    for (int j = 0; j < segments; ++j) {
      const double theta = 2.0 * M_PI * j / segments;
      t.vertices.row(ring_vertex(i, j)) =
          (c + r * Eigen::Vector3d(std::sin(phi) * std::sin(theta), std::cos(phi),
                                   std::sin(phi) * std::cos(theta)))
              .transpose();
    }
  }
  std::vector<Eigen::Vector3i> tris, uvtris;
  std::vector<Eigen::Vector2d> uvs;
  const auto uv = [&](int i, int j) {
    uvs.emplace_back(0.02 + 0.96 * j / segments, 0.02 + 0.96 * i / rings);
    return static_cast<int>(uvs.size()) - 1;
  };
  for (int j = 0; j < segments; ++j) {
    // Top cap (counter-clockwise seen from outside).
    tris.emplace_back(0, ring_vertex(1, j), ring_vertex(1, j + 1));
    uvtris.emplace_back(uv(0, j), uv(1, j), uv(1, j + 1));
    for (int i = 1; i < rings - 1; ++i) {
      const int a = ring_vertex(i, j), b = ring_vertex(i, j + 1);
      const int cc = ring_vertex(i + 1, j), d = ring_vertex(i + 1, j + 1);
      tris.emplace_back(a, cc, d);
      uvtris.emplace_back(uv(i, j), uv(i + 1, j), uv(i + 1, j + 1));
      tris.emplace_back(a, d, b);
      uvtris.emplace_back(uv(i, j), uv(i + 1, j + 1), uv(i, j + 1));
    }
    tris.emplace_back(1, ring_vertex(rings - 1, j + 1), ring_vertex(rings - 1, j));
    uvtris.emplace_back(uv(rings, j), uv(rings - 1, j + 1), uv(rings - 1, j));
  }
  t.triangles.resize(static_cast<int>(tris.size()), 3);
  t.uv_triangles.resize(static_cast<int>(tris.size()), 3);
  for (std::size_t f = 0; f < tris.size(); ++f) {
    t.triangles.row(f) = tris[f].transpose();
    t.uv_triangles.row(f) = uvtris[f].transpose();
  }
  t.uvs.resize(static_cast<int>(uvs.size()), 2);
  for (std::size_t k = 0; k < uvs.size(); ++k) t.uvs.row(k) = uvs[k].transpose();
  t.joints.resize(1);
  t.vertex_joint = Eigen::VectorXi::Zero(v_count);
  t.lbs_weight = Eigen::VectorXd::Ones(v_count);
  t.slerp_tau = Eigen::VectorXd::Ones(v_count);
  return t;
}

// A detailed true texture: coloured checks with thin stripes.
cv::Mat TrueAtlas(int size) {
  cv::Mat atlas(size, size, CV_8UC3);
  for (int y = 0; y < size; ++y) {
    for (int x = 0; x < size; ++x) {
      const int check = ((x / 16) + (y / 16)) % 2;
      const bool stripe = (x % 8) < 2;
      cv::Vec3b c = check ? cv::Vec3b(40, 120, 200) : cv::Vec3b(200, 180, 60);
      if (stripe) c = cv::Vec3b(250, 250, 250);
      atlas.at<cv::Vec3b>(y, x) = c;
    }
  }
  cv::GaussianBlur(atlas, atlas, cv::Size(3, 3), 0.7);
  return atlas;
}

PinholeCamera OrbitCamera(double angle, int size) {
  PinholeCamera cam;
  cam.width = cam.height = size;
  cam.fx = cam.fy = size * 1.3;
  cam.cx = cam.cy = (size - 1) / 2.0;
  const Eigen::Vector3d target(0, 1, 0);
  const Eigen::Vector3d eye = target + 1.2 * Eigen::Vector3d(std::sin(angle), 0.3, std::cos(angle));
  cam.world_to_camera = PinholeCamera::LookAt(eye, target, Eigen::Vector3d::UnitY());
  return cam;
}

double Psnr(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask) {
  double se = 0.0;
  long n = 0;
  for (int y = 0; y < a.rows; ++y)
    for (int x = 0; x < a.cols; ++x) {
      if (!mask.at<uint8_t>(y, x)) continue;
      for (int c = 0; c < 3; ++c) {
        const double d = a.at<cv::Vec3b>(y, x)[c] - b.at<cv::Vec3b>(y, x)[c];
        se += d * d;
      }
      n += 3;
    }
  return 10.0 * std::log10(255.0 * 255.0 / std::max(se / std::max(n, 1L), 1e-12));
}

struct Run {
  Texturer texturer;
  TextureFrameSummary last;
};

struct Scene {
  Template sphere = UvSphere(24, 48, 0.3, Eigen::Vector3d(0, 1, 0));
  cv::Mat truth = TrueAtlas(256);
  int image_size = 160;

  cv::Mat Image(int frame, double angle, double gain) const {
    cv::Mat image, mask;
    RenderTextured(sphere, sphere.vertices, truth, OrbitCamera(angle, image_size), &image, &mask);
    image.convertTo(image, CV_8UC3, gain);
    return image;
  }
};

TexturingOptions SmallOptions() {
  TexturingOptions o;
  o.atlas_size = 256;
  o.pool.max_images = 6;
  o.pool.hard_max_images = 10;
  return o;
}

// Feeds `frames` views orbiting the sphere; exposure alternates by `gain_swing`.
std::unique_ptr<Texturer> Feed(const Scene& scene, const TexturingOptions& options, int frames,
                               double gain_swing, TextureFrameSummary* last) {
  auto texturer = std::make_unique<Texturer>(scene.sphere, options);
  for (int f = 0; f < frames; ++f) {
    const double angle = 2.0 * M_PI * f / frames;
    const double gain = 1.0 + gain_swing * ((f % 2) ? 1.0 : -1.0);
    *last = texturer->AddFrame(f, scene.Image(f, angle, gain), OrbitCamera(angle, scene.image_size),
                               scene.sphere.vertices);
  }
  // The seams of the last labelling, levelled on this read (levelling_every_frame false).
  last->seam_rms_before = texturer->seam_rms_before();
  last->seam_rms_after = texturer->seam_rms_after();
  return texturer;
}

TEST(TexturingTest, HeldOutViewReachesHighPsnr) {
  Scene scene;
  TextureFrameSummary last;
  auto texturer = Feed(scene, SmallOptions(), 8, 0.0, &last);
  // The bottom cap is never seen from the cameras above the equator.
  EXPECT_GT(last.textured_triangles, 0.75 * scene.sphere.num_triangles());
  const cv::Mat atlas = texturer->Atlas();
  // Held-out viewpoint between two input views, slightly above.
  PinholeCamera held_out = OrbitCamera(2.0 * M_PI * 2.5 / 8.0, scene.image_size);
  cv::Mat truth_image, truth_mask, image, mask;
  RenderTextured(scene.sphere, scene.sphere.vertices, scene.truth, held_out, &truth_image,
                 &truth_mask);
  RenderTextured(scene.sphere, scene.sphere.vertices, atlas, held_out, &image, &mask);
  const double psnr = Psnr(image, truth_image, truth_mask);
  EXPECT_GE(psnr, 28.0) << "PSNR " << psnr;
  std::printf("held-out PSNR %.2f dB\n", psnr);
}

TEST(TexturingTest, SmoothnessTermReducesSeams) {
  Scene scene;
  TexturingOptions smooth = SmallOptions();
  TexturingOptions none = SmallOptions();
  none.selection.terms.lambda = 0.0;
  TextureFrameSummary with_lambda, without_lambda;
  Feed(scene, smooth, 8, 0.15, &with_lambda);
  Feed(scene, none, 8, 0.15, &without_lambda);
  EXPECT_GT(without_lambda.seam_edges, with_lambda.seam_edges)
      << "lambda=0: " << without_lambda.seam_edges << " default: " << with_lambda.seam_edges;
  // Colour jump at seams before levelling: worse without the smoothness term.
  EXPECT_GT(without_lambda.seam_rms_before * without_lambda.seam_edges,
            with_lambda.seam_rms_before * with_lambda.seam_edges);
}

TEST(TexturingTest, SeamLevellingLowersColourJumps) {
  Scene scene;
  TextureFrameSummary last;
  Feed(scene, SmallOptions(), 8, 0.2, &last);
  ASSERT_GT(last.seam_edges, 0);
  EXPECT_LT(last.seam_rms_after, 0.5 * last.seam_rms_before)
      << last.seam_rms_before << " -> " << last.seam_rms_after;
}

// Levelling when the texture is read (the default) and in every AddFrame give the same atlas,
// vertex colours and seam residuals bit for bit, also when the texture is read between frames;
// without a read the frame summaries carry no residuals.
TEST(TexturingTest, LevellingOnReadMatchesLevellingEveryFrame) {
  Scene scene;
  TexturingOptions every = SmallOptions();
  every.levelling_every_frame = true;
  TexturingOptions on_read = SmallOptions();
  ASSERT_FALSE(on_read.levelling_every_frame);
  Texturer a(scene.sphere, every), b(scene.sphere, on_read);
  const int frames = 8;
  for (int f = 0; f < frames; ++f) {
    const double angle = 2.0 * M_PI * f / frames;
    const double gain = 1.0 + 0.2 * ((f % 2) ? 1.0 : -1.0);
    const cv::Mat image = scene.Image(f, angle, gain);
    const TextureFrameSummary sa =
        a.AddFrame(f, image, OrbitCamera(angle, scene.image_size), scene.sphere.vertices);
    const TextureFrameSummary sb =
        b.AddFrame(f, image, OrbitCamera(angle, scene.image_size), scene.sphere.vertices);
    EXPECT_EQ(sa.changed_triangles, sb.changed_triangles) << "frame " << f;
    EXPECT_FALSE(b.seams_levelled()) << "frame " << f;
    EXPECT_TRUE(std::isnan(sb.seam_rms_after)) << "frame " << f;
    if (f == 3) {  // a read between frames levels that frame's labelling
      const cv::Mat atlas_a = a.Atlas(), atlas_b = b.Atlas();
      EXPECT_TRUE(b.seams_levelled());
      EXPECT_GT(b.levelling_seconds_since_add(), 0.0);
      ASSERT_EQ(atlas_a.size(), atlas_b.size());
      EXPECT_EQ(cv::norm(atlas_a, atlas_b, cv::NORM_INF), 0.0) << "frame " << f;
      EXPECT_EQ(sa.seam_rms_after, b.seam_rms_after()) << "frame " << f;
      EXPECT_EQ(sa.seam_rms_before, b.seam_rms_before()) << "frame " << f;
    }
  }
  ASSERT_GT(b.seam_rms_before(), b.seam_rms_after());
  const cv::Mat atlas_a = a.Atlas(), atlas_b = b.Atlas();
  EXPECT_EQ(cv::norm(atlas_a, atlas_b, cv::NORM_INF), 0.0);
  Eigen::MatrixX3d rgb_a, rgb_b;
  std::vector<uint8_t> valid_a, valid_b;
  a.VertexColors(&rgb_a, &valid_a);
  b.VertexColors(&rgb_b, &valid_b);
  EXPECT_EQ(valid_a, valid_b);
  EXPECT_TRUE(rgb_a == rgb_b);
  int valid_count = 0;
  for (uint8_t v : valid_b) valid_count += v;
  EXPECT_EQ(b.ColouredVertexCount(), valid_count);
}

TEST(TexturingTest, PoolStaysBoundedOverLongSequences) {
  Scene scene;
  scene.image_size = 64;
  TexturingOptions o = SmallOptions();
  o.atlas_size = 64;
  o.pool.max_images = 5;
  o.pool.hard_max_images = 8;
  Texturer texturer(scene.sphere, o);
  std::size_t max_bytes = 0;
  for (int f = 0; f < 300; ++f) {
    const double angle = 0.05 * f;
    const auto s = texturer.AddFrame(f, scene.Image(f, angle, 1.0), OrbitCamera(angle, 64),
                                     scene.sphere.vertices);
    ASSERT_LE(s.pool_size, o.pool.hard_max_images) << "frame " << f;
    if (f >= 20) max_bytes = std::max(max_bytes, s.pool_bytes);
  }
  EXPECT_LE(texturer.pool().size(), o.pool.hard_max_images);
  EXPECT_GT(max_bytes, 0u);
}

TEST(TexturingTest, TermsFollowThePaper) {
  TextureTermOptions o;
  // Quality: facing the camera = 1, grazing = 0, back-facing clamps to 0.
  EXPECT_DOUBLE_EQ(TriangleQuality({0, 0, -1}, {0, 0, 1}), 1.0);
  EXPECT_DOUBLE_EQ(TriangleQuality({0, 0, 1}, {0, 0, 1}), 0.0);
  // Occluded = infinite; lifetime saturates at t_max.
  EXPECT_TRUE(std::isinf(ViewDataCost(false, 1.0, 0, o)));
  EXPECT_DOUBLE_EQ(ViewDataCost(true, 1.0, 0, o), 0.0);
  EXPECT_DOUBLE_EQ(ViewDataCost(true, 1.0, 10 * o.t_max, o), 1.0 - o.beta);
  EXPECT_LT(ViewDataCost(true, 0.9, 1, o), ViewDataCost(true, 0.5, 1, o));
  EXPECT_DOUBLE_EQ(SeamPairCost(0.4, 1.0, o), (1 - o.alpha) * 0.4 + o.alpha * 1.0);
  // Distance field along a 1 m path of 3 collinear vertices.
  Eigen::MatrixX3d v(4, 3);
  v << 0, 0, 0, 1, 0, 0, 2, 0, 0, 1, 1, 0;
  Eigen::MatrixX3i t(2, 3);
  t << 0, 1, 3, 1, 2, 3;
  const auto d = MeshDistanceField(v, t, {0});
  EXPECT_DOUBLE_EQ(d[2], 2.0);
  EXPECT_DOUBLE_EQ(d[3], std::sqrt(2.0));
  // Bounded: exact up to the bound, +inf beyond.
  const MeshGeodesics geodesics(v, t);
  EXPECT_DOUBLE_EQ(geodesics.max_edge_length(), std::sqrt(2.0));
  const auto bounded = geodesics.DistanceField({0}, 1.5);
  EXPECT_DOUBLE_EQ(bounded[1], 1.0);
  EXPECT_DOUBLE_EQ(bounded[3], std::sqrt(2.0));
  EXPECT_TRUE(std::isinf(bounded[2]));
}

// Bounded distance fields (bucket search) equal the unbounded ones (binary heap) bit for bit up
// to the bound, on a jittered grid with edges from 0.2 to 1.8 units and several sources.
TEST(TexturingTest, BoundedDistanceFieldMatchesDijkstra) {
  constexpr int kSide = 40;
  Eigen::MatrixX3d v(kSide * kSide, 3);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> jitter(-0.4, 0.4);
  for (int y = 0; y < kSide; ++y)
    for (int x = 0; x < kSide; ++x) v.row(y * kSide + x) << x + jitter(rng), y + jitter(rng), 0.0;
  Eigen::MatrixX3i t(2 * (kSide - 1) * (kSide - 1), 3);
  int f = 0;
  for (int y = 0; y + 1 < kSide; ++y) {
    for (int x = 0; x + 1 < kSide; ++x) {
      const int a = y * kSide + x;
      t.row(f++) << a, a + 1, a + kSide + 1;
      t.row(f++) << a, a + kSide + 1, a + kSide;
    }
  }
  const MeshGeodesics geodesics(v, t);
  const std::vector<int> sources = {0, 17, 17, 433, 1210, 1599, -3, kSide * kSide};
  const std::vector<double> full = geodesics.DistanceField(sources);
  for (const double bound : {0.5, 3.0, 11.0, 1e3}) {
    const std::vector<double> bounded = geodesics.DistanceField(sources, bound);
    int within = 0;
    for (int i = 0; i < v.rows(); ++i) {
      if (full[i] <= bound) {
        EXPECT_EQ(bounded[i], full[i]) << "vertex " << i << ", bound " << bound;
        ++within;
      } else {
        EXPECT_TRUE(std::isinf(bounded[i])) << "vertex " << i << ", bound " << bound;
      }
    }
    EXPECT_GT(within, bound < 1.0 ? 4 : 40);
  }
  EXPECT_EQ(full[17], 0.0);
  EXPECT_TRUE(std::isfinite(full[kSide * kSide - 1]));
}

// A white square (z = 1 m) in the left half of a black image, its right border on the pixel
// boundary u = 31.5: colours sampled at that border come from the square only with
// surface-aware sampling.
TEST(TexturingTest, SurfaceAwareSamplingIgnoresTheBackground) {
  Eigen::MatrixX3d v(4, 3);
  v << -0.4, -0.4, 1.0, 0.0, -0.4, 1.0, 0.0, 0.4, 1.0, -0.4, 0.4, 1.0;
  Eigen::MatrixX3i t(2, 3);
  t << 0, 2, 1, 0, 3, 2;  // facing the camera (-z)
  PinholeCamera camera;
  camera.width = camera.height = 64;
  camera.fx = camera.fy = 64.0;
  camera.cx = camera.cy = 31.5;
  cv::Mat image(64, 64, CV_8UC3, cv::Scalar(0, 0, 0));
  image(cv::Rect(0, 0, 32, 64)).setTo(cv::Scalar(255, 255, 255));  // the square: u <= 31.5
  const TextureMesh mesh = TextureMesh::Build(t);
  for (const bool aware : {false, true}) {
    ImagePoolOptions o;
    o.surface_aware_sampling = aware;
    ImagePool pool(&mesh, o, VisibilityOptions());
    pool.Add(0, image, camera, v);
    const PoolEntry& e = pool.entry(0);
    ASSERT_TRUE(e.visibility.visible[0] && e.visibility.visible[1]);
    // Half a pixel inside the border: the bilinear footprint straddles it.
    const Eigen::Vector3d point(-0.004, 0.0, 1.0);
    Eigen::Vector3f c;
    ASSERT_TRUE(e.SampleSurface(point, 1.0, false, &c));
    if (aware) {
      EXPECT_NEAR(c.x(), 1.0f, 1e-6);
    } else {
      EXPECT_LT(c.x(), 0.9f);
    }
  }
}

TEST(TexturingTest, HalfResolutionVisibilityMostlyAgrees) {
  const Template sphere = UvSphere(24, 48, 0.3, Eigen::Vector3d(0, 1, 0));
  const PinholeCamera camera = OrbitCamera(0.3, 320);
  VisibilityOptions full, half;
  half.raster_scale = 0.5;
  SurfaceDepth depth;
  const TriangleVisibility a =
      ComputeVisibility(sphere.vertices, sphere.triangles, camera, full, &depth);
  const TriangleVisibility b = ComputeVisibility(sphere.vertices, sphere.triangles, camera, half);
  int visible = 0, agree = 0;
  for (int f = 0; f < sphere.num_triangles(); ++f) {
    visible += a.visible[f];
    agree += a.visible[f] == b.visible[f];
  }
  EXPECT_GT(visible, sphere.num_triangles() / 4);
  EXPECT_GT(agree, 0.95 * sphere.num_triangles());
  // The kept z-buffer: the sphere's nearest point is 0.3 m nearer than its centre, 1.2
  // sqrt(1.09) m from the camera (up to the tessellation); nothing outside the sphere.
  const Eigen::Vector2d centre = camera.Project(Eigen::Vector3d(0, 1, 0));
  const float z = depth.At(static_cast<int>(std::lround(centre.x())),
                           static_cast<int>(std::lround(centre.y())));
  EXPECT_NEAR(z, 1.2 * std::sqrt(1.09) - 0.3, 0.01);
  EXPECT_TRUE(std::isinf(depth.At(0, 0)));
}

// Expects the leveller's corrections to solve the normal equations of its least-squares
// problem, built here densely and independently (some colours unknown).
void ExpectSolvesNormalEquations(int v_count, const Eigen::MatrixX3i& triangles,
                                 const std::vector<int>& labels) {
  const int f_count = static_cast<int>(triangles.rows());
  const auto colour = [](int v, int l, Eigen::Vector3f* c) {
    if ((v + l) % 11 == 0) return false;  // some unknown colours
    *c = Eigen::Vector3f(0.1f * l + 0.01f * v, 0.5f - 0.03f * l, 0.2f + 0.002f * v * l);
    return true;
  };
  SeamLevellingOptions options;
  Eigen::MatrixX3f corrections;
  SeamLevellingSummary summary;
  LevelSeams(v_count, triangles, labels, colour, options, &corrections, &summary);
  ASSERT_GT(summary.seam_equations, 0);
  // Dense reference: unknowns (v, l) in order of first use.
  std::map<std::pair<int, int>, int> index;
  for (int f = 0; f < f_count; ++f)
    for (int c = 0; c < 3; ++c)
      if (labels[f] >= 0) index.emplace(std::make_pair(triangles(f, c), labels[f]), index.size());
  const int n = static_cast<int>(index.size());
  EXPECT_EQ(n, summary.unknowns);
  Eigen::MatrixXd a = options.regularisation * Eigen::MatrixXd::Identity(n, n);
  Eigen::MatrixXd b = Eigen::MatrixXd::Zero(n, 3);
  for (auto i = index.begin(); i != index.end(); ++i) {
    for (auto j = std::next(i); j != index.end(); ++j) {
      if (i->first.first != j->first.first) continue;  // same vertex, two labels
      Eigen::Vector3f ci, cj;
      if (!colour(i->first.first, i->first.second, &ci) ||
          !colour(j->first.first, j->first.second, &cj))
        continue;
      const int p = i->second, q = j->second;
      a(p, p) += 1;
      a(q, q) += 1;
      a(p, q) -= 1;
      a(q, p) -= 1;
      b.row(p) += (cj - ci).cast<double>().transpose();
      b.row(q) -= (cj - ci).cast<double>().transpose();
    }
  }
  for (int f = 0; f < f_count; ++f) {
    if (labels[f] < 0) continue;
    for (int c = 0; c < 3; ++c) {
      const int p = index.at({triangles(f, c), labels[f]});
      const int q = index.at({triangles(f, (c + 1) % 3), labels[f]});
      const double w = options.smoothness;
      a(p, p) += w;
      a(q, q) += w;
      a(p, q) -= w;
      a(q, p) -= w;
    }
  }
  const Eigen::MatrixXd g = a.ldlt().solve(b);
  for (int f = 0; f < f_count; ++f) {
    for (int c = 0; c < 3; ++c) {
      if (labels[f] < 0) {
        EXPECT_EQ(corrections.row(3 * f + c).norm(), 0.0f);
        continue;
      }
      const int p = index.at({triangles(f, c), labels[f]});
      EXPECT_NEAR((corrections.row(3 * f + c).cast<double>() - g.row(p)).norm(), 0.0, 1e-5)
          << "triangle " << f << " corner " << c;
    }
  }
  EXPECT_LT(summary.seam_residual_after, summary.seam_residual_before);
}

// The leveller's corrections solve the normal equations of its least-squares problem on a
// small sphere with four regions (one untextured).
TEST(TexturingTest, SeamLevellerSolvesTheLeastSquaresProblem) {
  const Template sphere = UvSphere(6, 8, 1.0, Eigen::Vector3d::Zero());
  const int f_count = sphere.num_triangles();
  std::vector<int> labels(f_count);
  for (int f = 0; f < f_count; ++f) {
    const Eigen::Vector3d c =
        (sphere.vertices.row(sphere.triangles(f, 0)) + sphere.vertices.row(sphere.triangles(f, 1)) +
         sphere.vertices.row(sphere.triangles(f, 2))) /
        3.0;
    labels[f] = c.y() > 0.5 ? -1 : (c.x() > 0 ? 3 : (c.z() > 0 ? 7 : 9));
  }
  ExpectSolvesNormalEquations(sphere.num_vertices(), sphere.triangles, labels);
}

// Also with fragmented labels (many vertices with three or more labels), scattered
// untextured triangles, a duplicated triangle and triangles that repeat a vertex, on a larger
// mesh.
TEST(TexturingTest, SeamLevellerSolvesFragmentedLabellings) {
  const Template sphere = UvSphere(12, 24, 1.0, Eigen::Vector3d::Zero());
  Eigen::MatrixX3i triangles(sphere.num_triangles() + 3, 3);
  const int a = sphere.triangles(40, 0), b = sphere.triangles(40, 1), c = sphere.triangles(90, 2);
  triangles << sphere.triangles, sphere.triangles.row(5), a, a, b, c, c, c;
  std::vector<int> labels(triangles.rows());
  for (int f = 0; f < static_cast<int>(labels.size()); ++f)
    labels[f] = f % 13 == 0 ? -1 : (f / 9) % 4 + 2 * (f % 3 == 0);
  ExpectSolvesNormalEquations(sphere.num_vertices(), triangles, labels);
}

// The leveller's factorisation (LdltFactor) gives SimplicialLDLT's factor and solutions bit for
// bit, on random sparse SPD matrices in its layout (upper triangle, natural order) with much
// fill, for right-hand sides that have zero entries (+0 and -0) and an all-zero row; one
// LdltFactor refactorises (its buffers reused, the matrices growing and shrinking).
TEST(TexturingTest, SeamLevellerFactorMatchesEigenBitForBit) {
  using SparseMatrix = Eigen::SparseMatrix<double, Eigen::ColMajor, Eigen::Index>;
  using seam_levelling_internal::Rows3;
  const auto same_bits = [](double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; };
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  seam_levelling_internal::LdltFactor factor;
  for (const int n : {400, 90, 700}) {
    std::vector<Eigen::Triplet<double, Eigen::Index>> entries;
    for (int j = 0; j < n; ++j) {
      entries.emplace_back(j, j, 8.0 + uniform(rng));
      for (int k = 0; k < 3; ++k) {
        const int i = static_cast<int>(rng() % n);
        if (i < j) entries.emplace_back(i, j, 0.5 * uniform(rng));
      }
    }
    SparseMatrix upper(n, n);
    upper.setFromTriplets(entries.begin(), entries.end());
    Eigen::SimplicialLDLT<SparseMatrix, Eigen::Upper, Eigen::NaturalOrdering<Eigen::Index>> solver(
        upper);
    ASSERT_EQ(solver.info(), Eigen::Success);
    const std::vector<int> outer(upper.outerIndexPtr(), upper.outerIndexPtr() + n + 1);
    const std::vector<int> inner(upper.innerIndexPtr(), upper.innerIndexPtr() + upper.nonZeros());
    ASSERT_TRUE(factor.Factorize(n, outer.data(), inner.data(), upper.valuePtr()));
    const SparseMatrix& l = solver.matrixL().nestedExpression();
    ASSERT_EQ(static_cast<int>(factor.l_value().size()), l.nonZeros());
    for (int k = 0; k <= n; ++k) ASSERT_EQ(factor.l_outer()[k], l.outerIndexPtr()[k]);
    for (int p = 0; p < l.nonZeros(); ++p) {
      ASSERT_EQ(factor.l_inner()[p], l.innerIndexPtr()[p]);
      ASSERT_TRUE(same_bits(factor.l_value()[p], l.valuePtr()[p])) << "entry " << p;
    }
    for (int k = 0; k < n; ++k) ASSERT_TRUE(same_bits(factor.d()[k], solver.vectorD()[k]));
    Rows3 b(n, 3);
    for (int i = 0; i < n; ++i)
      for (int c = 0; c < 3; ++c) b(i, c) = (i + c) % 5 == 0 ? 0.0 : uniform(rng);
    b(3, 1) = -0.0;
    b.row(17).setZero();
    const Eigen::MatrixX3d expected = solver.solve(Eigen::MatrixX3d(b));
    Rows3 x = b;
    factor.Solve3(&x);
    for (int i = 0; i < n; ++i) {
      for (int c = 0; c < 3; ++c) {
        ASSERT_TRUE(same_bits(x(i, c), expected(i, c)))
            << "n " << n << " row " << i << " column " << c << ": " << x(i, c) << " vs "
            << expected(i, c);
      }
    }
  }
  // A zero pivot is reported.
  const std::vector<int> outer = {0, 1, 3}, inner = {0, 0, 1};
  const std::vector<double> singular = {1.0, 1.0, 1.0};
  EXPECT_FALSE(factor.Factorize(2, outer.data(), inner.data(), singular.data()));
}

// With a switch cost, triangles keep their source image unless another is clearly better.
TEST(TexturingTest, SwitchCostKeepsSources) {
  Scene scene;
  TexturingOptions plain = SmallOptions(), sticky = SmallOptions();
  plain.selection.terms.switch_cost = 0.0;  // the paper's energy
  sticky.selection.terms.switch_cost = 0.05;
  Texturer a(scene.sphere, plain), b(scene.sphere, sticky);
  long changed_plain = 0, changed_sticky = 0;
  for (int f = 0; f < 12; ++f) {
    const double angle = 0.03 * f;  // a slow orbit: consecutive views are nearly equal
    const cv::Mat image = scene.Image(f, angle, 1.0);
    const auto sa =
        a.AddFrame(f, image, OrbitCamera(angle, scene.image_size), scene.sphere.vertices);
    const auto sb =
        b.AddFrame(f, image, OrbitCamera(angle, scene.image_size), scene.sphere.vertices);
    if (f > 0) {
      changed_plain += sa.changed_triangles;
      changed_sticky += sb.changed_triangles;
    }
    EXPECT_NEAR(sa.textured_triangles, sb.textured_triangles, 0.01 * sa.textured_triangles);
  }
  std::printf("changed triangles over 11 frames: %ld (switch cost 0), %ld (0.05)\n", changed_plain,
              changed_sticky);
  EXPECT_LT(changed_sticky, changed_plain / 4);
  TexturingOptions bad = SmallOptions();
  bad.selection.terms.switch_cost = -1.0;
  EXPECT_THROW(Texturer(scene.sphere, bad), Error);
}

TEST(TexturingTest, BadInputIsRejected) {
  Scene scene;
  TexturingOptions bad = SmallOptions();
  bad.selection.terms.beta = 2.0;
  EXPECT_THROW(Texturer(scene.sphere, bad), Error);
  Texturer texturer(scene.sphere, SmallOptions());
  cv::Mat wrong(10, 10, CV_8UC3);
  EXPECT_THROW(texturer.AddFrame(0, wrong, OrbitCamera(0, scene.image_size), scene.sphere.vertices),
               Error);
  Template no_uv = scene.sphere;
  no_uv.uv_triangles.resize(0, 3);
  EXPECT_THROW(Texturer(no_uv, SmallOptions()), Error);
}

}  // namespace
}  // namespace artex
