// On-the-fly texturing on a synthetic virtual-Kinect sequence (sensors/virtual_kinect.h): the
// subject turns in front of the colour camera; the texturer is fed the ground-truth posed
// subject and the colour frames, and its texture is rendered from a held-out viewpoint against
// the ground-truth render (subject + true texture).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "models/template_io.h"
#include "render/rasterizer.h"
#include "sensors/sequence.h"
#include "sensors/virtual_kinect.h"
#include "texture/texture_quality.h"
#include "texture/texturer.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

constexpr int kFrames = 10;
constexpr int kAtlasSize = 512;
constexpr int kTrueTextureSize = 256;

// A small, fast sequence: coarse subject, 320 x 406 colour frames, one turn cycle (+-40 degrees
// of yaw) in kFrames frames. Unshaded albedo (ambient 1) so that the true texture is what the
// camera sees up to a mild exposure / white-balance drift and sensor noise.
SynthOptions SequenceOptions() {
  SynthOptions o;
  o.subject_shape.resolution = 0;
  o.texture.size = kTrueTextureSize;
  o.kinect.color_width = 640;
  o.kinect.color_height = 812;
  o.kinect.depth_intrinsics.width = 160;
  o.kinect.depth_intrinsics.height = 120;
  o.kinect.depth_intrinsics.fx = o.kinect.depth_intrinsics.fy = 525.0 / 4;
  o.kinect.depth_intrinsics.cx = 79.5;
  o.kinect.depth_intrinsics.cy = 59.5;
  o.kinect.color_model.ambient = 1.0;
  o.kinect.color_model.exposure_limit = 0.06;
  o.kinect.color_model.white_balance_limit = 0.03;
  o.motion.type = MotionType::kTurn;
  o.motion.frames = kFrames;
  o.motion.ramp_s = 0.0;
  o.motion.period_s = kFrames / o.motion.frame_rate;
  o.background_frames = 1;
  return o;
}

struct Sequence {
  Template subject;
  cv::Mat truth_texture;
  PinholeCamera camera;
  std::vector<cv::Mat> color;
  std::vector<Eigen::MatrixX3d> posed;
};

class TexturingSequenceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    const fs::path dir =
        fs::temp_directory_path() / ("artex_texturing_sequence_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    SynthesizeSequence(SequenceOptions(), dir.string());
    auto seq = std::make_unique<Sequence>();
    SequenceReader reader(dir.string());
    seq->subject = ReadTemplateGlb(reader.GroundTruthSubjectPath());
    seq->truth_texture = cv::imread(reader.GroundTruthTexturePath(), cv::IMREAD_COLOR);
    seq->camera = reader.calibration().color;
    for (int i = 0; i < reader.num_frames(); ++i) {
      Frame frame;
      std::string warning;
      if (!reader.ReadFrame(i, &frame, &warning)) continue;
      seq->color.push_back(frame.color);
      seq->posed.push_back(reader.ReadGroundTruth(i).vertices);
    }
    fs::remove_all(dir);
    sequence_ = seq.release();
  }
  static void TearDownTestSuite() {
    delete sequence_;
    sequence_ = nullptr;
  }

  // Feeds every frame; returns the last frame's summary.
  static std::unique_ptr<Texturer> Feed(const TexturingOptions& options,
                                        TextureFrameSummary* last) {
    auto texturer = std::make_unique<Texturer>(sequence_->subject, options);
    for (std::size_t i = 0; i < sequence_->color.size(); ++i) {
      *last = texturer->AddFrame(static_cast<int>(i), sequence_->color[i], sequence_->camera,
                                 sequence_->posed[i]);
    }
    // The seams of the last labelling, levelled on this read (levelling_every_frame false).
    last->seam_rms_before = texturer->seam_rms_before();
    last->seam_rms_after = texturer->seam_rms_after();
    return texturer;
  }

  static TexturingOptions Options() {
    TexturingOptions o;
    o.atlas_size = kAtlasSize;
    return o;
  }

  static Sequence* sequence_;
};

Sequence* TexturingSequenceTest::sequence_ = nullptr;

