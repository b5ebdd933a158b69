// The stream through the pipeline: `artex track --stream` (pipeline.stream) with exported
// atlases and texture quality against ground truth in metrics.json, `artex stream encode RUN/`
// of the same run, and `artex stream play` against the sender's run and the ground truth.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "experiments/config.h"
#include "experiments/pipeline.h"
#include "experiments/stream_evaluation.h"
#include "models/template_io.h"
#include "sensors/virtual_kinect.h"
#include "stream/stream_player.h"
#include "tests/solvers/virtual_kinect_scans.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

class StreamPipelineTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    SynthOptions options = testing_util::SmallSequenceOptions(8);
    options.kinect.color_width = 320;
    options.kinect.color_height = 406;
    data_ = new testing_util::SequenceFixture("stream_pipeline_test", options);

    Config config;
    config.Set("texture.atlas_size", "256");
    config.Set("pipeline.export_atlases", "true");
    config.Set("pipeline.texture_quality_every", "4");
    config.Set("pipeline.stream", "'" + (data_->root / "track.artx").string() + "'");
    config.Set("stream.keyframe_interval", "4");
    config.Set("stream.texture_kbps", "600");
    result_ = new PipelineResult(RunPipeline(data_->sequence, data_->template_path,
                                             LoadPipelineOptions(config), config,
                                             (data_->root / "run").string()));
  }
  static void TearDownTestSuite() {
    delete data_;
    delete result_;
  }
  static testing_util::SequenceFixture* data_;
  static PipelineResult* result_;
};

testing_util::SequenceFixture* StreamPipelineTest::data_ = nullptr;
PipelineResult* StreamPipelineTest::result_ = nullptr;

TEST_F(StreamPipelineTest, MetricsHaveTextureQualityAndStreamRates) {
  std::ifstream in(data_->root / "run" / "metrics.json");
  std::stringstream s;
  s << in.rdbuf();
  const nlohmann::json m = nlohmann::json::parse(s.str());
  const double psnr = m.at("novel_view_psnr_db").get<double>();
  const double coverage = m.at("texture_coverage").get<double>();
  std::printf("novel view: PSNR %.2f dB, SSIM %.3f, coverage %.3f; stream %.1f kbit/s\n", psnr,
              m.at("novel_view_ssim").get<double>(), coverage,
              m.at("stream").at("total_kbit_per_s").get<double>());
  EXPECT_GT(psnr, 10.0);
  EXPECT_LT(psnr, 60.0);
  EXPECT_GT(coverage, 0.3);
  EXPECT_LE(coverage, 1.0);
  ASSERT_TRUE(result_->has_stream);
  EXPECT_EQ(result_->stream.frames, 8);
  EXPECT_EQ(result_->stream.keyframes, 2);
  EXPECT_GT(m.at("stream").at("pose_kbit_per_s").get<double>(), 0.0);
  EXPECT_LT(result_->stream.max_hand_error_mm, 1.0);
  // Evaluated every 4th frame and at the last: frames 3 and 7.
  int evaluated = 0;
  for (const FrameRecord& r : result_->frames) evaluated += r.texture_quality.views > 0;
  EXPECT_EQ(evaluated, 2);
}

TEST_F(StreamPipelineTest, PlayedStreamMatchesTheSender) {
  // The track's stream and a re-encoding of the run's exported atlases are the same frames.
  StreamOptions o;
  o.keyframe_interval = 4;
  o.video.bitrate_kbps = 600;
  const StreamSummary again = EncodeRunStream((data_->root / "run").string(), "",
                                              (data_->root / "encoded.artx").string(), o);
  EXPECT_EQ(again.frames, result_->stream.frames);
  EXPECT_EQ(again.pose_bytes, result_->stream.pose_bytes);
  PlaybackOptions p;
  p.out_dir = (data_->root / "play").string();
  p.evaluate_every = 1;
  p.reference_run = (data_->root / "run").string();
  p.sequence = data_->sequence;
  const PlaybackReport r = PlayStream((data_->root / "track.artx").string(), p);
  std::printf(
      "receiver: vs sender PSNR %.2f dB SSIM %.3f (atlas %.2f dB, vertices %.3f mm); vs "
      "truth %.2f dB (sender %.2f dB)\n",
      r.psnr_vs_sender_db, r.ssim_vs_sender, r.atlas_psnr_db, r.max_vertex_error_mm,
      r.receiver_psnr_db, r.sender_psnr_db);
  EXPECT_EQ(r.frames, 8);
  EXPECT_TRUE(r.issues.empty());
  EXPECT_GT(r.psnr_vs_sender_db, 25.0);  // 4:2:0 video of a 256^2 atlas (docs/streaming.md)
  EXPECT_LT(r.max_vertex_error_mm, 1.0);
  EXPECT_LT(std::abs(r.receiver_psnr_db - r.sender_psnr_db), 1.0);
  EXPECT_TRUE(fs::exists(data_->root / "play" / "atlas.png"));
  EXPECT_TRUE(fs::exists(data_->root / "play" / "report.json"));
  // The sender's times come from the run's stream_frames.csv: every frame's latency covers them.
  EXPECT_TRUE(fs::exists(data_->root / "run" / "stream_frames.csv"));
  EXPECT_TRUE(r.sender_times);
  EXPECT_GT(r.median_latency_ms, 0.0);
  EXPECT_GE(r.max_latency_ms, r.median_latency_ms);
  // Joining at frame 2 starts at the keyframe of frame 4.
  p.from_frame = 2;
  p.out_dir.clear();
  const PlaybackReport joined = PlayStream((data_->root / "track.artx").string(), p);
  EXPECT_EQ(joined.first_frame, 4);
  EXPECT_EQ(joined.frames, 4);
}

