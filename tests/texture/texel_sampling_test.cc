// SampleTriangle against a straightforward per-texel reference: each texel's surface point
// (its barycentrics applied to the corners in camera coordinates) sampled with
// PoolEntry::SampleSurface at the triangle's quality (plain bilinear without a z-buffer). Scene:
// two UV spheres, the smaller partly in front of the larger (silhouettes and an occlusion
// border for surface-aware sampling), in a random-coloured image (the largest colour gradients),
// seen by cameras that put the spheres inside the image, across its border, close enough for
// large triangles, behind the camera, or not at all.
#include "texture/texel_sampling.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <vector>

#include "models/template.h"
#include "tests/texture/sphere_mesh.h"
#include "texture/image_pool.h"
#include "texture/visibility.h"

namespace artex {
namespace {

using testing::AddUvSphere;

constexpr int kAtlasSize = 256;
constexpr int kImageSeed = 7;
constexpr double kColourTolerance = 1e-5;

// The two spheres with their atlas halves.
Template Spheres() {
  std::vector<Eigen::Vector3d> v;
  std::vector<Eigen::Vector3i> t, uvt;
  std::vector<Eigen::Vector2d> uv;
  AddUvSphere(16, 32, 0.3, Eigen::Vector3d(0, 1, 0), 0.02, 0.48, 0.02, 0.98, &v, &t, &uv, &uvt);
  AddUvSphere(10, 20, 0.12, Eigen::Vector3d(0.12, 1.05, 0.35), 0.52, 0.98, 0.02, 0.98, &v, &t, &uv,
              &uvt);
  Template s;
  s.vertices.resize(static_cast<int>(v.size()), 3);
  for (std::size_t k = 0; k < v.size(); ++k) s.vertices.row(k) = v[k].transpose();
  s.triangles.resize(static_cast<int>(t.size()), 3);
  s.uv_triangles.resize(static_cast<int>(t.size()), 3);
  for (std::size_t k = 0; k < t.size(); ++k) {
    s.triangles.row(k) = t[k].transpose();
    s.uv_triangles.row(k) = uvt[k].transpose();
  }
  s.uvs.resize(static_cast<int>(uv.size()), 2);
  for (std::size_t k = 0; k < uv.size(); ++k) s.uvs.row(k) = uv[k].transpose();
  return s;
}

// A size x size camera with focal length `focal` (pixels) and principal point (cx, cx), at
// `eye` looking at the larger sphere's centre.
PinholeCamera Camera(int size, double focal, double cx, const Eigen::Vector3d& eye) {
  PinholeCamera camera;
  camera.width = camera.height = size;
  camera.fx = camera.fy = focal;
  camera.cx = cx;
  camera.cy = (size - 1) / 2.0;
  camera.world_to_camera =
      PinholeCamera::LookAt(eye, Eigen::Vector3d(0, 1, 0), Eigen::Vector3d::UnitY());
  return camera;
}

cv::Mat RandomImage(int size) {
  cv::Mat image(size, size, CV_8UC3);
  cv::RNG rng(kImageSeed);
  rng.fill(image, cv::RNG::UNIFORM, 0, 256);
  return image;
}

struct Comparison {
  double max_difference = 0.0;
  int texels = 0;
  int written = 0;
  int partly_written_triangles = 0;  // some but not all texels in the crop
  int surface_aware_texels = 0;      // colour differs from plain bilinear by > 0.05
};

// Samples every triangle of `entry` and compares texel by texel with the reference; texels the
// reference cannot sample must keep their previous (sentinel) colour.
Comparison CompareWithReference(const Template& spheres, const AtlasMap& map,
                                const PoolEntry& entry) {
  const Eigen::Vector3f sentinel(-2.0f, -3.0f, -4.0f);
  TexelBuffer texels(map);
  std::fill(texels.color.begin(), texels.color.end(), sentinel);
  Comparison result;
  for (int f = 0; f < map.num_triangles(); ++f) {
    const int written = SampleTriangle(map, f, spheres.triangles, entry, &texels);
    Eigen::Vector3d corner[3];
    for (int k = 0; k < 3; ++k) {
      corner[k] =
          entry.camera.world_to_camera * entry.vertices.row(spheres.triangles(f, k)).transpose();
    }
    int expected = 0;
    for (int p = map.first(f); p < map.last(f); ++p) {
      const Eigen::Vector3f w = map.barycentric_at(p);
      const Eigen::Vector3d point = static_cast<double>(w.x()) * corner[0] +
                                    static_cast<double>(w.y()) * corner[1] +
                                    static_cast<double>(w.z()) * corner[2];
      Eigen::Vector3f reference;
      const bool sampled =
          entry.SampleSurface(point, entry.visibility.quality[f], true, &reference);
      ++result.texels;
      if (!sampled) {
        EXPECT_EQ(texels.valid[p], 0) << "triangle " << f << " position " << p;
        EXPECT_EQ(texels.color[p], sentinel) << "triangle " << f << " position " << p;
        continue;
      }
      ++expected;
      EXPECT_EQ(texels.valid[p], 1) << "triangle " << f << " position " << p;
      result.max_difference =
          std::max(result.max_difference,
                   static_cast<double>((texels.color[p] - reference).cwiseAbs().maxCoeff()));
      Eigen::Vector3f plain;
      const Eigen::Vector2d pixel(entry.camera.fx * point.x() / point.z() + entry.camera.cx,
                                  entry.camera.fy * point.y() / point.z() + entry.camera.cy);
      if (entry.Sample(pixel, &plain) && (plain - reference).cwiseAbs().maxCoeff() > 0.05f)
        ++result.surface_aware_texels;
    }
    EXPECT_EQ(written, expected) << "triangle " << f;
    result.written += written;
    result.partly_written_triangles += written > 0 && written < map.last(f) - map.first(f);
  }
  return result;
}

struct Scene {
  Template spheres = Spheres();
  AtlasMap map{spheres, kAtlasSize};
  TextureMesh mesh = TextureMesh::Build(spheres.triangles);

