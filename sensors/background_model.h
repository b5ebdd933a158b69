// Per-pixel background model of a static scene from empty-scene depth frames (paper sec. 2:
// "a background model is trained using depth frames of the empty scene to perform a foreground
// extraction in the depth image"). Each pixel keeps the median z_bg and the MAD of its valid
// samples. A measured depth z is foreground when it is valid, within [min_depth, max_depth] and
//   z < z_bg - max(min_foreground_distance, threshold_sigmas * sigma),
//   sigma = max(noise_sigma_at_1m * z_bg^2, kMadToSigma * MAD)      (Kinect: sigma ~ z^2),
// or, where the background was valid in fewer than min_valid_samples frames ("unknown
// background"), whenever it is valid and within [min_depth, max_depth].
#pragma once

#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace artex {

struct BackgroundModelOptions {
  // A pixel needs at least this many valid (non-zero) training samples to have a known
  // background; training requires at least this many frames.
  int min_valid_samples = 5;
  // Axial depth noise sigma at 1 m (m); the model uses noise_sigma_at_1m * z^2.
  double noise_sigma_at_1m = 0.0015;
  // Use the per-pixel MAD (scaled to a Gaussian sigma) when it exceeds the noise model.
  bool use_mad = true;
  // Foreground margin in sigmas and its lower bound (m).
  double threshold_sigmas = 4.0;
  double min_foreground_distance = 0.03;
  // Valid measurement range (m): depths outside are never foreground.
  double min_depth = 0.3;
  double max_depth = 4.0;
  // Morphological cleanup of the mask (square kernels of side 2r+1; 0 = off): an opening
  // removes speckle, a closing fills pinholes (closed pixels still need a valid depth).
  int opening_radius = 1;
  int closing_radius = 0;
  // Keep only the largest 8-connected foreground component (a single subject).
  bool keep_largest_component = false;

  bool IsValid(std::string* error) const;
};

class BackgroundModel {
 public:
  explicit BackgroundModel(const BackgroundModelOptions& options = BackgroundModelOptions());

  // frames: CV_16UC1 empty-scene depth images of one size, depth_scale units per metre.
  // Throws artex::Error for invalid options, too few frames, or mixed sizes/types.
  void Train(const std::vector<cv::Mat>& frames, double depth_scale);
  // No background knowledge: every pixel is "unknown background" (e.g. TUM data).
  void TrainEmpty(int width, int height, double depth_scale);
  bool trained() const { return !limit_.empty(); }

  // depth: CV_16UC1 of the trained size -> mask CV_8UC1 (255 = foreground). Throws
  // artex::Error for a wrong size or type, or when untrained.
  void Classify(const cv::Mat& depth, cv::Mat* mask);

  // CV_32FC1 (m): per-pixel background median (0 = unknown) and noise sigma.
  const cv::Mat& background_depth() const { return median_; }
  const cv::Mat& background_sigma() const { return sigma_; }
  // Fraction of pixels with a known background.
  double known_fraction() const { return known_fraction_; }
  const BackgroundModelOptions& options() const { return options_; }

 private:
  void FinishLimits(double depth_scale);

  BackgroundModelOptions options_;
  cv::Mat median_;  // CV_32FC1, m
  cv::Mat sigma_;   // CV_32FC1, m
  // CV_16UC1, integer depth units relative to min_units_: foreground iff
  // min_units_ <= d < min_units_ + limit (d = 0 never).
  cv::Mat limit_;
  uint16_t min_units_ = 1;  // ceil(min_depth), ceil(max_depth) in depth units, >= 1
  uint16_t max_units_ = 1;
  double known_fraction_ = 0;
  cv::Mat work_mask_, kernel_open_, kernel_close_, labels_, stats_, centroids_;
};

}  // namespace artex
