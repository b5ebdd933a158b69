// The tele-presence stream (stream/, docs/streaming.md) per frame: pose encoding and decoding,
// the sender's atlas picture (ComposeAtlas of the default 1024^2 atlas) and the atlas video
// encoded and decoded with each codec and encoder setting. The atlas is the procedural subject
// texture of the default template (GenerateSubjectTexture) in which, every frame, 1/8 of the
// charts' area is redrawn slightly shifted and re-exposed (as incremental texturing resamples
// changed triangles from a newer image).
//
// BM_PoseEncode / BM_PoseDecode: one frame of the default template's pose (17 joints) on a walk.
// BM_ComposeAtlas: Texturer::Atlas() of the default atlas (levelling corrections, 4 padding
//   passes): the picture the sender encodes every frame.
// BM_AtlasEncode/codec/kbps/speed/threads: codec 1 VP9 (libvpx, realtime, cpu-used = speed, at
//   most 8 in FFmpeg),
//   2 H.264 (libx264, preset 9 - speed: 8 superfast, 9 ultrafast, 7 veryfast; zerolatency);
//   wall time per frame and the CPU time of all the process's threads (the encoder's threads
//   included); counters: bytes per delta frame, PSNR of the decoded atlas (decoding not timed).
// BM_AtlasDecode/codec: decoding of the same packets (one thread, as the player).
#include <benchmark/benchmark.h>

#include <cmath>
#include <memory>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "models/so3.h"
#include "models/template_generator.h"
#include "sensors/motion.h"
#include "sensors/subject_texture.h"
#include "stream/pose_codec.h"
#include "stream/video_codec.h"
#include "texture/texel_sampling.h"

