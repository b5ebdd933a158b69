#include "texture/texture_quality.h"

#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "models/error.h"

namespace artex {
namespace {

void CheckSameSize(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask, const char* what) {
  if (a.type() != CV_8UC3 || b.type() != CV_8UC3 || mask.type() != CV_8UC1 ||
      a.size() != b.size() || a.size() != mask.size()) {
    std::ostringstream msg;
    msg << what << ": expected two CV_8UC3 images and a CV_8UC1 mask of one size, found " << a.cols
        << "x" << a.rows << ", " << b.cols << "x" << b.rows << ", " << mask.cols << "x"
        << mask.rows;
    throw Error(msg.str());
  }
}

double SquaredError(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask, long* n) {
  double se = 0.0;
  *n = 0;
  for (int y = 0; y < a.rows; ++y) {
    const auto* pa = a.ptr<cv::Vec3b>(y);
    const auto* pb = b.ptr<cv::Vec3b>(y);
    const auto* pm = mask.ptr<uint8_t>(y);
    for (int x = 0; x < a.cols; ++x) {
      if (!pm[x]) continue;
      ++*n;
      for (int c = 0; c < 3; ++c) {
        const double d = static_cast<double>(pa[x][c]) - pb[x][c];
        se += d * d;
      }
    }
  }
  return se;
}

// Sum of SSIM over the inner pixels of mask and their count. Only the inner pixels' bounding
// box, grown by the window's radius, is filtered: a pixel's Gaussian windows then read the same
// pixels as over the whole image (the grown box is clipped at the image border, where the
// border rule applies as before), so the sum is the whole image's, at the cost of the box.
double SsimSum(const cv::Mat& a_bgr, const cv::Mat& b_bgr, const cv::Mat& mask, int window_side,
               double sigma, long* n) {
  const cv::Size window(window_side, window_side);
  *n = 0;
  cv::Mat inner;
  cv::erode(mask, inner, cv::Mat::ones(window, CV_8UC1), cv::Point(-1, -1), 1, cv::BORDER_CONSTANT,
            cv::Scalar(0));
  const cv::Rect box = cv::boundingRect(inner);
  if (box.empty()) return 0.0;
  const int radius = window_side / 2;
  const cv::Rect grown =
      cv::Rect(box.x - radius, box.y - radius, box.width + 2 * radius, box.height + 2 * radius) &
      cv::Rect(0, 0, a_bgr.cols, a_bgr.rows);
  const cv::Rect& work = grown;
  cv::Mat a, b;
  cv::cvtColor(a_bgr(work), a, cv::COLOR_BGR2GRAY);
  cv::cvtColor(b_bgr(work), b, cv::COLOR_BGR2GRAY);
  a.convertTo(a, CV_64F);
  b.convertTo(b, CV_64F);
  const double c1 = std::pow(0.01 * 255, 2), c2 = std::pow(0.03 * 255, 2);
  cv::Mat mu_a, mu_b, aa, bb, ab;
  cv::GaussianBlur(a, mu_a, window, sigma);
  cv::GaussianBlur(b, mu_b, window, sigma);
  cv::GaussianBlur(a.mul(a), aa, window, sigma);
  cv::GaussianBlur(b.mul(b), bb, window, sigma);
  cv::GaussianBlur(a.mul(b), ab, window, sigma);
  double sum = 0.0;
  for (int y = box.y; y < box.y + box.height; ++y) {
    const uint8_t* in = inner.ptr<uint8_t>(y);
    const int wy = y - work.y;
    const double* pma = mu_a.ptr<double>(wy);
    const double* pmb = mu_b.ptr<double>(wy);
    const double* paa = aa.ptr<double>(wy);
    const double* pbb = bb.ptr<double>(wy);
    const double* pab = ab.ptr<double>(wy);
    for (int x = box.x; x < box.x + box.width; ++x) {
      if (!in[x]) continue;
      const int wx = x - work.x;
      const double ma = pma[wx], mb = pmb[wx];
      const double va = paa[wx] - ma * ma, vb = pbb[wx] - mb * mb;
      const double cov = pab[wx] - ma * mb;
      sum += ((2 * ma * mb + c1) * (2 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2));
      ++*n;
    }
  }
  return sum;
}

}  // namespace

bool HeldOutViewOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (yaws_deg.empty())
    msg << "held-out views: expected at least one yaw, found none";
  else if (!std::isfinite(height))
    msg << "held-out views: height: expected a finite value, found " << height;
  else if (ssim_window < 3 || ssim_window % 2 == 0)
    msg << "held-out views: ssim_window: expected an odd value >= 3, found " << ssim_window;
  else if (!(ssim_sigma > 0.0))
    msg << "held-out views: ssim_sigma: expected > 0, found " << ssim_sigma;
  for (double y : yaws_deg)
    if (!std::isfinite(y) && msg.str().empty()) msg << "held-out views: non-finite yaw " << y;
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

std::vector<PinholeCamera> HeldOutCameras(const PinholeCamera& training,
                                          const Eigen::Vector3d& target, const Eigen::Vector3d& up,
                                          const HeldOutViewOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(why);
  const Eigen::Vector3d axis = up.normalized();
  std::vector<PinholeCamera> cameras;
  for (double yaw : options.yaws_deg) {
    PinholeCamera camera = training;
    const Eigen::Vector3d eye =
        Eigen::AngleAxisd(yaw * M_PI / 180.0, axis) * (training.Center() - target) + target +
        options.height * axis;
    camera.world_to_camera = PinholeCamera::LookAt(eye, target, axis);
    cameras.push_back(camera);
  }
  return cameras;
}

double MaskedPsnr(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask) {
  CheckSameSize(a, b, mask, "MaskedPsnr");
  long n = 0;
  const double se = SquaredError(a, b, mask, &n);
  if (n == 0) return std::numeric_limits<double>::quiet_NaN();
  if (se == 0.0) return std::numeric_limits<double>::infinity();
  return 10.0 * std::log10(255.0 * 255.0 / (se / (3.0 * n)));
}

double MaskedSsim(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask, int window,
                  double sigma) {
  CheckSameSize(a, b, mask, "MaskedSsim");
  long n = 0;
  const double sum = SsimSum(a, b, mask, window, sigma, &n);
  return n > 0 ? sum / n : std::numeric_limits<double>::quiet_NaN();
}

void NovelViewAccumulator::Add(const cv::Mat& image, const cv::Mat& image_mask,
                               const cv::Mat& truth, const cv::Mat& truth_mask) {
  CheckSameSize(image, truth, image_mask, "NovelViewAccumulator");
  CheckSameSize(image, truth, truth_mask, "NovelViewAccumulator");
  cv::Mat both;
  cv::bitwise_and(image_mask, truth_mask, both);
  long n = 0, ns = 0;
  squared_error_ += SquaredError(image, truth, both, &n);
  ssim_sum_ += SsimSum(image, truth, both, options_.ssim_window, options_.ssim_sigma, &ns);
  ssim_pixels_ += ns;
  compared_ += n;
  truth_pixels_ += cv::countNonZero(truth_mask);
  ++views_;
}

NovelViewQuality NovelViewAccumulator::Result() const {
  NovelViewQuality q;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  q.views = views_;
  q.pixels = static_cast<int>(compared_);
  q.coverage = truth_pixels_ > 0 ? static_cast<double>(compared_) / truth_pixels_ : nan;
  if (compared_ == 0) {
    q.psnr_db = nan;
  } else if (squared_error_ == 0.0) {
    q.psnr_db = std::numeric_limits<double>::infinity();
  } else {
    q.psnr_db = 10.0 * std::log10(255.0 * 255.0 / (squared_error_ / (3.0 * compared_)));
  }
  q.ssim = ssim_pixels_ > 0 ? ssim_sum_ / ssim_pixels_ : nan;
  return q;
}

}  // namespace artex
