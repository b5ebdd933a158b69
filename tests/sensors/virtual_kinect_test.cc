#include "sensors/virtual_kinect.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <opencv2/imgproc.hpp>

#include "models/error.h"
#include "models/skinning.h"
#include "sensors/sequence.h"
#include "tests/sensors/small_synth.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

SynthOptions SmallOptions() { return testing_util::SmallSynthOptions(3, 2); }

fs::path TempDir(const std::string& name) {
  const fs::path dir = testing_util::FreshTempDir("vk_" + name);
  fs::remove_all(dir);  // absent: the writers create it
  return dir;
}

std::string ReadAll(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// Independent ray cast (Moeller-Trumbore over all triangles): camera depth of the first hit.
double RayCastDepth(const PinholeCamera& camera, const Eigen::MatrixX3d& v,
                    const Eigen::MatrixX3i& t, int u, int w) {
  const Eigen::Vector3d origin = camera.Center();
  const Eigen::Vector3d dir = camera.Unproject(u, w, 1.0) - origin;  // camera z = 1 per unit
  double best = std::numeric_limits<double>::infinity();
  for (int f = 0; f < t.rows(); ++f) {
    const Eigen::Vector3d a = v.row(t(f, 0)), b = v.row(t(f, 1)), c = v.row(t(f, 2));
    const Eigen::Vector3d e1 = b - a, e2 = c - a, p = dir.cross(e2);
    const double det = e1.dot(p);
    if (std::abs(det) < 1e-15) continue;
    const Eigen::Vector3d s = origin - a;
    const double bu = s.dot(p) / det;
    if (bu < 0 || bu > 1) continue;
    const Eigen::Vector3d q = s.cross(e1);
    const double bv = dir.dot(q) / det;
    if (bv < 0 || bu + bv > 1) continue;
    const double tt = e2.dot(q) / det;
    if (tt > 0) best = std::min(best, tt);
  }
  return best;
}

// The subject of SmallOptions(), generated once (only the cameras and noise vary below).
const SynthSubject& SmallSubject() {
  static const SynthSubject subject = PrepareSynthSubject(SmallOptions());
  return subject;
}

// A sequence written once with SmallOptions().
const fs::path& SmallSequence() {
  static const fs::path dir = [] {
    const fs::path d = TempDir("sequence");
    SynthesizeSequence(SmallOptions(), SmallSubject(), d.string());
    return d;
  }();
  return dir;
}

struct Scene {
  const SynthSubject& subject = SmallSubject();
  Eigen::MatrixX3d posed;
};

Scene MakeScene(const SynthOptions& o, int frame) {
  Scene s;
  Skinning(s.subject.subject).Apply(s.subject.poses[frame], &s.posed);
  return s;
}

TEST(VirtualKinectTest, TwoRunsWriteIdenticalFiles) {
  // Two complete runs, each generating its own subject, write byte-identical folders.
  const SynthOptions o = SmallOptions();
  const fs::path a = TempDir("det_a"), b = TempDir("det_b");
  const SynthSummary summary = SynthesizeSequence(o, a.string());
  SynthesizeSequence(o, b.string());
  EXPECT_EQ(summary.frames, 3);
  EXPECT_EQ(summary.background_frames, 2);
  int files = 0;
  for (const auto& entry : fs::recursive_directory_iterator(a)) {
    if (!entry.is_regular_file()) continue;
    const fs::path rel = fs::relative(entry.path(), a);
    ASSERT_TRUE(fs::exists(b / rel)) << rel;
    ASSERT_EQ(ReadAll(entry.path()), ReadAll(b / rel)) << rel;
    ++files;
  }
  EXPECT_GE(files, 3 * 2 + 2 + 2);  // depth + colour per frame, backgrounds, csv/yaml...
  fs::remove_all(a);
  fs::remove_all(b);
}

TEST(VirtualKinectTest, TheSeedSelectsTheNoise) {
  SynthOptions o = SmallOptions();
  const Scene s = MakeScene(o, 1);
  const VirtualKinect k1(o.kinect, s.subject.subject, s.subject.texture_bgr);
  o.kinect.seed = 2;
  const VirtualKinect k2(o.kinect, s.subject.subject, s.subject.texture_bgr);
  const cv::Mat a = k1.RenderDepth(1, &s.posed), b = k1.RenderDepth(1, &s.posed);
  const cv::Mat c = k2.RenderDepth(1, &s.posed), d = k1.RenderDepth(2, &s.posed);
  EXPECT_EQ(cv::norm(a, b, cv::NORM_L1), 0);
  EXPECT_GT(cv::norm(a, c, cv::NORM_L1), 0);  // other seed
  EXPECT_GT(cv::norm(a, d, cv::NORM_L1), 0);  // other frame
}

TEST(VirtualKinectTest, SubjectDepthMatchesTheMeshWithinTheNoiseBound) {
  const SynthOptions o = SmallOptions();
  const Scene s = MakeScene(o, 1);
  const VirtualKinect kinect(o.kinect, s.subject.subject, s.subject.texture_bgr);
  DepthDiagnostics diag;
  const cv::Mat depth = kinect.RenderDepth(1, &s.posed, &diag);
  const PinholeCamera& cam = kinect.calibration().depth;
  const DepthNoiseOptions& n = o.kinect.depth_noise;
  const double bf = n.baseline_m * cam.fx;
  int checked = 0;
  for (int y = 0; y < cam.height; y += 7) {
    for (int x = 0; x < cam.width; x += 7) {
      if (!diag.subject_mask.at<uint8_t>(y, x) || depth.at<uint16_t>(y, x) == 0) continue;
      const double truth = RayCastDepth(cam, s.posed, s.subject.subject.triangles, x, y);
      ASSERT_TRUE(std::isfinite(truth));
      // Diagnostic true depth is the exact surface.
      ASSERT_NEAR(diag.true_depth.at<float>(y, x), truth, 1e-4);
      const double z = depth.at<uint16_t>(y, x) / kinect.calibration().depth_scale;
      // 5 sigma of the disparity noise plus half a quantisation step, in depth, plus 1 unit.
      const double bound =
          truth * truth / bf * (5 * n.disparity_noise_px + 0.5 * n.disparity_step_px) +
          1.0 / kinect.calibration().depth_scale;
      ASSERT_LT(std::abs(z - truth), bound) << x << "," << y;
      ++checked;
    }
  }
  EXPECT_GT(checked, 50);
}

TEST(VirtualKinectTest, NoiseOffGivesExactDepth) {
  SynthOptions o = SmallOptions();
  o.kinect.SetNoiseLevel(NoiseLevel::kOff);
  const Scene s = MakeScene(o, 0);
  const VirtualKinect kinect(o.kinect, s.subject.subject, s.subject.texture_bgr);
  DepthDiagnostics diag;
  const cv::Mat depth = kinect.RenderDepth(0, &s.posed, &diag);
  int valid = 0;
  for (int y = 0; y < depth.rows; ++y) {
    for (int x = 0; x < depth.cols; ++x) {
      const float truth = diag.true_depth.at<float>(y, x);
      if (truth == 0) continue;
      ASSERT_EQ(depth.at<uint16_t>(y, x), static_cast<uint16_t>(std::lround(truth * 1000.0)));
      ++valid;
    }
  }
  EXPECT_EQ(valid, depth.rows * depth.cols);  // floor and wall fill the view
}

TEST(VirtualKinectTest, CompositingOverTheCachedSceneEqualsRasterisingEverything) {
  SynthOptions o = SmallOptions();
  o.kinect.SetNoiseLevel(NoiseLevel::kOff);
  const Scene s = MakeScene(o, 2);
  const VirtualKinect kinect(o.kinect, s.subject.subject, s.subject.texture_bgr);
  DepthDiagnostics diag;
  kinect.RenderDepth(2, &s.posed, &diag);
  // Subject and scene in one mesh, subject first.
  const Eigen::MatrixX3d& sv = kinect.scene_vertices();
  const Eigen::MatrixX3i& st = kinect.scene_triangles();
  const Eigen::MatrixX3i& ft = s.subject.subject.triangles;
  Eigen::MatrixX3d v(s.posed.rows() + sv.rows(), 3);
  v << s.posed, sv;
  Eigen::MatrixX3i t(ft.rows() + st.rows(), 3);
  t << ft, (st.array() + static_cast<int>(s.posed.rows())).matrix();
  RasterBuffers all;
  Rasterize(v, t, kinect.calibration().depth, RasterOptions(), &all);
  for (int y = 0; y < diag.true_depth.rows; ++y) {
    for (int x = 0; x < diag.true_depth.cols; ++x) {
      const int i = all.index(x, y);
      ASSERT_EQ(diag.true_depth.at<float>(y, x), all.triangle_id[i] >= 0 ? all.depth[i] : 0.0f);
      ASSERT_EQ(diag.subject_mask.at<uint8_t>(y, x) != 0,
                all.triangle_id[i] >= 0 && all.triangle_id[i] < ft.rows());
    }
  }
}

// Standard deviation of (measured - true) depth over valid central pixels of a wall facing
// the camera at `distance`.
double WallNoiseStd(double distance, double* predicted) {
  SynthOptions o = SmallOptions();
  o.kinect.scene.floor = false;
  o.kinect.scene.wall_z_m = -1.0;
  o.kinect.scene.wall_height_m = 6.0;
  o.kinect.depth_eye = Eigen::Vector3d(0, 2.0, -1.0 + distance);
  o.kinect.depth_target = Eigen::Vector3d(0, 2.0, -1.0);
  o.kinect.depth_noise.edge_drop_probability = 0;
  const Scene s = MakeScene(o, 0);
  const VirtualKinect kinect(o.kinect, s.subject.subject, s.subject.texture_bgr);
  DepthDiagnostics diag;
  const cv::Mat depth = kinect.RenderDepth(0, nullptr, &diag);
  double sum = 0, sum2 = 0;
  int count = 0;
  for (int y = 100; y < 380; ++y) {
    for (int x = 150; x < 490; ++x) {
      const uint16_t d = depth.at<uint16_t>(y, x);
      if (d == 0) continue;
      const double e = d / 1000.0 - diag.true_depth.at<float>(y, x);
      sum += e;
      sum2 += e * e;
      ++count;
    }
  }
  const DepthNoiseOptions& n = o.kinect.depth_noise;
  const double bf = n.baseline_m * kinect.calibration().depth.fx;
  *predicted = distance * distance / bf *
               std::sqrt(n.disparity_noise_px * n.disparity_noise_px +
                         n.disparity_step_px * n.disparity_step_px / 12.0);
  const double mean = sum / count;
  return std::sqrt(sum2 / count - mean * mean);
}

TEST(VirtualKinectTest, DepthNoiseGrowsWithTheSquareOfDepth) {
  double predicted_near = 0, predicted_far = 0;
  const double near = WallNoiseStd(1.5, &predicted_near);
  const double far = WallNoiseStd(3.0, &predicted_far);
  EXPECT_GT(far / near, 3.0);  // z^2: a factor 4
  EXPECT_LT(far / near, 5.0);
  EXPECT_NEAR(near, predicted_near, 0.15 * predicted_near);
  EXPECT_NEAR(far, predicted_far, 0.15 * predicted_far);
}

// Shadow pixels within `reach` pixels left / right of the subject's silhouette, per row.
void CountShadowBesideSubject(const DepthDiagnostics& d, int reach, int* left, int* right) {
  *left = *right = 0;
  for (int y = 0; y < d.status.rows; ++y) {
    for (int x = 0; x < d.status.cols; ++x) {
      if (d.status.at<uint8_t>(y, x) != static_cast<uint8_t>(DepthStatus::kShadow)) continue;
      if (d.subject_mask.at<uint8_t>(y, x)) continue;
      for (int k = 1; k <= reach; ++k) {
        if (x + k < d.status.cols && d.subject_mask.at<uint8_t>(y, x + k)) {
          ++*left;  // the subject is to the right: shadow on its left side
          break;
        }
        if (x - k >= 0 && d.subject_mask.at<uint8_t>(y, x - k)) {
          ++*right;
          break;
        }
      }
    }
  }
}

TEST(VirtualKinectTest, ProjectorShadowLiesBesideTheSubjectOppositeTheProjector) {
  SynthOptions o = SmallOptions();
  const Scene s = MakeScene(o, 0);
  for (int side = 0; side < 2; ++side) {
    // Projector right of the IR camera (+x): the shadow falls on the subject's left in the
    // image, i.e. the background seen past the silhouette on the side away from the projector.
    o.kinect.depth_noise.projector_offset_m = Eigen::Vector3d(side == 0 ? 0.075 : -0.075, 0, 0);
    const VirtualKinect kinect(o.kinect, s.subject.subject, s.subject.texture_bgr);
    DepthDiagnostics diag;
    const cv::Mat depth = kinect.RenderDepth(0, &s.posed, &diag);
    int left = 0, right = 0;
    CountShadowBesideSubject(diag, 12, &left, &right);
    const int away = side == 0 ? left : right, toward = side == 0 ? right : left;
    EXPECT_GT(away, 200) << "side " << side;
    EXPECT_GT(away, 5 * toward) << "side " << side;
    for (int y = 0; y < depth.rows; ++y) {
      for (int x = 0; x < depth.cols; ++x) {
        if (diag.status.at<uint8_t>(y, x) != static_cast<uint8_t>(DepthStatus::kValid)) {
          ASSERT_EQ(depth.at<uint16_t>(y, x), 0);
        }
      }
    }
  }
  // Without the shadow model there are no shadow pixels.
  o.kinect.depth_noise.projector_shadow = false;
  const VirtualKinect kinect(o.kinect, s.subject.subject, s.subject.texture_bgr);
  DepthDiagnostics diag;
  kinect.RenderDepth(0, &s.posed, &diag);
  EXPECT_EQ(cv::countNonZero(diag.status == static_cast<uint8_t>(DepthStatus::kShadow)), 0);
}

TEST(VirtualKinectTest, BackgroundFramesContainNoSubject) {
  const SynthOptions o = SmallOptions();
  SequenceReader reader(SmallSequence().string());
  const std::vector<cv::Mat> background = reader.ReadBackgroundFrames();
  ASSERT_EQ(background.size(), 2u);
  // The empty scene's exact depth.
  SynthOptions exact = o;
  exact.kinect.SetNoiseLevel(NoiseLevel::kOff);
  const Scene s = MakeScene(o, 0);
  const VirtualKinect kinect(exact.kinect, s.subject.subject, s.subject.texture_bgr);
  DepthDiagnostics empty, with_subject;
  const cv::Mat scene = kinect.RenderBackgroundDepth(0, &empty);
  EXPECT_EQ(cv::countNonZero(empty.subject_mask), 0);
  kinect.RenderDepth(0, &s.posed, &with_subject);
  ASSERT_GT(cv::countNonZero(with_subject.subject_mask), 1000);
  const double bf = o.kinect.depth_noise.baseline_m * kinect.calibration().depth.fx;
  for (const cv::Mat& b : background) {
    int valid = 0;
    for (int y = 0; y < b.rows; ++y) {
      for (int x = 0; x < b.cols; ++x) {
        if (b.at<uint16_t>(y, x) == 0) continue;
        const double z = b.at<uint16_t>(y, x) / 1000.0, truth = scene.at<uint16_t>(y, x) / 1000.0;
        ASSERT_LT(std::abs(z - truth), truth * truth / bf * 0.5 + 0.002) << x << "," << y;
        ++valid;
      }
    }
    EXPECT_GT(valid, b.rows * b.cols * 8 / 10);
  }
  // Reading frame 0: the subject pixels are much nearer than the background there.
  Frame frame;
  std::string warning;
  ASSERT_TRUE(reader.ReadFrame(0, &frame, &warning)) << warning;
  // Pixels where the subject stands at least 40 cm before the background (not the feet on
  // the floor) measure at least 30 cm nearer than the background there.
  int nearer = 0, subject = 0;
  for (int y = 0; y < frame.depth.rows; ++y) {
    for (int x = 0; x < frame.depth.cols; ++x) {
      if (!with_subject.subject_mask.at<uint8_t>(y, x) || frame.depth.at<uint16_t>(y, x) == 0)
        continue;
      if (with_subject.true_depth.at<float>(y, x) * 1000 + 400 > scene.at<uint16_t>(y, x)) continue;
      ++subject;
      nearer += frame.depth.at<uint16_t>(y, x) + 300 < scene.at<uint16_t>(y, x);
    }
  }
  EXPECT_GT(subject, 1000);
  EXPECT_EQ(nearer, subject);
}

TEST(VirtualKinectTest, GroundTruthVerticesAreTheSkinnedSubject) {
  const SynthOptions o = SmallOptions();
  SequenceReader reader(SmallSequence().string());
  ASSERT_TRUE(reader.has_ground_truth());
  EXPECT_NE(reader.GroundTruthTexturePath(), "");
  EXPECT_NE(reader.GroundTruthSubjectPath(), "");
  const Template& subject = SmallSubject().subject;
  const Skinning skinning(subject);
  for (int f = 0; f < reader.num_frames(); ++f) {
    const GroundTruthFrame truth = reader.ReadGroundTruth(f);
    ASSERT_EQ(truth.vertices.rows(), subject.num_vertices());
    Eigen::MatrixX3d posed;
    skinning.Apply(truth.pose, &posed);
    EXPECT_LT((posed - truth.vertices).cwiseAbs().maxCoeff(), 1e-5) << "frame " << f;
  }
  // The subject differs in shape from the default tracking template (same resolution).
  BodyShapeOptions tracking_shape;
  tracking_shape.resolution = o.subject_shape.resolution;
  const Template tracking = GenerateTemplate(tracking_shape);
  const double height_difference =
      tracking.vertices.col(1).maxCoeff() - subject.vertices.col(1).maxCoeff();
  EXPECT_NEAR(height_difference, tracking_shape.height - o.subject_shape.height, 0.01);
  // Torso breadth (vertices of the spine joint): the subject's girth factor makes it broader.
  auto torso_width = [](const Template& t) {
    const int spine = t.FindJoint("spine");
    double lo = 1e9, hi = -1e9;
    for (int v = 0; v < t.num_vertices(); ++v) {
      if (t.vertex_joint(v) != spine) continue;
      lo = std::min(lo, t.vertices(v, 0));
      hi = std::max(hi, t.vertices(v, 0));
    }
    return hi - lo;
  };
  EXPECT_GT(torso_width(subject) - torso_width(tracking), 0.005);
}

TEST(VirtualKinectTest, ColourDriftIsSmoothBoundedAndNeutralAtFrameZero) {
  const ColorModelOptions o;
  const std::vector<ColorConditions> c = GenerateColorConditions(o, 7, 200);
  ASSERT_EQ(c.size(), 200u);
  EXPECT_NEAR((c[0].gain - Eigen::Vector3d::Ones()).norm(), 0, 1e-12);
  double max_step = 0, max_dev = 0;
  for (size_t f = 1; f < c.size(); ++f) {
    max_step = std::max(max_step,
                        (c[f].gain.array().log() - c[f - 1].gain.array().log()).abs().maxCoeff());
    max_dev = std::max(max_dev, c[f].gain.array().log().abs().maxCoeff());
  }
  EXPECT_GT(max_dev, 0.02);  // it does drift
  EXPECT_LE(max_dev, o.exposure_limit + o.white_balance_limit + 1e-9);
  EXPECT_LT(max_step, 0.08);  // smooth: small per-frame change
  ColorModelOptions off;
  off.exposure_step = off.white_balance_step = 0;
  for (const ColorConditions& k : GenerateColorConditions(off, 7, 20)) {
    EXPECT_NEAR((k.gain - Eigen::Vector3d::Ones()).norm(), 0, 1e-12);
  }
}

TEST(VirtualKinectTest, ColourImageShowsTheTexturedSubject) {
  SynthOptions o = SmallOptions();
  o.kinect.SetNoiseLevel(NoiseLevel::kOff);
  o.kinect.color_model.ambient = 1.0;  // no shading: pixels equal the albedo
  const Scene s = MakeScene(o, 0);
  const VirtualKinect kinect(o.kinect, s.subject.subject, s.subject.texture_bgr);
  const cv::Mat empty = kinect.RenderColor(0, nullptr, ColorConditions());
  const cv::Mat with = kinect.RenderColor(0, &s.posed, ColorConditions());
  ASSERT_EQ(with.cols, 200);
  ASSERT_EQ(with.rows, 254);
  cv::Mat diff;
  cv::absdiff(empty, with, diff);
  cv::Mat gray;
  cv::cvtColor(diff, gray, cv::COLOR_BGR2GRAY);
  EXPECT_GT(cv::countNonZero(gray > 10), 2000);  // the subject covers part of the image
}

TEST(VirtualKinectTest, InvalidOptionsThrowNamingTheField) {
  SynthOptions o = SmallOptions();
  o.kinect.depth_noise.edge_drop_probability = 2;
  try {
    PrepareSynthSubject(o);
    FAIL() << "expected artex::Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("edge_drop_probability"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ParseNoiseLevel("loud"), Error);
  EXPECT_EQ(ParseNoiseLevel("high"), NoiseLevel::kHigh);
}

}  // namespace
}  // namespace artex
