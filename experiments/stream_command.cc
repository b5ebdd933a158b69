// artex stream encode RUN/ -o OUT.artx | artex stream play STREAM -o OUT/: the tele-presence
// stream's sender from a tracked run and its receiver (experiments/stream_evaluation.h,
// docs/streaming.md).
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "experiments/commands.h"
#include "experiments/config.h"
#include "experiments/pipeline.h"
#include "experiments/stream_evaluation.h"
#include "models/error.h"

namespace artex {
namespace {

// RUN/summary.json's first shape swap (shape estimation changed the tracking template after this
// frame), -1 when there was none or the summary cannot be read.
int ShapeSwapFrame(const std::string& run_dir) {
  std::ifstream in(run_dir + "/summary.json");
  if (!in) return -1;
  const nlohmann::json summary = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (!summary.is_object() || !summary.contains("shape")) return -1;
  const nlohmann::json& shape = summary["shape"];
  const auto it = shape.find("calibrated_after_frame");
  return it != shape.end() && it->is_number_integer() ? it->get<int>() : -1;
}

void PrintSummary(const StreamSummary& s, const std::string& path) {
  std::printf("stream: %s: %d frames (%d keyframes) at %.2f Hz\n", path.c_str(), s.frames,
              s.keyframes, s.frame_rate);
  std::printf(
      "bitrate: pose %.2f kbit/s, texture %.1f kbit/s, total %.1f kbit/s (framing "
      "included); header %zu bytes once (template glb %zu)\n",
      s.pose_kbps, s.texture_kbps, s.total_kbps, s.header_bytes, s.glb_bytes);
  std::printf("pose quantisation error at the hands: max %.3f mm, mean %.3f mm\n",
              s.max_hand_error_mm, s.mean_hand_error_mm);
  std::printf("encoding: %.1f ms/frame (max %.1f; video encoder thread CPU %.1f ms/frame)\n",
              s.mean_encode_ms, s.max_encode_ms, s.mean_encode_cpu_ms);
}

}  // namespace

void RegisterStreamCommands(CLI::App* app) {
  CLI::App* stream =
      app->add_subcommand("stream", "Tele-presence stream: encode a run, play a stream");
  stream->require_subcommand(1);
  RegisterStreamServeCommand(stream);

  struct EncodeArgs {
    std::string run, out, config, template_path;
    std::vector<std::string> overrides;
  };
  auto e = std::make_shared<EncodeArgs>();
  CLI::App* enc = stream->add_subcommand(
      "encode", "Encode a tracked run (poses.csv, atlases/ from pipeline.export_atlases) as .artx");
  enc->add_option("run", e->run, "run folder of artex track")->required();
  enc->add_option("-o,--output", e->out, "stream file (.artx)")->required();
  enc->add_option("-c,--config", e->config, "configuration (its stream section is used)");
  enc->add_option("-t,--template", e->template_path, "template (.glb); default RUN/tracked.glb");
  enc->add_option("-s,--set", e->overrides,
                  "override an option: key=value (e.g. stream.texture_kbps=600)");
  enc->callback([e] {
    Config config = e->config.empty() ? Config() : Config::Load(e->config);
    for (const auto& o : e->overrides) {
      const auto eq = o.find('=');
      if (eq == std::string::npos || eq == 0) throw Error("--set " + o + ": expected key=value");
      config.Set(o.substr(0, eq), o.substr(eq + 1));
    }
    const PipelineOptions options = LoadPipelineOptions(config);
    const int swap = ShapeSwapFrame(e->run);
    if (swap >= 0) {
      std::fprintf(stderr,
                   "stream encode: warning: %s was tracked with shape estimation (the template "
                   "changed after frame %d); this stream skins every frame with one template, "
                   "so the frames tracked with an earlier shape are rendered with the wrong body "
                   "(artex track --stream writes each frame's shape)\n",
                   e->run.c_str(), swap);
    }
    PrintSummary(EncodeRunStream(e->run, e->template_path, e->out, options.stream), e->out);
  });

  struct PlayArgs {
    std::string stream, out, reference, sequence;
    int from_frame = 0, render_every = 0, evaluate_every = 5;
    std::vector<double> yaws{20.0, -20.0};
    double height = 0.4, link_kbps = 0.0;
  };
  auto p = std::make_shared<PlayArgs>();
  CLI::App* play = stream->add_subcommand(
      "play", "Decode a stream: receiver's poses, atlas, renders, bitrate, quality, latency");
  play->add_option("stream", p->stream, "stream file (.artx)")->required();
  play->add_option("-o,--output", p->out,
                   "output folder (atlas.png, poses.csv, report.json, renders/)")
      ->required();
  play->add_option("--from-frame", p->from_frame, "join at the first keyframe at or after frame K");
  play->add_option("--render-every", p->render_every, "write renders every n-th frame (0: none)");
  play->add_option("--evaluate-every", p->evaluate_every, "quality every n-th frame");
  play->add_option("--views", p->yaws,
                   "viewpoints: yaw (degrees) about the model from the sender's camera");
  play->add_option("--view-height", p->height, "viewpoints raised by this (m)");
  play->add_option("--link-kbps", p->link_kbps,
                   "link rate of the latency model (kbit/s; 0: the stream's mean rate)");
  play->add_option("--reference", p->reference,
                   "the sender's run folder (with atlases/): quality vs sender");
  play->add_option("--sequence", p->sequence, "the synthetic recording: quality vs ground truth");
  play->callback([p] {
    PlaybackOptions o;
    o.from_frame = p->from_frame;
    o.out_dir = p->out;
    o.render_every = p->render_every;
    o.evaluate_every = p->evaluate_every;
    o.reference_run = p->reference;
    o.sequence = p->sequence;
    o.views.yaws_deg = p->yaws;
    o.views.height = p->height;
    o.link_kbps = p->link_kbps;
    const PlaybackReport r = PlayStream(p->stream, o);
    for (const StreamIssue& i : r.issues)
      std::fprintf(stderr, "stream play: byte %zu, frame %d: %s\n", i.offset, i.frame,
                   i.what.c_str());
    std::printf("played: %d frames (%d keyframes), frames %d..%d, %d records skipped, %zu issues\n",
                r.frames, r.keyframes, r.first_frame, r.last_frame, r.skipped_records,
                r.issues.size());
    std::printf(
        "bitrate: pose %.2f kbit/s, texture %.1f kbit/s, total %.1f kbit/s; header %zu bytes\n",
        r.pose_kbps, r.texture_kbps, r.total_kbps, r.header_bytes);
    std::printf("decoding: %.1f ms/frame (max %.1f)\n", r.mean_decode_ms, r.max_decode_ms);
    std::printf(
        "latency (%s + queue + sending at %.0f kbit/s + decoding): median %.1f ms, max %.1f ms\n",
        r.sender_times ? "sender's composition and encoding" : "sender's time unknown (0)",
        r.link_kbps, r.median_latency_ms, r.max_latency_ms);
    if (std::isfinite(r.psnr_vs_sender_db))
      std::printf(
          "vs sender: novel-view PSNR %.2f dB, SSIM %.4f, atlas PSNR %.2f dB, vertices "
          "within %.3f mm\n",
          r.psnr_vs_sender_db, r.ssim_vs_sender, r.atlas_psnr_db, r.max_vertex_error_mm);
    if (std::isfinite(r.receiver_psnr_db))
      std::printf(
          "vs ground truth: receiver PSNR %.2f dB SSIM %.4f; sender PSNR %.2f dB SSIM %.4f\n",
          r.receiver_psnr_db, r.receiver_ssim, r.sender_psnr_db, r.sender_ssim);
    std::printf("results in %s\n", p->out.c_str());
  });
}

}  // namespace artex