  // The pool entry of one image seen by `camera`.
  Comparison Run(const PinholeCamera& camera, bool surface_aware, double raster_scale = 1.0) {
    ImagePoolOptions pool_options;
    pool_options.surface_aware_sampling = surface_aware;
    VisibilityOptions visibility_options;
    visibility_options.raster_scale = raster_scale;
    ImagePool pool(&mesh, pool_options, visibility_options);
    pool.Add(0, RandomImage(camera.width), camera, spheres.vertices);
    return CompareWithReference(spheres, map, pool.entry(0));
  }
};

TEST(TexelSamplingTest, AtlasBarycentricsAreConvexWeights) {
  // The fast path relies on texels projecting inside their triangle's corners' hull.
  const Scene scene;
  const AtlasMap& map = scene.map;
  ASSERT_GT(map.num_covered(), 1000);
  for (int f = 0; f < map.num_triangles(); ++f) {
    for (int p = map.first(f); p < map.last(f); ++p) {
      const Eigen::Vector3f w = map.barycentric_at(p);
      ASSERT_GE(w.minCoeff(), 0.0f) << p;
      ASSERT_NEAR(static_cast<double>(w.x()) + w.y() + w.z(), 1.0, 2.5e-7) << p;
      for (int c = 0; c < 3; ++c) ASSERT_EQ(map.barycentrics(c)[p], w[c]);
      const int texel = map.texels_begin(f)[p - map.first(f)];
      ASSERT_EQ(map.position(texel), p);
      ASSERT_EQ(map.barycentric(texel), w);
    }
  }
}

TEST(TexelSamplingTest, SurfaceAwareSamplingMatchesTheReference) {
  Scene scene;
  const Comparison c = scene.Run(Camera(160, 200.0, 79.5, Eigen::Vector3d(0.3, 1.1, 1.3)), true);
  EXPECT_LE(c.max_difference, kColourTolerance);
  EXPECT_GT(c.written, c.texels / 3);  // the front halves of both spheres
  // Texels whose colour depends on the depth tests (silhouettes, the occlusion border).
  EXPECT_GT(c.surface_aware_texels, 100);
}

TEST(TexelSamplingTest, HalfResolutionZBufferMatchesTheReference) {
  Scene scene;
  const Comparison c =
      scene.Run(Camera(160, 200.0, 79.5, Eigen::Vector3d(-0.4, 0.9, 1.2)), true, 0.5);
  EXPECT_LE(c.max_difference, kColourTolerance);
  EXPECT_GT(c.surface_aware_texels, 100);
}

TEST(TexelSamplingTest, PlainSamplingMatchesTheReference) {
  Scene scene;
  const Comparison c = scene.Run(Camera(160, 200.0, 79.5, Eigen::Vector3d(0.3, 1.1, 1.3)), false);
  EXPECT_LE(c.max_difference, kColourTolerance);
  EXPECT_EQ(c.surface_aware_texels, 0);
  // Every texel of every triangle in front of the camera projects into the image.
  EXPECT_EQ(c.written, c.texels);
}

TEST(TexelSamplingTest, TrianglesAcrossTheCropBorderKeepTheirOutsideTexels) {
  Scene scene;
  // Principal point near the left border: the spheres cross it, the crop is cut there.
  for (const bool surface_aware : {true, false}) {
    const Comparison c =
        scene.Run(Camera(160, 200.0, 12.0, Eigen::Vector3d(0.0, 1.0, 1.3)), surface_aware);
    EXPECT_LE(c.max_difference, kColourTolerance);
    EXPECT_GT(c.partly_written_triangles, 10);
    EXPECT_GT(c.written, 0);
    EXPECT_LT(c.written, c.texels);
  }
}

TEST(TexelSamplingTest, LargeTrianglesMatchTheReference) {
  Scene scene;
  // Close and long focal length: triangles cover thousands of pixels.
  const Comparison c = scene.Run(Camera(480, 1500.0, 239.5, Eigen::Vector3d(0.1, 1.0, 1.0)), true);
  EXPECT_LE(c.max_difference, kColourTolerance);
  EXPECT_GT(c.written, 0);
}

TEST(TexelSamplingTest, CornersBehindTheCameraMatchTheReference) {
  Scene scene;
  // Inside the larger sphere: part of it is behind the camera.
  const Comparison c = scene.Run(Camera(160, 120.0, 79.5, Eigen::Vector3d(0.01, 1.02, 0.17)), true);
  EXPECT_LE(c.max_difference, kColourTolerance);
  EXPECT_GT(c.written, 0);
  EXPECT_LT(c.written, c.texels);
}

TEST(TexelSamplingTest, NothingIsWrittenWhenTheSubjectIsOutOfView) {
  Scene scene;
  PinholeCamera camera = Camera(160, 200.0, 79.5, Eigen::Vector3d(0.0, 1.0, 1.3));
  camera.world_to_camera = PinholeCamera::LookAt(
      Eigen::Vector3d(0.0, 1.0, 1.3), Eigen::Vector3d(0.0, 1.0, 3.0), Eigen::Vector3d::UnitY());
  for (const bool surface_aware : {true, false}) {
    const Comparison c = scene.Run(camera, surface_aware);
    EXPECT_EQ(c.written, 0);
  }
}

TEST(TexelSamplingTest, ClearTriangleResetsOnlyItsTexels) {
  Scene scene;
  ImagePool pool(&scene.mesh, ImagePoolOptions(), VisibilityOptions());
  const PinholeCamera camera = Camera(160, 200.0, 79.5, Eigen::Vector3d(0.3, 1.1, 1.3));
  pool.Add(0, RandomImage(camera.width), camera, scene.spheres.vertices);
  TexelBuffer texels(scene.map);
  for (int f = 0; f < scene.map.num_triangles(); ++f)
    SampleTriangle(scene.map, f, scene.spheres.triangles, pool.entry(0), &texels);
  const TexelBuffer before = texels;
  // A triangle with sampled texels.
  int cleared = -1;
  for (int f = 0; f < scene.map.num_triangles() && cleared < 0; ++f) {
    if (scene.map.last(f) > scene.map.first(f) && before.valid[scene.map.first(f)]) cleared = f;
  }
  ASSERT_GE(cleared, 0);
  ClearTriangle(scene.map, cleared, &texels);
  for (int p = 0; p < scene.map.num_covered(); ++p) {
    if (p >= scene.map.first(cleared) && p < scene.map.last(cleared)) {
      EXPECT_EQ(texels.valid[p], 0);
      EXPECT_EQ(texels.color[p], Eigen::Vector3f::Zero());
    } else {
      EXPECT_EQ(texels.valid[p], before.valid[p]);
      EXPECT_EQ(texels.color[p], before.color[p]);
    }
  }
}

// ComposeAtlas against the straightforward composition: every covered texel, corrections
// interpolated, then `padding` passes over the whole image, each filling every empty texel
// that has filled 8-neighbours with their mean (the dilation it replaced, which visits every
// texel on every pass). Byte for byte, with holes inside the charts (cleared triangles).
cv::Mat ReferenceComposition(const AtlasMap& map, const TexelBuffer& base,
                             const Eigen::MatrixX3f& corrections, int padding) {
  const int size = map.size();
  cv::Mat out(size, size, CV_32FC3, cv::Scalar(0, 0, 0));
  cv::Mat mask(size, size, CV_8UC1, cv::Scalar(0));
  for (int f = 0; f < map.num_triangles(); ++f) {
    for (int p = map.first(f); p < map.last(f); ++p) {
      const int t = *(map.texels_begin(f) + (p - map.first(f)));
      Eigen::Vector3f c = base.color[p];
      if (base.valid[p]) {
        mask.data[t] = 255;
        const Eigen::Vector3f w = map.barycentric_at(p);
        c += w.x() * corrections.row(3 * f).transpose() +
             w.y() * corrections.row(3 * f + 1).transpose() +
             w.z() * corrections.row(3 * f + 2).transpose();
      }
      reinterpret_cast<cv::Vec3f*>(out.data)[t] = cv::Vec3f(c.x(), c.y(), c.z());
    }
  }
  for (int pass = 0; pass < padding; ++pass) {
    cv::Mat next = out.clone(), next_mask = mask.clone();
    for (int y = 0; y < size; ++y) {
      for (int x = 0; x < size; ++x) {
        if (mask.at<uint8_t>(y, x)) continue;
        cv::Vec3f sum(0, 0, 0);
        int n = 0;
        for (int dy = -1; dy <= 1; ++dy) {
          for (int dx = -1; dx <= 1; ++dx) {
            const int yy = y + dy, xx = x + dx;
            if (yy < 0 || xx < 0 || yy >= size || xx >= size || !mask.at<uint8_t>(yy, xx)) continue;
            sum += out.at<cv::Vec3f>(yy, xx);
            ++n;
          }
        }
        if (n > 0) {
          next.at<cv::Vec3f>(y, x) = sum / static_cast<float>(n);
          next_mask.at<uint8_t>(y, x) = 255;
        }
      }
    }
    out = next;
    mask = next_mask;
  }
  cv::Mat out8;
  out.convertTo(out8, CV_8UC3, 255.0);
  return out8;
}

TEST(TexelSamplingTest, ComposeAtlasMatchesTheWholeImageDilation) {
  Scene scene;
  const AtlasMap& map = scene.map;
  TexelBuffer texels(map);
  cv::RNG rng(kImageSeed);
  for (int f = 0; f < map.num_triangles(); ++f) {
    const bool cleared = f % 7 == 3;  // holes inside the charts
    for (int p = map.first(f); p < map.last(f); ++p) {
      texels.valid[p] = cleared ? 0 : 1;
      texels.color[p] = cleared ? Eigen::Vector3f::Zero()
                                : Eigen::Vector3f(rng.uniform(0.f, 1.f), rng.uniform(0.f, 1.f),
                                                  rng.uniform(0.f, 1.f));
    }
  }
  Eigen::MatrixX3f corrections(3 * map.num_triangles(), 3);
  for (int r = 0; r < corrections.rows(); ++r)
    for (int c = 0; c < 3; ++c) corrections(r, c) = rng.uniform(-0.1f, 0.1f);
  // Working images kept across the calls (as the texturer keeps them), each call after one
  // that padded further: what an earlier call left in them must not show.
  AtlasScratch scratch;
  for (const int padding : {40, 0, 1, 4}) {
    const cv::Mat fast = ComposeAtlas(map, texels, &corrections, padding);
    const cv::Mat reference = ReferenceComposition(map, texels, corrections, padding);
    ASSERT_EQ(fast.type(), CV_8UC3);
    EXPECT_EQ(cv::norm(fast, reference, cv::NORM_INF), 0.0) << "padding " << padding;
    const uchar* kept = scratch.color.data;
    const cv::Mat reusing = ComposeAtlas(map, texels, &corrections, padding, &scratch);
    EXPECT_EQ(cv::norm(reusing, reference, cv::NORM_INF), 0.0) << "padding " << padding;
    if (kept != nullptr) {
      EXPECT_EQ(scratch.color.data, kept) << "padding " << padding;
    }
    // The padding grows into the empty texels (it is not a no-op the comparison would miss).
    if (padding > 0) {
      const cv::Mat unpadded = ReferenceComposition(map, texels, corrections, 0);
      EXPECT_GT(cv::norm(fast, unpadded, cv::NORM_L1), 0.0) << "padding " << padding;
    }
  }
}

}  // namespace
}  // namespace artex