// With shape estimation (docs/shape.md) every swap of the tracking template reaches the
// receiver: the record of the first frame posed with the new shape carries it, so the player's
// model follows the sender's, ending at the template the last frames were tracked with.
TEST_F(StreamPipelineTest, TheStreamCarriesTheSubjectsShape) {
  Config config;
  config.Set("texture.atlas_size", "256");
  config.Set("pipeline.stream", "'" + (data_->root / "shape.artx").string() + "'");
  config.Set("shape.mode", "bones_girth");
  config.Set("shape.calibration_frames", "1");
  config.Set("shape.calibration_rounds", "1");
  config.Set("shape.iterations_per_stage", "2");
  config.Set("shape.detail.frames", "1");
  config.Set("fitting.scale_estimation_frames", "2");
  const PipelineResult run =
      RunPipeline(data_->sequence, data_->template_path, LoadPipelineOptions(config), config,
                  (data_->root / "run_shape").string());
  // The round's swap and the detail's, each after a frame that is not the last.
  std::vector<int> swaps;
  for (int f : {run.shape_calibrated_frame, run.shape_detail_frame})
    if (f >= 0 && f + 1 < 8) swaps.push_back(f);
  ASSERT_EQ(swaps.size(), 2u) << run.shape_calibrated_frame << " " << run.shape_detail_frame;
  EXPECT_EQ(run.stream.shapes, 2);
  StreamPlayer player((data_->root / "shape.artx").string());
  const Template initial = player.model();
  std::vector<int> changed;
  PlayedFrame f;
  while (player.Next(&f)) {
    if (f.shape_changed) {
      changed.push_back(f.frame - 1);
      EXPECT_TRUE(f.keyframe) << f.frame;
    }
  }
  EXPECT_EQ(changed, swaps);
  EXPECT_TRUE(player.issues().empty());
  const Template tracked = ReadTemplateGlb((data_->root / "run_shape" / "tracked.glb").string());
  ASSERT_EQ(tracked.num_vertices(), player.model().num_vertices());
  // Within the payload's 0.1 mm step (and the glTF's float32).
  EXPECT_LT((player.model().vertices - tracked.vertices).rowwise().norm().maxCoeff(), 1e-4);
  EXPECT_GT((initial.vertices - tracked.vertices).rowwise().norm().maxCoeff(), 1e-3);
  for (int j = 0; j < tracked.num_joints(); ++j)
    EXPECT_LT((player.model().joints[j].center - tracked.joints[j].center).norm(), 1e-5);
}

// The latency model: records sent one after another over the link, each after the sender's time.
TEST(StreamLatencyTest, RecordsQueueBehindALargeKeyframe) {
  // 30 Hz, a link of 240 kbit/s: a 1,000-byte record takes 33.33 ms, a 5,000-byte one 166.7 ms.
  std::vector<FrameTiming> t(4);
  for (int k = 0; k < 4; ++k) {
    t[k].frame = k;
    t[k].record_bytes = k == 0 ? 5000 : 1000;
    t[k].sender_ms = 10.0;
    t[k].decode_ms = 2.0;
  }
  StreamLatency(30.0, 240.0, &t);
  EXPECT_NEAR(t[0].queue_ms, 0.0, 1e-9);
  EXPECT_NEAR(t[0].latency_ms, 10.0 + 166.667 + 2.0, 1e-2);
  // Frame 1 is ready at 33.3 + 10 ms but the link is busy until 176.7 ms.
  EXPECT_NEAR(t[1].queue_ms, 176.667 - 43.333, 1e-2);
  EXPECT_NEAR(t[1].latency_ms, 176.667 + 33.333 + 2.0 - 33.333, 1e-2);
  // Each later frame is still behind by the keyframe's extra 133.3 ms.
  EXPECT_NEAR(t[3].latency_ms, t[1].latency_ms, 1e-6);
  // A faster link removes the queue.
  StreamLatency(30.0, 2400.0, &t);
  for (const FrameTiming& f : t) EXPECT_NEAR(f.queue_ms, 0.0, 1e-9) << "frame " << f.frame;
  EXPECT_NEAR(t[2].latency_ms, 10.0 + 3.333 + 2.0, 1e-2);
}

}  // namespace
}  // namespace artex