namespace artex {
namespace {

constexpr int kAtlasSide = 1024;
constexpr int kFrames = 30;

const std::vector<cv::Mat>& Atlases() {
  static const std::vector<cv::Mat> atlases = [] {
    const Template tmpl = GenerateTemplate();
    SubjectTextureOptions o;
    o.size = kAtlasSide;
    const cv::Mat base = GenerateSubjectTexture(tmpl, o);
    std::vector<cv::Mat> out;
    cv::Mat current = base.clone();
    for (int f = 0; f < kFrames; ++f) {
      const int band = kAtlasSide / 8;
      const cv::Rect region(0, (f * band) % kAtlasSide, kAtlasSide, band);
      cv::Mat shifted;
      const cv::Mat m = (cv::Mat_<double>(2, 3) << 1, 0, 0.5 * ((f % 3) - 1), 0, 1, 0.3);
      cv::warpAffine(base(region), shifted, m, region.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
      shifted.convertTo(current(region), -1, 1.0 + 0.01 * ((f % 5) - 2), 0.0);
      out.push_back(current.clone());
    }
    return out;
  }();
  return atlases;
}

std::vector<Pose> WalkPoses() {
  const Template tmpl = GenerateTemplate();
  MotionOptions mo;
  mo.type = MotionType::kWalk;
  mo.frames = kFrames;
  return GenerateMotion(tmpl, mo);
}

void BM_PoseEncode(benchmark::State& state) {
  const std::vector<Pose> poses = WalkPoses();
  PoseEncoder enc(poses[0].num_joints(), PoseCodecOptions());
  int f = 0;
  std::size_t bytes = 0;
  for (auto _ : state) {
    const auto out = enc.Encode(poses[f % kFrames], f % 60 == 0);
    bytes += out.size();
    ++f;
  }
  state.counters["bytes_per_frame"] = static_cast<double>(bytes) / f;
}
BENCHMARK(BM_PoseEncode);

void BM_PoseDecode(benchmark::State& state) {
  const std::vector<Pose> poses = WalkPoses();
  PoseEncoder enc(poses[0].num_joints(), PoseCodecOptions());
  std::vector<std::vector<uint8_t>> packets;
  for (int f = 0; f < kFrames; ++f) packets.push_back(enc.Encode(poses[f], f == 0));
  PoseDecoder dec(poses[0].num_joints(), PoseCodecOptions());
  int f = 0;
  Pose p;
  std::string why;
  for (auto _ : state) {
    const int k = f % kFrames;
    if (!dec.Decode(packets[k].data(), packets[k].size(), k == 0, &p, &why))
      state.SkipWithError(why.c_str());
    ++f;
  }
}
BENCHMARK(BM_PoseDecode);

void BM_ComposeAtlas(benchmark::State& state) {
  const Template tmpl = GenerateTemplate();
  const AtlasMap map(tmpl, kAtlasSide);
  const cv::Mat& source = Atlases()[0];
  TexelBuffer texels(map);
  cv::RNG rng(1);
  for (int f = 0; f < map.num_triangles(); ++f) {
    const bool textured = f % 9 != 0;  // some triangles untextured: holes to pad
    for (int p = map.first(f); p < map.last(f); ++p) {
      const int t = *(map.texels_begin(f) + (p - map.first(f)));
      const cv::Vec3b c = source.at<cv::Vec3b>(t / kAtlasSide, t % kAtlasSide);
      texels.valid[p] = textured;
      if (textured) texels.color[p] = Eigen::Vector3f(c[0], c[1], c[2]) / 255.0f;
    }
  }
  Eigen::MatrixX3f corrections(3 * map.num_triangles(), 3);
  for (int r = 0; r < corrections.rows(); ++r)
    for (int c = 0; c < 3; ++c) corrections(r, c) = rng.uniform(-0.02f, 0.02f);
  for (auto _ : state) {
    cv::Mat atlas = ComposeAtlas(map, texels, &corrections, 4);
    benchmark::DoNotOptimize(atlas.data);
  }
}
BENCHMARK(BM_ComposeAtlas)
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()
    ->UseRealTime()
    ->Iterations(kFrames);

void BM_AtlasEncode(benchmark::State& state) {
  const std::vector<cv::Mat>& atlases = Atlases();
  VideoEncoderOptions o;
  o.codec = static_cast<VideoCodec>(state.range(0));
  o.bitrate_kbps = static_cast<int>(state.range(1));
  o.speed = static_cast<int>(state.range(2));
  o.threads = static_cast<int>(state.range(3));
  std::unique_ptr<AtlasVideoEncoder> enc;
  AtlasVideoDecoder dec(o.codec, kAtlasSide, kAtlasSide);
  int f = 0;
  double bytes = 0.0, psnr = 0.0;
  int measured = 0;
  for (auto _ : state) {
    if (f % kFrames == 0) {
      state.PauseTiming();
      enc = std::make_unique<AtlasVideoEncoder>(kAtlasSide, kAtlasSide, 30.0, o);
      dec.Reset();
      state.ResumeTiming();
    }
    bool key = false;
    const std::vector<uint8_t> packet = enc->Encode(atlases[f % kFrames], f % kFrames == 0, &key);
    state.PauseTiming();
    if (f % kFrames != 0) bytes += packet.size();
    cv::Mat decoded;
    std::string why;
    if (dec.Decode(packet.data(), packet.size(), &decoded, &why)) {
      psnr += ImagePsnr(decoded, atlases[f % kFrames]);
      ++measured;
    }
    state.ResumeTiming();
    ++f;
  }
  const int deltas = f - (f + kFrames - 1) / kFrames;
  state.counters["delta_bytes_per_frame"] = deltas > 0 ? bytes / deltas : 0.0;
  state.counters["psnr_db"] = measured ? psnr / measured : 0.0;
}
BENCHMARK(BM_AtlasEncode)
    ->ArgNames({"codec", "kbps", "speed", "threads"})
    ->Args({1, 600, 8, 2})  // VP9 before: cpu-used 8, 2 threads
    ->Args({1, 600, 8, 1})  // VP9 default (cpu-used 8 is FFmpeg's fastest)
    ->Args({1, 600, 7, 1})
    ->Args({1, 600, 6, 1})
    ->Args({2, 600, 9, 1})  // H.264 ultrafast
    ->Args({2, 600, 8, 1})  // H.264 superfast
    ->Args({2, 600, 8, 2})
    ->Args({2, 600, 7, 1})  // H.264 veryfast
    ->Args({1, 1500, 8, 1})
    ->Args({2, 1500, 8, 1})
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()
    ->UseRealTime()
    ->Iterations(kFrames);

void BM_AtlasDecode(benchmark::State& state) {
  const std::vector<cv::Mat>& atlases = Atlases();
  VideoEncoderOptions o;
  o.codec = static_cast<VideoCodec>(state.range(0));
  AtlasVideoEncoder enc(kAtlasSide, kAtlasSide, 30.0, o);
  std::vector<std::vector<uint8_t>> packets;
  for (int f = 0; f < kFrames; ++f) {
    bool key = false;
    packets.push_back(enc.Encode(atlases[f], f == 0, &key));
  }
  AtlasVideoDecoder dec(o.codec, kAtlasSide, kAtlasSide);
  int f = 0;
  cv::Mat image;
  std::string why;
  for (auto _ : state) {
    const int k = f % kFrames;
    if (k == 0) dec.Reset();
    if (!dec.Decode(packets[k].data(), packets[k].size(), &image, &why))
      state.SkipWithError(why.c_str());
    ++f;
  }
}
BENCHMARK(BM_AtlasDecode)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->Iterations(kFrames);

}  // namespace
}  // namespace artex