// Held-out camera: 20 degrees around the subject from the training camera and 0.4 m higher,
// looking at the body.
PinholeCamera HeldOutCamera(const PinholeCamera& training) {
  PinholeCamera camera = training;
  const Eigen::Vector3d target(0.0, 1.0, 0.0);
  const Eigen::Vector3d eye = training.Center();
  const Eigen::Vector3d rotated =
      Eigen::AngleAxisd(20.0 * M_PI / 180.0, Eigen::Vector3d::UnitY()) * (eye - target) + target +
      Eigen::Vector3d(0.0, 0.4, 0.0);
  camera.world_to_camera = PinholeCamera::LookAt(rotated, target, Eigen::Vector3d::UnitY());
  return camera;
}

TEST_F(TexturingSequenceTest, HeldOutViewMatchesTheTrueTexture) {
  ASSERT_EQ(static_cast<int>(sequence_->color.size()), kFrames);
  TextureFrameSummary last;
  const auto texturer = Feed(Options(), &last);
  EXPECT_GT(last.textured_triangles, 0.4 * sequence_->subject.num_triangles());

  const Eigen::MatrixX3d& pose = sequence_->posed[kFrames / 2];  // facing the camera
  const PinholeCamera held_out = HeldOutCamera(sequence_->camera);
  cv::Mat truth, truth_mask, image, mask;
  RenderTextured(sequence_->subject, pose, sequence_->truth_texture, held_out, &truth, &truth_mask);
  RenderTextured(sequence_->subject, pose, texturer->Atlas(), held_out, &image, &mask);
  // Pixels of triangles that some training view textured.
  RasterBuffers raster;
  Rasterize(pose, sequence_->subject.triangles, held_out, RasterOptions(), &raster);
  cv::Mat seen(held_out.height, held_out.width, CV_8UC1, cv::Scalar(0));
  int covered = 0, seen_pixels = 0;
  double se = 0.0;
  for (int y = 0; y < held_out.height; ++y) {
    for (int x = 0; x < held_out.width; ++x) {
      const int f = raster.triangle_id[raster.index(x, y)];
      if (f < 0) continue;
      ++covered;
      if (texturer->triangle_frames()[f] < 0) continue;
      seen.at<uint8_t>(y, x) = 255;
      ++seen_pixels;
      for (int c = 0; c < 3; ++c) {
        const double d = image.at<cv::Vec3b>(y, x)[c] - truth.at<cv::Vec3b>(y, x)[c];
        se += d * d;
      }
    }
  }
  ASSERT_GT(seen_pixels, 0.5 * covered) << seen_pixels << " of " << covered;
  const double psnr = 10.0 * std::log10(255.0 * 255.0 / std::max(se / (3.0 * seen_pixels), 1e-12));
  const double ssim = MaskedSsim(image, truth, seen);
  std::printf("held-out view: %d of %d covered pixels textured, PSNR %.2f dB, SSIM %.3f\n",
              seen_pixels, covered, psnr, ssim);
  EXPECT_GE(psnr, 28.0);
  EXPECT_GT(ssim, 0.8);
}

TEST_F(TexturingSequenceTest, SmoothnessGivesFewerAndSmallerSeams) {
  TexturingOptions none = Options();
  none.selection.terms.lambda = 0.0;
  TextureFrameSummary with_lambda, without_lambda;
  Feed(Options(), &with_lambda);
  Feed(none, &without_lambda);
  std::printf("seam edges %d (lambda = 1) vs %d (lambda = 0); RMS jump %.4f vs %.4f\n",
              with_lambda.seam_edges, without_lambda.seam_edges, with_lambda.seam_rms_before,
              without_lambda.seam_rms_before);
  EXPECT_GT(without_lambda.seam_edges, with_lambda.seam_edges);
  EXPECT_GT(without_lambda.seam_rms_before, with_lambda.seam_rms_before);
}

TEST_F(TexturingSequenceTest, LevellingLowersSeamJumps) {
  TextureFrameSummary last;
  Feed(Options(), &last);
  ASSERT_GT(last.seam_edges, 0);
  std::printf("seam RMS jump %.4f before levelling, %.4f after\n", last.seam_rms_before,
              last.seam_rms_after);
  EXPECT_LT(last.seam_rms_after, 0.5 * last.seam_rms_before);
}

}  // namespace
}  // namespace artex
