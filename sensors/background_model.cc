#include "sensors/background_model.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <vector>

#include "models/error.h"
#include "sensors/image_io.h"

namespace artex {
namespace {
// MAD -> standard deviation of a Gaussian.
constexpr double kMadToSigma = 1.4826;
}  // namespace

bool BackgroundModelOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = "background." + m;
    return false;
  };
  if (min_valid_samples < 1) return fail("min_valid_samples: expected >= 1");
  if (!(noise_sigma_at_1m >= 0)) return fail("noise_sigma_at_1m: expected >= 0");
  if (!(threshold_sigmas >= 0)) return fail("threshold_sigmas: expected >= 0");
  if (!(min_foreground_distance >= 0)) return fail("min_foreground_distance: expected >= 0");
  if (!(min_depth >= 0) || !(max_depth > min_depth)) {
    return fail("min_depth/max_depth: expected 0 <= min_depth < max_depth");
  }
  if (opening_radius < 0 || closing_radius < 0)
    return fail("opening/closing_radius: expected >= 0");
  return true;
}

BackgroundModel::BackgroundModel(const BackgroundModelOptions& options) : options_(options) {
  std::string error;
  if (!options_.IsValid(&error)) throw Error(error);
  if (options_.opening_radius > 0) {
    const int s = 2 * options_.opening_radius + 1;
    kernel_open_ = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(s, s));
  }
  if (options_.closing_radius > 0) {
    const int s = 2 * options_.closing_radius + 1;
    kernel_close_ = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(s, s));
  }
}

void BackgroundModel::Train(const std::vector<cv::Mat>& frames, double depth_scale) {
  if (!(depth_scale > 0)) throw Error("background model: expected a positive depth_scale");
  if (static_cast<int>(frames.size()) < options_.min_valid_samples) {
    throw Error("background model: expected at least background.min_valid_samples = " +
                std::to_string(options_.min_valid_samples) + " empty-scene depth frames, found " +
                std::to_string(frames.size()));
  }
  const int w = frames[0].cols, h = frames[0].rows;
  for (size_t i = 0; i < frames.size(); ++i) {
    if (frames[i].type() != CV_16UC1 || frames[i].cols != w || frames[i].rows != h) {
      throw Error("background model: frame " + std::to_string(i) + ": expected CV_16UC1 " +
                  std::to_string(w) + "x" + std::to_string(h) + ", found " +
                  MatTypeName(frames[i].type()) + " " + std::to_string(frames[i].cols) + "x" +
                  std::to_string(frames[i].rows));
    }
  }
  median_.create(h, w, CV_32FC1);
  sigma_.create(h, w, CV_32FC1);
  const float inv_scale = static_cast<float>(1.0 / depth_scale);
  // Rows in parallel (each pixel is its own: the same model with any number of threads); a
  // run's set-up waits for it.
  std::vector<int> known_in_row(h, 0);
  tbb::parallel_for(tbb::blocked_range<int>(0, h, 8), [&](const tbb::blocked_range<int>& rows) {
    std::vector<uint16_t> samples(frames.size());
    std::vector<float> deviations(frames.size());
    for (int y = rows.begin(); y < rows.end(); ++y) {
      float* med = median_.ptr<float>(y);
      float* sig = sigma_.ptr<float>(y);
      for (int x = 0; x < w; ++x) {
        int n = 0;
        for (const cv::Mat& f : frames) {
          const uint16_t d = f.ptr<uint16_t>(y)[x];
          if (d != 0) samples[n++] = d;
        }
        if (n < options_.min_valid_samples) {
          med[x] = 0;
          sig[x] = 0;
          continue;
        }
        std::sort(samples.begin(), samples.begin() + n);
        const float m = (n % 2 == 1)
                            ? samples[n / 2]
                            : 0.5f * (static_cast<float>(samples[n / 2 - 1]) + samples[n / 2]);
        for (int k = 0; k < n; ++k) deviations[k] = std::abs(static_cast<float>(samples[k]) - m);
        std::sort(deviations.begin(), deviations.begin() + n);
        const float mad =
            (n % 2 == 1) ? deviations[n / 2] : 0.5f * (deviations[n / 2 - 1] + deviations[n / 2]);
        const double z = m * inv_scale;
        double s = options_.noise_sigma_at_1m * z * z;
        if (options_.use_mad) s = std::max(s, kMadToSigma * mad * inv_scale);
        med[x] = static_cast<float>(z);
        sig[x] = static_cast<float>(s);
        ++known_in_row[y];
      }
    }
  });
  long long known = 0;
  for (int k : known_in_row) known += k;
  known_fraction_ = static_cast<double>(known) / (static_cast<double>(w) * h);
  FinishLimits(depth_scale);
}

