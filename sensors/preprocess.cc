#include "sensors/preprocess.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "models/error.h"
#include "sensors/image_io.h"

namespace artex {
namespace {

double Seconds(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

const PreprocessOptions& Checked(const PreprocessOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw Error("preprocessing options: " + error);
  return options;
}

}  // namespace

const std::map<std::string, ForegroundMode>& ForegroundModeNames() {
  static const std::map<std::string, ForegroundMode> names = {
      {"auto", ForegroundMode::kAuto},
      {"background", ForegroundMode::kBackground},
      {"segment", ForegroundMode::kSegment}};
  return names;
}

bool PreprocessOptions::IsValid(std::string* error) const {
  if (!background.IsValid(error) || !mesh.IsValid(error)) return false;
  if (!(assumed_camera_height >= 0 && std::isfinite(assumed_camera_height))) {
    if (error) *error = "assumed_camera_height: expected a finite value >= 0 (m)";
    return false;
  }
  if (!segmentation.IsValid(error)) {
    if (error) *error = "segmentation." + *error;
    return false;
  }
  if (!silhouette.IsValid(error)) {
    if (error) *error = "silhouette." + *error;
    return false;
  }
  return true;
}

int SampleScanColors(const PinholeCamera& cam, const Distortion& distortion,
                     const cv::Mat& color_bgr, Scan* scan) {
  if (color_bgr.type() != CV_8UC3 || color_bgr.cols != cam.width || color_bgr.rows != cam.height) {
    throw Error("colour sampling: expected a CV_8UC3 " + std::to_string(cam.width) + "x" +
                std::to_string(cam.height) + " colour image, found " +
                MatTypeName(color_bgr.type()) + " " + std::to_string(color_bgr.cols) + "x" +
                std::to_string(color_bgr.rows));
  }
  const int n = scan->size();
  scan->colors.resize(n, 3);
  scan->color_valid.resize(n);
  const Eigen::Matrix3d r = cam.world_to_camera.linear();
  const Eigen::Vector3d t = cam.world_to_camera.translation();
  const bool distorted = !distortion.IsZero();
  const double max_u = cam.width - 1, max_v = cam.height - 1;
  const int last_u0 = std::max(cam.width - 2, 0), last_v0 = std::max(cam.height - 2, 0);
  const int dx = cam.width > 1 ? 3 : 0;  // byte offset of the right neighbour
  const size_t dy = cam.height > 1 ? color_bgr.step[0] : 0;
  constexpr float kInv255 = 1.0f / 255.0f;
  const double* px = scan->points.col(0).data();
  const double* py = scan->points.col(1).data();
  const double* pz = scan->points.col(2).data();
  double* red = scan->colors.col(0).data();
  double* green = scan->colors.col(1).data();
  double* blue = scan->colors.col(2).data();
  int invalid = 0;
  // Local copies: the output arrays could otherwise alias them and force reloads.
  const double r00 = r(0, 0), r01 = r(0, 1), r02 = r(0, 2), r10 = r(1, 0), r11 = r(1, 1),
               r12 = r(1, 2), r20 = r(2, 0), r21 = r(2, 1), r22 = r(2, 2);
  const double tx = t.x(), ty = t.y(), tz = t.z();
  const double fx = cam.fx, fy = cam.fy, cx = cam.cx, cy = cam.cy;
  const uint8_t* image = color_bgr.data;
  const size_t row_step = color_bgr.step[0];
  uint8_t* valid = scan->color_valid.data();
  for (int i = 0; i < n; ++i) {
    const double x = r00 * px[i] + r01 * py[i] + r02 * pz[i] + tx;
    const double y = r10 * px[i] + r11 * py[i] + r12 * pz[i] + ty;
    const double z = r20 * px[i] + r21 * py[i] + r22 * pz[i] + tz;
    double u = -1, v = -1;
    if (z > 0) {
      const double inv_z = 1.0 / z;
      u = fx * x * inv_z + cx;
      v = fy * y * inv_z + cy;
      if (distorted) {
        const Eigen::Vector2d p = DistortPixel(cam, distortion, Eigen::Vector2d(u, v));
        u = p.x();
        v = p.y();
      }
    }
    if (!(u >= 0 && v >= 0 && u <= max_u && v <= max_v)) {
      red[i] = green[i] = blue[i] = 0;
      valid[i] = 0;
      ++invalid;
      continue;
    }
    const int u0 = std::min(static_cast<int>(u), last_u0);
    const int v0 = std::min(static_cast<int>(v), last_v0);
    const float a = static_cast<float>(u - u0), b = static_cast<float>(v - v0);
    const uint8_t* p00 = image + row_step * v0 + 3 * u0;
    const uint8_t* p10 = p00 + dy;
    const float w00 = (1 - a) * (1 - b), w01 = a * (1 - b), w10 = (1 - a) * b, w11 = a * b;
    auto tap = [&](int c) {
      return (w00 * p00[c] + w01 * p00[dx + c] + w10 * p10[c] + w11 * p10[dx + c]) * kInv255;
    };
    blue[i] = tap(0);  // BGR -> RGB
    green[i] = tap(1);
    red[i] = tap(2);
    valid[i] = 1;
  }
  return invalid;
}

Preprocessor::Preprocessor(const Calibration& calibration, const PreprocessOptions& options)
    : calibration_(calibration),
      options_(Checked(options)),
      background_(options.background),
      mesher_(calibration.depth, calibration.depth_distortion, options.mesh) {
  if (!(calibration.depth_scale > 0)) throw Error("calibration: expected a positive depth_scale");
  if (calibration.color.width <= 0 || calibration.color.height <= 0 ||
      !(calibration.color.fx > 0) || !(calibration.color.fy > 0)) {
    throw Error("calibration: colour camera: expected positive width, height, fx, fy");
  }
}

void Preprocessor::Train(const std::vector<cv::Mat>& background_depth) {
  if (options_.foreground == ForegroundMode::kSegment) {
    TrainWithoutBackground();
    return;
  }
  segmenter_.reset();
  for (size_t i = 0; i < background_depth.size(); ++i) {
    const cv::Mat& f = background_depth[i];
    if (f.cols != calibration_.depth.width || f.rows != calibration_.depth.height) {
      throw Error("background frame " + std::to_string(i) + ": expected the depth camera size " +
                  std::to_string(calibration_.depth.width) + "x" +
                  std::to_string(calibration_.depth.height) + ", found " + std::to_string(f.cols) +
                  "x" + std::to_string(f.rows));
    }
  }
  background_.Train(background_depth, calibration_.depth_scale);
}

void Preprocessor::TrainWithoutBackground() {
  if (options_.foreground != ForegroundMode::kBackground) {
    const Eigen::Vector3d up =
        calibration_.depth.world_to_camera.linear() * Eigen::Vector3d::UnitY();
    segmenter_ = std::make_unique<SubjectSegmenter>(mesher_.projector(), calibration_.depth_scale,
                                                    up, options_.segmentation);
    return;
  }
  background_.TrainEmpty(calibration_.depth.width, calibration_.depth.height,
                         calibration_.depth_scale);
}

void Preprocessor::SetScenePlanes(const std::vector<ScenePlane>& planes) {
  if (segmenter_) segmenter_->SetPlanes(planes);
}

void Preprocessor::ResetSubject() {
  if (segmenter_) segmenter_->ResetTracking();
}

void Preprocessor::Process(const Frame& frame, Scan* scan, PreprocessStats* stats) {
  if (!trained()) {
    throw Error(
        "preprocessing: the background model is not trained (call Train with empty-scene "
        "depth frames, or TrainWithoutBackground)");
  }
  const auto t0 = std::chrono::steady_clock::now();
  SegmentationStats segmentation;
  if (segmenter_) {
    segmenter_->Segment(frame.depth, &mask_, &segmentation);
  } else {
    background_.Classify(frame.depth, &mask_);
  }
  const auto t1 = std::chrono::steady_clock::now();
  DepthMeshStats mesh_stats;
  mesher_.Build(frame.depth, calibration_.depth_scale, mask_, scan, &mesh_stats);
  const auto t2 = std::chrono::steady_clock::now();
  const int invalid =
      SampleScanColors(calibration_.color, calibration_.color_distortion, frame.color, scan);
  const auto t3 = std::chrono::steady_clock::now();
  scan->silhouette.reset();
  if (options_.silhouette.enabled) {
    scan->silhouette = BuildSilhouetteMap(frame.depth, calibration_.depth_scale, mask_,
                                          calibration_.depth, options_.silhouette);
  }
  const auto t4 = std::chrono::steady_clock::now();
  if (stats) {
    stats->valid_depth_pixels = cv::countNonZero(frame.depth);
    stats->foreground_pixels = cv::countNonZero(mask_);
    stats->segmentation = segmentation;
    stats->mesh = mesh_stats;
    stats->color_invalid = invalid;
    stats->background_seconds = Seconds(t0, t1);
    stats->mesh_seconds = Seconds(t1, t2);
    stats->color_seconds = Seconds(t2, t3);
    stats->silhouette_seconds = Seconds(t3, t4);
    stats->silhouette_free_pixels = scan->silhouette ? scan->silhouette->free_pixels : 0;
    stats->total_seconds = Seconds(t0, t4);
  }
}

}  // namespace artex
