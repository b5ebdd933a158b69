// Texture quality against ground truth (issue "novel-view" measure): the textured model is
// rendered from held-out viewpoints and compared with the ground-truth render (true subject,
// true pose, true texture) on the pixels where both show the surface. PSNR over the BGR
// channels (8-bit peak), mean SSIM (Wang et al. 2004) of the grey images, and coverage: the
// fraction of the true visible surface that the model textures.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "render/camera.h"

namespace artex {

struct HeldOutViewOptions {
  // Viewpoints around the subject: the training (colour) camera rotated about the world up
  // axis through the target by each of these angles (degrees) and raised by `height` (m).
  std::vector<double> yaws_deg = {20.0, -20.0};
  double height = 0.4;
  int ssim_window = 11;     // Gaussian window side (odd, >= 3)
  double ssim_sigma = 1.5;  // Gaussian window sigma (pixels); > 0

  bool IsValid(std::string* error) const;
};

struct NovelViewQuality {
  double psnr_db = 0.0;   // over pixels textured in the model and covered by the truth
  double ssim = 0.0;      // mean SSIM over those pixels whose whole window lies in them
  double coverage = 0.0;  // compared pixels / pixels of the true surface
  int pixels = 0;         // compared pixels (summed over views)
  int views = 0;
};

// Held-out cameras for `training` (same intrinsics) looking at `target` (world), world up `up`.
std::vector<PinholeCamera> HeldOutCameras(const PinholeCamera& training,
                                          const Eigen::Vector3d& target, const Eigen::Vector3d& up,
                                          const HeldOutViewOptions& options);

// PSNR (dB, 8-bit peak) of two CV_8UC3 images over mask (CV_8UC1, nonzero = compared); +inf for
// identical pixels, NaN for an empty mask.
double MaskedPsnr(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask);
// Mean SSIM of the grey images over the pixels whose whole window lies in mask; NaN when none.
double MaskedSsim(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask, int window = 11,
                  double sigma = 1.5);

// Accumulates views: image/image_mask the model's render and its textured pixels, truth /
// truth_mask the ground-truth render and its surface pixels (all the same size). The result's
// PSNR pools the squared errors of all views, its SSIM is the pixel-weighted mean.
class NovelViewAccumulator {
 public:
  explicit NovelViewAccumulator(const HeldOutViewOptions& options) : options_(options) {}
  void Add(const cv::Mat& image, const cv::Mat& image_mask, const cv::Mat& truth,
           const cv::Mat& truth_mask);
  NovelViewQuality Result() const;

 private:
  HeldOutViewOptions options_;
  double squared_error_ = 0.0;
  double ssim_sum_ = 0.0;
  long ssim_pixels_ = 0;
  long compared_ = 0, truth_pixels_ = 0;
  int views_ = 0;
};

}  // namespace artex
