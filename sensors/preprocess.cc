#include "sensors/preprocess.h"

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

bool PreprocessOptions::IsValid(std::string* error) const {
  return background.IsValid(error) && mesh.IsValid(error);
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
  constexpr double kInv255 = 1.0 / 255.0;
  int invalid = 0;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d c = r * scan->points.row(i).transpose() + t;
    double u = -1, v = -1;
    if (c.z() > 0) {
      u = cam.fx * c.x() / c.z() + cam.cx;
      v = cam.fy * c.y() / c.z() + cam.cy;
      if (distorted) {
        const Eigen::Vector2d p = DistortPixel(cam, distortion, Eigen::Vector2d(u, v));
        u = p.x();
        v = p.y();
      }
    }
    if (!(u >= 0 && v >= 0 && u <= max_u && v <= max_v)) {
      scan->colors.row(i).setZero();
      scan->color_valid[i] = 0;
      ++invalid;
      continue;
    }
    const int u0 = std::min(static_cast<int>(u), cam.width - 2 < 0 ? 0 : cam.width - 2);
    const int v0 = std::min(static_cast<int>(v), cam.height - 2 < 0 ? 0 : cam.height - 2);
    const int u1 = std::min(u0 + 1, cam.width - 1), v1 = std::min(v0 + 1, cam.height - 1);
    const double a = u - u0, b = v - v0;
    const uint8_t* p00 = color_bgr.ptr<uint8_t>(v0) + 3 * u0;
    const uint8_t* p01 = color_bgr.ptr<uint8_t>(v0) + 3 * u1;
    const uint8_t* p10 = color_bgr.ptr<uint8_t>(v1) + 3 * u0;
    const uint8_t* p11 = color_bgr.ptr<uint8_t>(v1) + 3 * u1;
    const double w00 = (1 - a) * (1 - b), w01 = a * (1 - b), w10 = (1 - a) * b, w11 = a * b;
    for (int k = 0; k < 3; ++k) {  // BGR -> RGB
      const int s = 2 - k;
      scan->colors(i, k) = (w00 * p00[s] + w01 * p01[s] + w10 * p10[s] + w11 * p11[s]) * kInv255;
    }
    scan->color_valid[i] = 1;
  }
  return invalid;
}

Preprocessor::Preprocessor(const Calibration& calibration, const PreprocessOptions& options)
    : calibration_(calibration),
      options_(Checked(options)),
      background_(options.background),
      mesher_(calibration.depth, calibration.depth_distortion, options.mesh) {
  if (!(calibration.depth_scale > 0)) throw Error("calibration: expected a positive depth_scale");
  if (calibration.color.width <= 0 || calibration.color.height <= 0 || !(calibration.color.fx > 0) ||
      !(calibration.color.fy > 0)) {
    throw Error("calibration: colour camera: expected positive width, height, fx, fy");
  }
}

void Preprocessor::Train(const std::vector<cv::Mat>& background_depth) {
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
  background_.TrainEmpty(calibration_.depth.width, calibration_.depth.height,
                         calibration_.depth_scale);
}

void Preprocessor::Process(const Frame& frame, Scan* scan, PreprocessStats* stats) {
  if (!trained()) {
    throw Error("preprocessing: the background model is not trained (call Train with empty-scene "
                "depth frames, or TrainWithoutBackground)");
  }
  const auto t0 = std::chrono::steady_clock::now();
  background_.Classify(frame.depth, &mask_);
  const auto t1 = std::chrono::steady_clock::now();
  DepthMeshStats mesh_stats;
  mesher_.Build(frame.depth, calibration_.depth_scale, mask_, scan, &mesh_stats);
  const auto t2 = std::chrono::steady_clock::now();
  const int invalid = SampleScanColors(calibration_.color, calibration_.color_distortion,
                                       frame.color, scan);
  const auto t3 = std::chrono::steady_clock::now();
  if (stats) {
    stats->valid_depth_pixels = cv::countNonZero(frame.depth);
    stats->foreground_pixels = cv::countNonZero(mask_);
    stats->mesh = mesh_stats;
    stats->color_invalid = invalid;
    stats->background_seconds = Seconds(t0, t1);
    stats->mesh_seconds = Seconds(t1, t2);
    stats->color_seconds = Seconds(t2, t3);
    stats->total_seconds = Seconds(t0, t3);
  }
}

}  // namespace artex