void BackgroundModel::TrainEmpty(int width, int height, double depth_scale) {
  if (width <= 0 || height <= 0 || !(depth_scale > 0)) {
    throw Error("background model: expected a positive size and depth_scale");
  }
  median_ = cv::Mat::zeros(height, width, CV_32FC1);
  sigma_ = cv::Mat::zeros(height, width, CV_32FC1);
  known_fraction_ = 0;
  FinishLimits(depth_scale);
}

namespace {
// For integer d >= 0: d < x  <=>  d < ceil(x); clamped to [1, 65535] (0 = missing depth).
uint16_t IntegerLimit(double x) {
  return static_cast<uint16_t>(std::min(65535.0, std::max(1.0, std::ceil(x))));
}
}  // namespace

void BackgroundModel::FinishLimits(double depth_scale) {
  limit_.create(median_.size(), CV_16UC1);
  const double max_units = options_.max_depth * depth_scale;
  min_units_ = IntegerLimit(options_.min_depth * depth_scale);
  max_units_ = IntegerLimit(max_units);
  for (int y = 0; y < median_.rows; ++y) {
    const float* med = median_.ptr<float>(y);
    const float* sig = sigma_.ptr<float>(y);
    uint16_t* lim = limit_.ptr<uint16_t>(y);
    for (int x = 0; x < median_.cols; ++x) {
      double limit = max_units;
      if (med[x] > 0) {
        const double margin =
            std::max(options_.min_foreground_distance, options_.threshold_sigmas * sig[x]);
        limit = std::min(limit, (med[x] - margin) * depth_scale);
      }
      // Stored relative to min_units_: foreground iff (uint16)(d - min_units_) < lim, one
      // unsigned comparison (d < min_units_, including d = 0, wraps to a large value).
      lim[x] = static_cast<uint16_t>(std::max<int>(IntegerLimit(limit) - min_units_, 0));
    }
  }
}

void BackgroundModel::Classify(const cv::Mat& depth, cv::Mat* mask) {
  if (!trained()) throw Error("background model: Classify called before Train");
  if (depth.type() != CV_16UC1 || depth.size() != limit_.size()) {
    throw Error("background model: expected a CV_16UC1 " + std::to_string(limit_.cols) + "x" +
                std::to_string(limit_.rows) + " depth image, found " + MatTypeName(depth.type()) +
                " " + std::to_string(depth.cols) + "x" + std::to_string(depth.rows));
  }
  mask->create(depth.size(), CV_8UC1);
  const uint16_t lo = min_units_;  // >= 1: 0 = missing depth
  for (int y = 0; y < depth.rows; ++y) {
    const uint16_t* d = depth.ptr<uint16_t>(y);
    const uint16_t* lim = limit_.ptr<uint16_t>(y);
    uint8_t* m = mask->ptr<uint8_t>(y);
    for (int x = 0; x < depth.cols; ++x) {
      m[x] = static_cast<uint16_t>(d[x] - lo) < lim[x] ? 255 : 0;
    }
  }
  if (!kernel_open_.empty()) cv::morphologyEx(*mask, *mask, cv::MORPH_OPEN, kernel_open_);
  if (!kernel_close_.empty()) {
    cv::morphologyEx(*mask, *mask, cv::MORPH_CLOSE, kernel_close_);
    // Closed pixels still need a valid depth in range.
    for (int y = 0; y < depth.rows; ++y) {
      const uint16_t* d = depth.ptr<uint16_t>(y);
      uint8_t* m = mask->ptr<uint8_t>(y);
      for (int x = 0; x < depth.cols; ++x) {
        if (m[x] && !(d[x] >= lo && d[x] < max_units_)) m[x] = 0;
      }
    }
  }
  if (options_.keep_largest_component) {
    const int n = cv::connectedComponentsWithStats(*mask, labels_, stats_, centroids_, 8, CV_32S);
    if (n > 2) {
      int best = 1;
      for (int l = 2; l < n; ++l) {
        if (stats_.at<int>(l, cv::CC_STAT_AREA) > stats_.at<int>(best, cv::CC_STAT_AREA)) best = l;
      }
      for (int y = 0; y < mask->rows; ++y) {
        const int* lab = labels_.ptr<int>(y);
        uint8_t* m = mask->ptr<uint8_t>(y);
        for (int x = 0; x < mask->cols; ++x) m[x] = lab[x] == best ? 255 : 0;
      }
    }
  }
}

}  // namespace artex
