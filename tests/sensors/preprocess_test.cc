#include "sensors/preprocess.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <random>

#include "models/error.h"
#include "sensors/background_model.h"
#include "sensors/depth_mesh.h"

namespace artex {
namespace {

// ---------------------------------------------------------------------------------------------
// Synthetic scene: a wall and a floor, optionally an ellipsoidal subject, seen by a portrait
// Kinect-like depth camera (480 x 640) with noise sigma = 1.5 mm z^2, disparity quantisation
// (1/8 pixel, f b = 43.5 px m), random dropouts, and depth in millimetres.

constexpr double kSigmaAt1m = 0.0015;
constexpr double kFocalBaseline = 43.5;  // px m
constexpr double kSubpixel = 8.0;
constexpr double kDropout = 0.01;
const Eigen::Vector3d kSubjectCentre(0.0, 1.0, 0.5);   // 2.5 m in front of the camera
const Eigen::Vector3d kSubjectRadii(0.35, 0.85, 0.2);  // bottom 0.15 m above the floor
constexpr double kWallZ = -0.5;                        // 3.5 m from the camera

PinholeCamera DepthCamera() {
  PinholeCamera c;
  c.width = 480;
  c.height = 640;
  c.fx = c.fy = 575.0;
  c.cx = 239.5;
  c.cy = 319.5;
  c.world_to_camera = PinholeCamera::LookAt(Eigen::Vector3d(0, 1.0, 3.0),
                                            Eigen::Vector3d(0, 1.0, 0), Eigen::Vector3d::UnitY());
  return c;
}

Calibration Rig() {
  Calibration cal;
  cal.depth = DepthCamera();
  cal.color.width = 400;
  cal.color.height = 508;
  cal.color.fx = cal.color.fy = 460.0;
  cal.color.cx = 199.5;
  cal.color.cy = 253.5;
  cal.color.world_to_camera = PinholeCamera::LookAt(
      Eigen::Vector3d(0.05, 1.1, 3.0), Eigen::Vector3d(0, 1.0, 0), Eigen::Vector3d::UnitY());
  cal.depth_scale = 1000.0;
  return cal;
}

// Ray (world origin o, direction d) -> nearest positive hit parameter, or -1.
double HitEllipsoid(const Eigen::Vector3d& o, const Eigen::Vector3d& d) {
  const Eigen::Vector3d oc = (o - kSubjectCentre).cwiseQuotient(kSubjectRadii);
  const Eigen::Vector3d dc = d.cwiseQuotient(kSubjectRadii);
  const double a = dc.squaredNorm(), b = 2 * oc.dot(dc), c = oc.squaredNorm() - 1;
  const double disc = b * b - 4 * a * c;
  if (disc < 0) return -1;
  const double t = (-b - std::sqrt(disc)) / (2 * a);
  return t > 0 ? t : -1;
}

// True depth (m along the optical axis) per pixel and whether the subject is seen there.
void RenderTruth(const PinholeCamera& cam, bool with_subject, cv::Mat* z, cv::Mat* subject) {
  *z = cv::Mat(cam.height, cam.width, CV_64FC1);
  *subject = cv::Mat::zeros(cam.height, cam.width, CV_8UC1);
  const Eigen::Isometry3d c2w = cam.world_to_camera.inverse();
  const Eigen::Vector3d o = c2w.translation();
  for (int v = 0; v < cam.height; ++v) {
    for (int u = 0; u < cam.width; ++u) {
      // Camera-frame direction with z = 1, so the hit parameter is the depth.
      const Eigen::Vector3d d =
          c2w.linear() * Eigen::Vector3d((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0);
      double t = (kWallZ - o.z()) / d.z();
      if (d.y() < 0) t = std::min(t, -o.y() / d.y());  // floor y = 0
      if (with_subject) {
        const double ts = HitEllipsoid(o, d);
        if (ts > 0 && ts < t) {
          t = ts;
          subject->at<uint8_t>(v, u) = 255;
        }
      }
      z->at<double>(v, u) = t;
    }
  }
}

cv::Mat Measure(const cv::Mat& z, std::mt19937_64* rng) {
  std::normal_distribution<double> noise(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  cv::Mat out(z.size(), CV_16UC1);
  for (int v = 0; v < z.rows; ++v) {
    for (int u = 0; u < z.cols; ++u) {
      const double t = z.at<double>(v, u);
      const double noisy = t + kSigmaAt1m * t * t * noise(*rng);
      const double disparity = std::round(kSubpixel * kFocalBaseline / noisy) / kSubpixel;
      const double q = kFocalBaseline / disparity;
      out.at<uint16_t>(v, u) =
          uniform(*rng) < kDropout ? 0 : static_cast<uint16_t>(std::lround(q * 1000));
    }
  }
  return out;
}

// ---------------------------------------------------------------------------------------------

TEST(BackgroundModelTest, SeparatesSubjectFromSceneAtDefaultNoise) {
  const PinholeCamera cam = DepthCamera();
  std::mt19937_64 rng(20140527);
  cv::Mat z_empty, z_subject, none, subject;
  RenderTruth(cam, false, &z_empty, &none);
  RenderTruth(cam, true, &z_subject, &subject);
  std::vector<cv::Mat> background;
  for (int i = 0; i < 20; ++i) background.push_back(Measure(z_empty, &rng));
  const cv::Mat frame = Measure(z_subject, &rng);

  BackgroundModel model;  // default options
  model.Train(background, 1000.0);
  EXPECT_GT(model.known_fraction(), 0.99);
  cv::Mat mask;
  model.Classify(frame, &mask);

  int fg = 0, fg_kept = 0, bg = 0, bg_through = 0;
  for (int v = 0; v < cam.height; ++v) {
    for (int u = 0; u < cam.width; ++u) {
      if (frame.at<uint16_t>(v, u) == 0) continue;  // dropout: nothing to classify
      const bool is_subject = subject.at<uint8_t>(v, u) != 0;
      const bool said = mask.at<uint8_t>(v, u) != 0;
      fg += is_subject;
      fg_kept += is_subject && said;
      bg += !is_subject;
      bg_through += !is_subject && said;
    }
  }
  ::testing::Test::RecordProperty("subject_pixels", fg);
  ::testing::Test::RecordProperty("subject_kept", fg_kept);
  ::testing::Test::RecordProperty("background_pixels", bg);
  ::testing::Test::RecordProperty("background_through", bg_through);
  ASSERT_GT(fg, 0.13 * cam.width * cam.height);  // a realistic subject size
  EXPECT_GE(static_cast<double>(fg_kept) / fg, 0.99) << fg_kept << " of " << fg;
  EXPECT_LE(static_cast<double>(bg_through) / bg, 0.005) << bg_through << " of " << bg;

  // Without any margin (threshold 0) the same scene lets noise through: the test can fail.
  BackgroundModelOptions loose;
  loose.threshold_sigmas = 0;
  loose.min_foreground_distance = 0;
  loose.opening_radius = 0;
  BackgroundModel bad(loose);
  bad.Train(background, 1000.0);
  bad.Classify(frame, &mask);
  int loose_through = 0;
  for (int v = 0; v < cam.height; ++v) {
    for (int u = 0; u < cam.width; ++u) {
      loose_through +=
          frame.at<uint16_t>(v, u) != 0 && !subject.at<uint8_t>(v, u) && mask.at<uint8_t>(v, u);
    }
  }
  ::testing::Test::RecordProperty("background_through_without_margin", loose_through);
  EXPECT_GT(static_cast<double>(loose_through) / bg, 0.05);
}

// The model's rows are trained in parallel: the same medians, sigmas and known fraction with one
// thread as with every core.
TEST(BackgroundModelTest, TrainingIsTheSameOnOneThread) {
  const PinholeCamera cam = DepthCamera();
  std::mt19937_64 rng(7);
  cv::Mat z_empty, none;
  RenderTruth(cam, false, &z_empty, &none);
  std::vector<cv::Mat> background;
  for (int i = 0; i < 10; ++i) background.push_back(Measure(z_empty, &rng));
  for (cv::Mat& f : background) f(cv::Rect(0, 0, 40, 30)) = 0;  // some pixels never measured
  BackgroundModel all;
  all.Train(background, 1000.0);
  BackgroundModel one;
  {
    tbb::global_control single(tbb::global_control::max_allowed_parallelism, 1);
    one.Train(background, 1000.0);
  }
  EXPECT_EQ(cv::norm(all.background_depth(), one.background_depth(), cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(all.background_sigma(), one.background_sigma(), cv::NORM_INF), 0.0);
  EXPECT_EQ(all.known_fraction(), one.known_fraction());
  EXPECT_LT(all.known_fraction(), 1.0);
  EXPECT_GT(all.known_fraction(), 0.9);
}

TEST(BackgroundModelTest, UnknownBackgroundIsForegroundWithinRange) {
  const int w = 20, h = 10;
  std::vector<cv::Mat> frames;
  for (int i = 0; i < 6; ++i) {
    cv::Mat f(h, w, CV_16UC1, cv::Scalar(3000));
    f(cv::Rect(0, 0, 5, h)) = 0;             // never measured (e.g. beyond range, absorbing)
    if (i < 4) f(cv::Rect(5, 0, 5, h)) = 0;  // measured only twice: below min_valid_samples
    frames.push_back(f);
  }
  BackgroundModelOptions o;
  o.opening_radius = 0;
  BackgroundModel model(o);
  model.Train(frames, 1000.0);
  EXPECT_NEAR(model.known_fraction(), 0.5, 1e-12);
  EXPECT_EQ(model.background_depth().at<float>(0, 2), 0.0f);
  EXPECT_NEAR(model.background_depth().at<float>(0, 15), 3.0f, 1e-6);

  cv::Mat frame(h, w, CV_16UC1, cv::Scalar(2000));
  frame.at<uint16_t>(3, 1) = 4500;   // unknown background, beyond max_depth (4 m)
  frame.at<uint16_t>(3, 2) = 0;      // missing
  frame.at<uint16_t>(3, 15) = 2990;  // background, within noise
  frame.at<uint16_t>(3, 16) = 200;   // closer than min_depth
  cv::Mat mask;
  model.Classify(frame, &mask);
  EXPECT_EQ(mask.at<uint8_t>(0, 0), 255);   // unknown -> foreground
  EXPECT_EQ(mask.at<uint8_t>(0, 7), 255);   // too few samples -> unknown -> foreground
  EXPECT_EQ(mask.at<uint8_t>(0, 15), 255);  // 1 m in front of the wall
  EXPECT_EQ(mask.at<uint8_t>(3, 1), 0);
  EXPECT_EQ(mask.at<uint8_t>(3, 2), 0);
  EXPECT_EQ(mask.at<uint8_t>(3, 15), 0);
  EXPECT_EQ(mask.at<uint8_t>(3, 16), 0);
}

TEST(BackgroundModelTest, LargestComponentAndBadInput) {
  const int w = 40, h = 20;
  std::vector<cv::Mat> frames(5, cv::Mat(h, w, CV_16UC1, cv::Scalar(3000)));
  BackgroundModelOptions o;
  o.keep_largest_component = true;
  BackgroundModel model(o);
  model.Train(frames, 1000.0);
  cv::Mat frame(h, w, CV_16UC1, cv::Scalar(3000));
  frame(cv::Rect(2, 2, 10, 10)) = 2000;  // subject
  frame(cv::Rect(30, 5, 4, 4)) = 2000;   // smaller blob
  cv::Mat mask;
  model.Classify(frame, &mask);
  EXPECT_EQ(cv::countNonZero(mask), 100);
  EXPECT_EQ(mask.at<uint8_t>(6, 6), 255);
  EXPECT_EQ(mask.at<uint8_t>(6, 31), 0);

  EXPECT_THROW(model.Classify(cv::Mat(h, w + 1, CV_16UC1), &mask), Error);
  EXPECT_THROW(model.Classify(cv::Mat(h, w, CV_8UC1), &mask), Error);
  EXPECT_THROW(model.Train({frames[0], frames[1]}, 1000.0), Error);  // fewer than min samples
  std::vector<cv::Mat> mixed = frames;
  mixed[3] = cv::Mat(h + 1, w, CV_16UC1, cv::Scalar(1));
  EXPECT_THROW(model.Train(mixed, 1000.0), Error);
  BackgroundModelOptions invalid;
  invalid.max_depth = 0.1;
  EXPECT_THROW(BackgroundModel{invalid}, Error);
}

// ---------------------------------------------------------------------------------------------

// Least-squares plane through the rows of p: returns the RMS residual and the unit normal.
double PlaneFitRms(const Eigen::MatrixX3d& p, Eigen::Vector3d* normal) {
  const Eigen::RowVector3d mean = p.colwise().mean();
  const Eigen::MatrixX3d c = p.rowwise() - mean;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(c.transpose() * c);
  *normal = es.eigenvectors().col(0);
  return std::sqrt(std::max(0.0, es.eigenvalues()[0]) / p.rows());
}

TEST(DepthBackProjectionTest, PlaneBackProjectsToThePlane) {
  PinholeCamera cam;  // 640 x 480
  cam.world_to_camera = PinholeCamera::LookAt(Eigen::Vector3d(0.4, 1.3, 2.0),
                                              Eigen::Vector3d(0, 1, 0), Eigen::Vector3d::UnitY());
  const Distortion distortion{0.2624, -0.9531, -0.0054, 0.0026, 1.1633};
  // World plane n . x = d, tilted against the image plane.
  const Eigen::Vector3d n = Eigen::Vector3d(0.2, 0.1, 1.0).normalized();
  const double d = n.dot(Eigen::Vector3d(0, 1, -0.3));
  for (const bool distorted : {false, true}) {
    const Distortion dist = distorted ? distortion : Distortion();
    DepthBackProjector projector(cam, dist);
    const Eigen::Isometry3d c2w = cam.world_to_camera.inverse();
    const double scale = 10000.0;  // 0.1 mm units
    cv::Mat depth(cam.height, cam.width, CV_16UC1);
    Eigen::MatrixX3d exact(cam.width * cam.height, 3);
    for (int v = 0; v < cam.height; ++v) {
      for (int u = 0; u < cam.width; ++u) {
        // Ray of the (distorted) pixel: undistort, then intersect with the plane.
        const Eigen::Vector2d p = UndistortPixel(cam, dist, Eigen::Vector2d(u, v));
        const Eigen::Vector3d ray =
            c2w.linear() * Eigen::Vector3d((p.x() - cam.cx) / cam.fx, (p.y() - cam.cy) / cam.fy, 1);
        const double z = (d - n.dot(c2w.translation())) / n.dot(ray);
        ASSERT_GT(z, 0.5);
        depth.at<uint16_t>(v, u) = static_cast<uint16_t>(std::lround(z * scale));
        exact.row(v * cam.width + u) = projector.WorldPoint(u, v, z).transpose();
        // The back-projected point reprojects onto its pixel through the distortion model.
        if ((u % 97 == 0) && (v % 83 == 0)) {
          double depth_z = 0;
          const Eigen::Vector2d back = DistortPixel(
              cam, dist, cam.Project(exact.row(v * cam.width + u).transpose(), &depth_z));
          EXPECT_LT((back - Eigen::Vector2d(u, v)).norm(), 1e-3);
          EXPECT_NEAR(depth_z, z, 1e-9);
        }
      }
    }
    // Exact depths: residual at float ray precision.
    Eigen::Vector3d fitted;
    EXPECT_LT(PlaneFitRms(exact, &fitted), 2e-6) << "distorted " << distorted;
    EXPECT_GT(std::abs(fitted.dot(n)), 1 - 1e-9);
    const Eigen::VectorXd off = (exact * n).array() - d;
    EXPECT_LT(off.cwiseAbs().maxCoeff(), 5e-6);
    // Through the 16-bit image: residual at the quantisation level (0.05 mm).
    Eigen::MatrixX3d points;
    projector.BackProject(depth, scale, cv::Mat(), &points);
    ASSERT_EQ(points.rows(), cam.width * cam.height);
    const Eigen::VectorXd off16 = (points * n).array() - d;
    EXPECT_LT(off16.cwiseAbs().maxCoeff(), 1e-4);
    EXPECT_LT(PlaneFitRms(points, &fitted), 5e-5);
  }
  // Without undistortion the distorted plane is visibly not a plane (the test can fail).
  DepthBackProjector pinhole(cam, Distortion());
  Eigen::MatrixX3d wrong(cam.width * cam.height / 16, 3);
  const Eigen::Isometry3d c2w = cam.world_to_camera.inverse();
  int k = 0;
  for (int v = 0; v < cam.height; v += 4) {
    for (int u = 0; u < cam.width; u += 4) {
      const Eigen::Vector2d p = UndistortPixel(cam, distortion, Eigen::Vector2d(u, v));
      const Eigen::Vector3d ray =
          c2w.linear() * Eigen::Vector3d((p.x() - cam.cx) / cam.fx, (p.y() - cam.cy) / cam.fy, 1);
      const double z = (d - n.dot(c2w.translation())) / n.dot(ray);
      wrong.row(k++) = pinhole.WorldPoint(u, v, z).transpose();
    }
  }
  const Eigen::VectorXd wrong_off = (wrong * n).array() - d;
  EXPECT_GT(wrong_off.cwiseAbs().maxCoeff(), 1e-3);  // > 10x the tolerance above
}

// ---------------------------------------------------------------------------------------------

PinholeCamera SmallCamera(int w, int h) {
  PinholeCamera c;
  c.width = w;
  c.height = h;
  c.fx = c.fy = 60.0;
  c.cx = (w - 1) / 2.0;
  c.cy = (h - 1) / 2.0;
  c.world_to_camera = PinholeCamera::LookAt(Eigen::Vector3d(0, 1, 3), Eigen::Vector3d(0, 1, 0),
                                            Eigen::Vector3d::UnitY());
  return c;
}

double MaxTriangleJump(const Scan& scan, const PinholeCamera& cam, double* min_z) {
  double worst = 0;
  *min_z = 1e9;
  for (int t = 0; t < scan.triangles.rows(); ++t) {
    double z[3];
    for (int k = 0; k < 3; ++k) {
      cam.Project(scan.points.row(scan.triangles(t, k)).transpose(), &z[k]);
      *min_z = std::min(*min_z, z[k]);
    }
    worst = std::max({worst, std::abs(z[0] - z[1]), std::abs(z[1] - z[2]), std::abs(z[0] - z[2])});
  }
  return worst;
}

TEST(DepthMeshTest, NoTrianglesAcrossDepthJumps) {
  const int w = 64, h = 48;
  const PinholeCamera cam = SmallCamera(w, h);
  cv::Mat depth(h, w, CV_16UC1, cv::Scalar(2000));
  depth(cv::Rect(32, 0, 32, h)) = 2500;  // step of 0.5 m between columns 31 and 32
  DepthMesher mesher(cam, Distortion());
  Scan scan;
  DepthMeshStats stats;
  mesher.Build(depth, 1000.0, cv::Mat(), &scan, &stats);
  EXPECT_EQ(scan.size(), w * h);
  // Blocks entirely on either side: 2 x 31 columns x 47 rows, two triangles each.
  EXPECT_EQ(scan.triangles.rows(), 2 * 31 * 47 * 2);
  EXPECT_EQ(stats.triangles, scan.triangles.rows());
  double min_z = 0;
  EXPECT_LT(MaxTriangleJump(scan, cam, &min_z), 1e-6);
  EXPECT_NEAR(min_z, 2.0, 1e-6);

  // A step smaller than the threshold is bridged (the check is relative to depth).
  depth(cv::Rect(32, 0, 32, h)) = 2040;  // 4 cm < 0.03 x 2 m
  mesher.Build(depth, 1000.0, cv::Mat(), &scan, &stats);
  EXPECT_EQ(scan.triangles.rows(), 2 * 63 * 47);
  DepthMeshOptions strict;
  strict.max_relative_jump = 0.01;
  DepthMesher strict_mesher(cam, Distortion(), strict);
  strict_mesher.Build(depth, 1000.0, cv::Mat(), &scan, &stats);
  EXPECT_EQ(scan.triangles.rows(), 2 * 31 * 47 * 2);
}

TEST(DepthMeshTest, HolesSubsamplingAndIsolatedPoints) {
  const int w = 32, h = 24;
  const PinholeCamera cam = SmallCamera(w, h);
  cv::Mat depth(h, w, CV_16UC1, cv::Scalar(2000));
  depth.at<uint16_t>(10, 10) = 0;  // hole: its 4 blocks keep one triangle each
  DepthMesher mesher(cam, Distortion());
  Scan scan;
  mesher.Build(depth, 1000.0, cv::Mat(), &scan);
  EXPECT_EQ(scan.triangles.rows(), 2 * 31 * 23 - 4);
  EXPECT_EQ(scan.size(), w * h - 1);

  // Orientation: fronto-parallel plane -> every normal points to the camera (world +Z here).
  for (int i = 0; i < scan.size(); ++i) {
    EXPECT_NEAR(scan.normals(i, 2), 1.0, 1e-9);
  }
  // Triangles are counter-clockwise seen from the camera: face normals agree with the vertex ones.
  for (int t = 0; t < scan.triangles.rows(); ++t) {
    const Eigen::Vector3d a = scan.points.row(scan.triangles(t, 0));
    const Eigen::Vector3d b = scan.points.row(scan.triangles(t, 1));
    const Eigen::Vector3d c = scan.points.row(scan.triangles(t, 2));
    ASSERT_GT((b - a).cross(c - a).z(), 0);
  }

  // Isolated pixel: dropped by default, kept (zero normal) when asked.
  cv::Mat mask = cv::Mat::zeros(h, w, CV_8UC1);
  mask(cv::Rect(2, 2, 5, 5)) = 255;
  mask.at<uint8_t>(20, 20) = 255;
  DepthMeshStats stats;
  mesher.Build(depth, 1000.0, mask, &scan, &stats);
  EXPECT_EQ(scan.size(), 25);
  EXPECT_EQ(stats.isolated_dropped, 1);
  DepthMeshOptions keep;
  keep.drop_isolated_points = false;
  DepthMesher keeper(cam, Distortion(), keep);
  keeper.Build(depth, 1000.0, mask, &scan, &stats);
  EXPECT_EQ(scan.size(), 26);
  EXPECT_EQ(scan.normals.row(25).norm(), 0.0);
  EXPECT_EQ(keeper.vertex_pixels()[25], 20 * w + 20);

  // Every 2nd pixel: a 16 x 12 grid.
  DepthMeshOptions sub;
  sub.step = 2;
  DepthMesher coarse(cam, Distortion(), sub);
  depth.at<uint16_t>(10, 10) = 2000;
  coarse.Build(depth, 1000.0, cv::Mat(), &scan);
  EXPECT_EQ(scan.size(), 16 * 12);
  EXPECT_EQ(scan.triangles.rows(), 2 * 15 * 11);
  DepthMeshOptions bad;
  bad.step = 0;
  EXPECT_THROW(DepthMesher(cam, Distortion(), bad), Error);
  EXPECT_THROW(mesher.Build(cv::Mat(h, w, CV_8UC1), 1000.0, cv::Mat(), &scan), Error);
}

// ---------------------------------------------------------------------------------------------

TEST(ColorSamplingTest, BilinearRgbAndOutsideInvalid) {
  PinholeCamera cam;
  cam.width = 256;
  cam.height = 200;
  cam.fx = cam.fy = 200;
  cam.cx = 127.5;
  cam.cy = 99.5;
  cv::Mat image(cam.height, cam.width, CV_8UC3);
  for (int v = 0; v < cam.height; ++v) {
    for (int u = 0; u < cam.width; ++u) image.at<cv::Vec3b>(v, u) = cv::Vec3b(u, v, 17);  // BGR
  }
  Scan scan;
  scan.points.resize(3, 3);
  // Pixel (40.25, 60.75) at 2 m, a point behind the camera, a point left of the image.
  scan.points.row(0) = cam.Unproject(40.25, 60.75, 2.0).transpose();
  scan.points.row(1) = Eigen::RowVector3d(0, 0, -1);
  scan.points.row(2) = cam.Unproject(-3.0, 50, 2.0).transpose();
  EXPECT_EQ(SampleScanColors(cam, Distortion(), image, &scan), 2);
  EXPECT_NEAR(scan.colors(0, 0), 17 / 255.0, 1e-6);     // R
  EXPECT_NEAR(scan.colors(0, 1), 60.75 / 255.0, 1e-6);  // G = v
  EXPECT_NEAR(scan.colors(0, 2), 40.25 / 255.0, 1e-6);  // B = u
  EXPECT_EQ(scan.color_valid, (std::vector<uint8_t>{1, 0, 0}));
  EXPECT_EQ(scan.colors.row(2).norm(), 0.0);

  // With distortion, the sample is taken at the distorted pixel.
  const Distortion d{0.1, 0, 0, 0, 0};
  EXPECT_EQ(SampleScanColors(cam, d, image, &scan), 2);
  const Eigen::Vector2d q = DistortPixel(cam, d, Eigen::Vector2d(40.25, 60.75));
  EXPECT_NEAR(scan.colors(0, 2), q.x() / 255.0, 1e-6);
  EXPECT_NEAR(scan.colors(0, 1), q.y() / 255.0, 1e-6);
  EXPECT_THROW(SampleScanColors(cam, d, cv::Mat(10, 10, CV_8UC3), &scan), Error);
}

// ---------------------------------------------------------------------------------------------

TEST(PreprocessorTest, SyntheticFrameGivesTheSubjectMesh) {
  const Calibration cal = Rig();
  std::mt19937_64 rng(7);
  cv::Mat z_empty, z_subject, none, subject;
  RenderTruth(cal.depth, false, &z_empty, &none);
  RenderTruth(cal.depth, true, &z_subject, &subject);
  std::vector<cv::Mat> background;
  for (int i = 0; i < 15; ++i) background.push_back(Measure(z_empty, &rng));
  Frame frame;
  frame.depth = Measure(z_subject, &rng);
  frame.color.create(cal.color.height, cal.color.width, CV_8UC3);
  for (int v = 0; v < frame.color.rows; ++v) {
    for (int u = 0; u < frame.color.cols; ++u) {
      frame.color.at<cv::Vec3b>(v, u) = cv::Vec3b(u % 256, v % 256, 200);
    }
  }

  Preprocessor pre(cal);
  EXPECT_THROW(pre.Process(frame, nullptr), Error);  // untrained
  pre.Train(background);
  Scan scan;
  PreprocessStats stats;
  pre.Process(frame, &scan, &stats);
  ASSERT_GT(scan.size(), 30000);
  EXPECT_EQ(stats.mesh.vertices, scan.size());
  EXPECT_GT(scan.triangles.rows(), scan.size());
  EXPECT_EQ(scan.normals.rows(), scan.size());
  EXPECT_EQ(scan.colors.rows(), scan.size());
  EXPECT_EQ(static_cast<int>(scan.color_valid.size()), scan.size());

  const Eigen::Vector3d eye = cal.depth.Center();
  int on_subject = 0;
  for (int i = 0; i < scan.size(); ++i) {
    const Eigen::Vector3d p = scan.points.row(i);
    const double r = (p - kSubjectCentre).cwiseQuotient(kSubjectRadii).norm();
    on_subject += std::abs(r - 1) < 0.2;  // noise is ~1 cm along the ray
    const Eigen::Vector3d n = scan.normals.row(i);
    ASSERT_NEAR(n.norm(), 1.0, 1e-9);
    ASSERT_GT(n.dot(eye - p), 0.0);
  }
  EXPECT_GT(on_subject, 0.995 * scan.size());
  double min_z = 0;
  const double jump = MaxTriangleJump(scan, cal.depth, &min_z);
  EXPECT_LT(jump, 0.03 * 3.0);

  // Mesher normals (single precision internally) are models/normals.h normals, oriented.
  Eigen::MatrixX3d reference;
  ComputeOrientedVertexNormals(scan.points, scan.triangles, eye, &reference);
  EXPECT_LT((reference - scan.normals).cwiseAbs().maxCoeff(), 1e-4);

  // Colours: projection through the depth -> colour extrinsic, computed independently.
  const Eigen::Isometry3d depth_to_color = cal.DepthToColor();
  int checked = 0;
  for (int i = 0; i < scan.size(); i += 97) {
    const Eigen::Vector3d pc =
        depth_to_color * (cal.depth.world_to_camera * scan.points.row(i).transpose());
    const double u = cal.color.fx * pc.x() / pc.z() + cal.color.cx;
    const double v = cal.color.fy * pc.y() / pc.z() + cal.color.cy;
    ASSERT_EQ(scan.color_valid[i], 1);
    if (u < 1 || v < 1 || u > 254 || v > 254) continue;  // away from the 256-pixel wrap
    EXPECT_NEAR(scan.colors(i, 2), u / 255.0, 1e-6);
    EXPECT_NEAR(scan.colors(i, 1), v / 255.0, 1e-6);
    EXPECT_NEAR(scan.colors(i, 0), 200 / 255.0, 1e-6);
    ++checked;
  }
  EXPECT_GT(checked, 50);

  // Reusing the preprocessor for another frame gives a consistent result.
  Scan again;
  pre.Process(frame, &again);
  EXPECT_EQ(again.size(), scan.size());
  EXPECT_EQ((again.points - scan.points).norm(), 0.0);

  // Untrained alternative: everything within range is foreground (wall and floor too).
  PreprocessOptions range;
  range.foreground = ForegroundMode::kBackground;
  Preprocessor all(cal, range);
  all.TrainWithoutBackground();
  all.Process(frame, &again);
  EXPECT_GT(again.size(), 3 * scan.size());
  // The default without background frames segments the subject: floor and wall removed.
  Preprocessor segmenting(cal);
  segmenting.TrainWithoutBackground();
  EXPECT_TRUE(segmenting.segmenting());
  segmenting.Process(frame, &again);
  EXPECT_LT(again.size(), 1.5 * scan.size());
  EXPECT_GT(again.size(), 0.7 * scan.size());
}

}  // namespace
}  // namespace artex
