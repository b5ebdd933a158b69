// Novel-view texture measures: PSNR and SSIM on known images, the accumulator's pooling and
// coverage, and held-out cameras that look at the target.
#include "texture/texture_quality.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>

#include "models/error.h"

namespace artex {
namespace {

cv::Mat Pattern(int w, int h) {
  cv::Mat a(h, w, CV_8UC3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      a.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<uchar>(100 + 80 * std::sin(x / 5.0)),
                                        static_cast<uchar>(100 + 80 * std::cos(y / 7.0)), 90);
  return a;
}

TEST(TextureQualityTest, PsnrOfAConstantError) {
  const cv::Mat a = Pattern(64, 48);
  cv::Mat b = a + cv::Scalar(4, 4, 4);
  cv::Mat mask(48, 64, CV_8UC1, cv::Scalar(255));
  EXPECT_NEAR(MaskedPsnr(a, b, mask), 20.0 * std::log10(255.0 / 4.0), 1e-9);
  EXPECT_TRUE(std::isinf(MaskedPsnr(a, a, mask)));
  // Pixels outside the mask do not count.
  cv::Mat c = a.clone();
  c(cv::Rect(0, 0, 10, 10)).setTo(cv::Scalar(0, 0, 0));
  mask(cv::Rect(0, 0, 10, 10)).setTo(0);
  EXPECT_TRUE(std::isinf(MaskedPsnr(a, c, mask)));
  EXPECT_TRUE(std::isnan(MaskedPsnr(a, c, cv::Mat(48, 64, CV_8UC1, cv::Scalar(0)))));
  EXPECT_THROW(MaskedPsnr(a, Pattern(32, 48), mask), Error);
}

TEST(TextureQualityTest, SsimIsOneForEqualImagesAndDropsWithNoise) {
  const cv::Mat a = Pattern(80, 60);
  const cv::Mat mask(60, 80, CV_8UC1, cv::Scalar(255));
  EXPECT_NEAR(MaskedSsim(a, a, mask), 1.0, 1e-12);
  cv::Mat noise(60, 80, CV_8UC3), b;
  cv::randn(noise, cv::Scalar::all(0), cv::Scalar::all(20));
  cv::add(a, noise, b, cv::noArray(), CV_8UC3);
  const double noisy = MaskedSsim(a, b, mask);
  EXPECT_LT(noisy, 0.9);
  EXPECT_GT(noisy, 0.0);
}

// The SSIM of the whole image, filtered everywhere (the definition MaskedSsim restricts to the
// mask's bounding box).
double WholeImageSsim(const cv::Mat& a_bgr, const cv::Mat& b_bgr, const cv::Mat& mask, int side,
                      double sigma) {
  cv::Mat a, b;
  cv::cvtColor(a_bgr, a, cv::COLOR_BGR2GRAY);
  cv::cvtColor(b_bgr, b, cv::COLOR_BGR2GRAY);
  a.convertTo(a, CV_64F);
  b.convertTo(b, CV_64F);
  const cv::Size window(side, side);
  const double c1 = std::pow(0.01 * 255, 2), c2 = std::pow(0.03 * 255, 2);
  cv::Mat mu_a, mu_b, aa, bb, ab, inner;
  cv::GaussianBlur(a, mu_a, window, sigma);
  cv::GaussianBlur(b, mu_b, window, sigma);
  cv::GaussianBlur(a.mul(a), aa, window, sigma);
  cv::GaussianBlur(b.mul(b), bb, window, sigma);
  cv::GaussianBlur(a.mul(b), ab, window, sigma);
  cv::erode(mask, inner, cv::Mat::ones(window, CV_8UC1), cv::Point(-1, -1), 1, cv::BORDER_CONSTANT,
            cv::Scalar(0));
  double sum = 0.0;
  long n = 0;
  for (int y = 0; y < a.rows; ++y) {
    for (int x = 0; x < a.cols; ++x) {
      if (!inner.at<uint8_t>(y, x)) continue;
      const double ma = mu_a.at<double>(y, x), mb = mu_b.at<double>(y, x);
      const double va = aa.at<double>(y, x) - ma * ma, vb = bb.at<double>(y, x) - mb * mb;
      const double cov = ab.at<double>(y, x) - ma * mb;
      sum += ((2 * ma * mb + c1) * (2 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2));
      ++n;
    }
  }
  return sum / n;
}

TEST(TextureQualityTest, SsimOfTheMaskBoxEqualsTheWholeImages) {
  const cv::Mat a = Pattern(160, 120);
  cv::Mat noise(120, 160, CV_8UC3), b;
  cv::randn(noise, cv::Scalar::all(0), cv::Scalar::all(25));
  cv::add(a, noise, b, cv::noArray(), CV_8UC3);
  // A blob in the middle, one touching the image's corner, and both.
  cv::Mat middle(120, 160, CV_8UC1, cv::Scalar(0)), corner = middle.clone();
  cv::ellipse(middle, cv::Point(80, 60), cv::Size(30, 20), 15, 0, 360, cv::Scalar(255), -1);
  cv::circle(corner, cv::Point(3, 118), 25, cv::Scalar(255), -1);
  cv::Mat both = middle | corner;
  for (const cv::Mat* mask : std::initializer_list<const cv::Mat*>{&middle, &corner, &both}) {
    for (int side : {3, 7, 11}) {
      const double expected = WholeImageSsim(a, b, *mask, side, 1.5);
      EXPECT_LT(expected, 0.95);
      EXPECT_EQ(MaskedSsim(a, b, *mask, side, 1.5), expected) << "window " << side;
    }
  }
  EXPECT_TRUE(std::isnan(MaskedSsim(a, b, cv::Mat(120, 160, CV_8UC1, cv::Scalar(0)))));
}

TEST(TextureQualityTest, AccumulatorPoolsViewsAndMeasuresCoverage) {
  HeldOutViewOptions o;
  NovelViewAccumulator acc(o);
  const cv::Mat a = Pattern(40, 40);
  cv::Mat truth_mask(40, 40, CV_8UC1, cv::Scalar(255));
  cv::Mat half = truth_mask.clone();
  half(cv::Rect(0, 0, 20, 40)).setTo(0);
  acc.Add(a, half, a + cv::Scalar(2, 2, 2), truth_mask);  // half the surface, error 2
  acc.Add(a, truth_mask, a, truth_mask);                  // all of it, no error
  const NovelViewQuality q = acc.Result();
  EXPECT_EQ(q.views, 2);
  EXPECT_EQ(q.pixels, 800 + 1600);
  EXPECT_NEAR(q.coverage, 2400.0 / 3200.0, 1e-12);
  // Pooled MSE = 4 * 800 / 2400.
  EXPECT_NEAR(q.psnr_db, 10.0 * std::log10(255.0 * 255.0 / (4.0 * 800 / 2400)), 1e-9);
}

TEST(TextureQualityTest, HeldOutCamerasLookAtTheTarget) {
  PinholeCamera training;
  const Eigen::Vector3d target(0.0, 1.0, 0.0);
  training.world_to_camera =
      PinholeCamera::LookAt(Eigen::Vector3d(0.0, 1.0, 3.0), target, Eigen::Vector3d::UnitY());
  HeldOutViewOptions o;
  o.yaws_deg = {30.0, -45.0};
  const auto cameras = HeldOutCameras(training, target, Eigen::Vector3d::UnitY(), o);
  ASSERT_EQ(cameras.size(), 2u);
  for (std::size_t k = 0; k < cameras.size(); ++k) {
    const Eigen::Vector3d in_camera = cameras[k].world_to_camera * target;
    EXPECT_NEAR(in_camera.x(), 0.0, 1e-9);
    EXPECT_NEAR(in_camera.y(), 0.0, 1e-9);
    EXPECT_GT(in_camera.z(), 0.0);
    EXPECT_NEAR(cameras[k].Center().y(), 1.0 + o.height, 1e-9);
    const double yaw = std::atan2(cameras[k].Center().x(), cameras[k].Center().z()) * 180 / M_PI;
    EXPECT_NEAR(yaw, o.yaws_deg[k], 1e-9);
  }
  o.ssim_window = 4;
  std::string why;
  EXPECT_FALSE(o.IsValid(&why));
}

}  // namespace
}  // namespace artex
