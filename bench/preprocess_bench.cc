// Preprocessing of one Kinect-sized depth frame (paper sec. 2) on a synthetic scene: a portrait
// 480 x 640 depth camera 1 m above the floor, a wall 3.5 m away and an ellipsoidal subject at
// 2.5 m covering ~16% of the pixels; Kinect-like noise (1.5 mm z^2, 1/8-pixel disparity
// quantisation, 1% dropouts); the paper's separate 1600 x 2032 colour camera. Single thread.
// Median figures: --benchmark_repetitions=10 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <cmath>
#include <random>
#include <vector>

#include "sensors/preprocess.h"
#include "sensors/scene_segmentation.h"

namespace artex {
namespace {

constexpr double kSigmaAt1m = 0.0015;
constexpr double kFocalBaseline = 43.5;  // px m
constexpr double kSubpixel = 8.0;
constexpr double kDropout = 0.01;
constexpr int kBackgroundFrames = 20;
constexpr std::uint64_t kSeed = 11;
const Eigen::Vector3d kSubjectCentre(0.0, 1.0, 0.5);
const Eigen::Vector3d kSubjectRadii(0.35, 0.85, 0.2);
constexpr double kWallZ = -0.5;

Calibration Rig() {
  Calibration cal;
  cal.depth.width = 480;
  cal.depth.height = 640;
  cal.depth.fx = cal.depth.fy = 575.0;
  cal.depth.cx = 239.5;
  cal.depth.cy = 319.5;
  cal.depth.world_to_camera = PinholeCamera::LookAt(
      Eigen::Vector3d(0, 1.0, 3.0), Eigen::Vector3d(0, 1.0, 0), Eigen::Vector3d::UnitY());
  cal.color.width = 1600;
  cal.color.height = 2032;
  cal.color.fx = cal.color.fy = 1800.0;
  cal.color.cx = 799.5;
  cal.color.cy = 1015.5;
  cal.color.world_to_camera = PinholeCamera::LookAt(
      Eigen::Vector3d(0.05, 1.1, 3.0), Eigen::Vector3d(0, 1.0, 0), Eigen::Vector3d::UnitY());
  cal.depth_scale = 1000.0;
  return cal;
}

cv::Mat Render(const PinholeCamera& cam, bool with_subject, std::mt19937_64* rng) {
  std::normal_distribution<double> noise(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  cv::Mat out(cam.height, cam.width, CV_16UC1);
  const Eigen::Isometry3d c2w = cam.world_to_camera.inverse();
  const Eigen::Vector3d o = c2w.translation();
  for (int v = 0; v < cam.height; ++v) {
    for (int u = 0; u < cam.width; ++u) {
      const Eigen::Vector3d d =
          c2w.linear() * Eigen::Vector3d((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0);
      double t = (kWallZ - o.z()) / d.z();
      if (d.y() < 0) t = std::min(t, -o.y() / d.y());
      if (with_subject) {
        const Eigen::Vector3d oc = (o - kSubjectCentre).cwiseQuotient(kSubjectRadii);
        const Eigen::Vector3d dc = d.cwiseQuotient(kSubjectRadii);
        const double a = dc.squaredNorm(), b = 2 * oc.dot(dc), c = oc.squaredNorm() - 1;
        const double disc = b * b - 4 * a * c;
        if (disc >= 0) {
          const double ts = (-b - std::sqrt(disc)) / (2 * a);
          if (ts > 0 && ts < t) t = ts;
        }
      }
      const double noisy = t + kSigmaAt1m * t * t * noise(*rng);
      const double q =
          kFocalBaseline / (std::round(kSubpixel * kFocalBaseline / noisy) / kSubpixel);
      out.at<uint16_t>(v, u) =
          uniform(*rng) < kDropout ? 0 : static_cast<uint16_t>(std::lround(q * 1000));
    }
  }
  return out;
}

struct Scene {
  Calibration calibration = Rig();
  std::vector<cv::Mat> background;
  Frame frame;
  Scene() {
    std::mt19937_64 rng(kSeed);
    for (int i = 0; i < kBackgroundFrames; ++i)
      background.push_back(Render(calibration.depth, false, &rng));
    frame.depth = Render(calibration.depth, true, &rng);
    frame.color.create(calibration.color.height, calibration.color.width, CV_8UC3);
    cv::RNG color_rng(kSeed);
    color_rng.fill(frame.color, cv::RNG::UNIFORM, 0, 255);
  }
};

const Scene& GetScene() {
  static const Scene scene;  // built once, read-only
  return scene;
}

void BM_PreprocessFrame(benchmark::State& state) {
  const Scene& scene = GetScene();
  Preprocessor pre(scene.calibration);
  pre.Train(scene.background);
  Scan scan;
  PreprocessStats stats;
  for (auto _ : state) {
    pre.Process(scene.frame, &scan, &stats);
    benchmark::DoNotOptimize(scan.points.data());
  }
  state.counters["foreground_fraction"] =
      static_cast<double>(stats.foreground_pixels) / (scene.frame.depth.total());
  state.counters["vertices"] = stats.mesh.vertices;
  state.counters["triangles"] = stats.mesh.triangles;
}
BENCHMARK(BM_PreprocessFrame)->Unit(benchmark::kMillisecond);

// The same frame without empty-scene frames: floor and wall removed (planes detected on the
// first frame, then reused), the subject's 3-D connected component kept.
void BM_PreprocessFrameSegmented(benchmark::State& state) {
  const Scene& scene = GetScene();
  Preprocessor pre(scene.calibration);
  pre.TrainWithoutBackground();
  Scan scan;
  PreprocessStats stats;
  pre.Process(scene.frame, &scan, &stats);  // detects the planes
  for (auto _ : state) {
    pre.Process(scene.frame, &scan, &stats);
    benchmark::DoNotOptimize(scan.points.data());
  }
  state.counters["foreground_fraction"] =
      static_cast<double>(stats.foreground_pixels) / (scene.frame.depth.total());
  state.counters["vertices"] = stats.mesh.vertices;
}
BENCHMARK(BM_PreprocessFrameSegmented)->Unit(benchmark::kMillisecond);

// Plane removal and components alone (the part that replaces BM_BackgroundClassify).
void BM_SegmentSubject(benchmark::State& state) {
  const Scene& scene = GetScene();
  const Eigen::Vector3d up =
      scene.calibration.depth.world_to_camera.linear() * Eigen::Vector3d::UnitY();
  SubjectSegmenter seg(scene.calibration.depth, Distortion(), scene.calibration.depth_scale, up,
                       SubjectSegmentationOptions());
  cv::Mat mask;
  SegmentationStats stats;
  seg.Segment(scene.frame.depth, &mask, &stats);
  for (auto _ : state) {
    seg.Segment(scene.frame.depth, &mask, &stats);
    benchmark::DoNotOptimize(mask.data);
  }
  state.counters["components"] = stats.components;
  state.counters["subject_pixels"] = stats.subject_pixels;
}
BENCHMARK(BM_SegmentSubject)->Unit(benchmark::kMillisecond);

// RANSAC floor and walls of one frame (first frame and re-initialisations only).
void BM_DetectScenePlanes(benchmark::State& state) {
  const Scene& scene = GetScene();
  const Eigen::Vector3d up =
      scene.calibration.depth.world_to_camera.linear() * Eigen::Vector3d::UnitY();
  std::vector<ScenePlane> planes;
  for (auto _ : state) {
    planes = DetectScenePlanes(scene.frame.depth, scene.calibration.depth, Distortion(),
                               scene.calibration.depth_scale, up, PlaneDetectionOptions());
    benchmark::DoNotOptimize(planes.data());
  }
  state.counters["planes"] = static_cast<double>(planes.size());
}
BENCHMARK(BM_DetectScenePlanes)->Unit(benchmark::kMillisecond);

void BM_BackgroundClassify(benchmark::State& state) {
  const Scene& scene = GetScene();
  BackgroundModel model;
  model.Train(scene.background, scene.calibration.depth_scale);
  cv::Mat mask;
  for (auto _ : state) {
    model.Classify(scene.frame.depth, &mask);
    benchmark::DoNotOptimize(mask.data);
  }
}
BENCHMARK(BM_BackgroundClassify)->Unit(benchmark::kMillisecond);

void BM_DepthMeshAndNormals(benchmark::State& state) {
  const Scene& scene = GetScene();
  BackgroundModel model;
  model.Train(scene.background, scene.calibration.depth_scale);
  cv::Mat mask;
  model.Classify(scene.frame.depth, &mask);
  DepthMesher mesher(scene.calibration.depth, scene.calibration.depth_distortion);
  Scan scan;
  for (auto _ : state) {
    mesher.Build(scene.frame.depth, scene.calibration.depth_scale, mask, &scan);
    benchmark::DoNotOptimize(scan.normals.data());
  }
}
BENCHMARK(BM_DepthMeshAndNormals)->Unit(benchmark::kMillisecond);

void BM_SampleColors(benchmark::State& state) {
  const Scene& scene = GetScene();
  Preprocessor pre(scene.calibration);
  pre.Train(scene.background);
  Scan scan;
  pre.Process(scene.frame, &scan);
  for (auto _ : state) {
    SampleScanColors(scene.calibration.color, scene.calibration.color_distortion, scene.frame.color,
                     &scan);
    benchmark::DoNotOptimize(scan.colors.data());
  }
}
BENCHMARK(BM_SampleColors)->Unit(benchmark::kMillisecond);

void BM_TrainBackground(benchmark::State& state) {
  const Scene& scene = GetScene();
  BackgroundModel model;
  for (auto _ : state) model.Train(scene.background, scene.calibration.depth_scale);
}
BENCHMARK(BM_TrainBackground)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace artex
