// artex track RECORDING --config FILE -o OUT/: preprocessing, EM fitting and on-the-fly
// texturing of every frame (experiments/pipeline.h), with a progress line on stderr. The
// recording is an artex sequence or a TUM RGB-D folder (sensors/frame_source.h).
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "experiments/atomic_output.h"
#include "experiments/commands.h"
#include "experiments/stream_server.h"
#include "experiments/config.h"
#include "experiments/heap_retention.h"
#include "experiments/pipeline.h"
#include "models/error.h"
#include "sensors/frame_source.h"
#include "sensors/scene_segmentation.h"

namespace artex {
namespace {

// A YAML single-quoted scalar holding `text` verbatim (for Config::Set).
std::string YamlQuoted(const std::string& text) {
  std::string out = "'";
  for (char c : text) out += c == '\'' ? std::string("''") : std::string(1, c);
  return out + "'";
}

// The value of input.intrinsics for --intrinsics NAME|FILE: a preset name as is, a file as an
// absolute path (the run's config.yaml must name it from anywhere).
std::string IntrinsicsConfigValue(const std::string& name_or_file) {
  if (TumIntrinsicsPresetNames().count(name_or_file) || name_or_file.empty()) {
    return YamlQuoted(name_or_file);
  }
  std::error_code ec;
  if (!std::filesystem::is_regular_file(name_or_file, ec)) {
    std::string presets;
    for (const auto& kv : TumIntrinsicsPresetNames()) presets += " " + kv.first;
    throw Error("--intrinsics " + name_or_file + ": expected a preset name (" + presets.substr(1) +
                ") or an intrinsics YAML file, found neither");
  }
  return YamlQuoted(std::filesystem::absolute(name_or_file).string());
}

}  // namespace

void RegisterTrackCommand(CLI::App* app) {
  struct Args {
    std::string sequence, config, out, template_path, intrinsics, subject, stream;
    std::vector<std::string> overrides;
    bool export_meshes = false;
    bool no_texture = false;
    int max_frames = 0;
    bool quiet = false;
    bool serve = false;  // --serve: the live stream to the browser viewer (docs/viewer.md)
    double serve_wait_s = 0.0, serve_report_s = 0.0;
    StreamServerOptions server;
    bool live = false, sequential = false;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app->add_subcommand(
      "track", "Fit the template to every frame of a sequence and texture it on the fly");
  cmd->add_option(
         "sequence", args->sequence,
         "recording: an artex sequence folder, a TUM RGB-D folder (rgb.txt, depth.txt) or a "
         ".mkv file")
      ->required();
  cmd->add_option("-c,--config", args->config,
                  "configuration file (YAML); default: built-in defaults");
  cmd->add_option("-o,--output", args->out, "output folder")->required();
  cmd->add_option("-t,--template", args->template_path,
                  "tracking template (.glb, or .bin as artex experiment writes); default: the "
                  "generated default template (from the build's cache)");
  cmd->add_option("-s,--set", args->overrides,
                  "override an option: key=value (e.g. texture.lambda=0)");
  cmd->add_flag("--export-meshes", args->export_meshes,
                "write the posed mesh of every frame (PLY)");
  cmd->add_flag("--no-texture", args->no_texture, "fitting only");
  cmd->add_option("--max-frames", args->max_frames, "process at most this many frames (0: all)");
  cmd->add_option("--intrinsics", args->intrinsics,
                  "TUM RGB-D intrinsics: a YAML file or a preset fr1|fr2|fr3|kinect (default: "
                  "<folder>/camera.yaml; config key input.intrinsics)");
  cmd->add_flag("-q,--quiet", args->quiet, "no progress line");
  cmd->add_flag("--live", args->live,
                "replay the recording at its frame rate as a sensor would, dropping the frames "
                "the pipeline has no room for (config keys pipeline.live, .live_rate_hz)");
  cmd->add_flag("--sequential", args->sequential,
                "run the stages one after another on one thread (config key "
                "pipeline.concurrency: sequential; default pipelined)");
  cmd->add_option("--stream", args->stream,
                  "also write the tele-presence stream (.artx, docs/streaming.md; config key "
                  "pipeline.stream, options in the stream section)");
  cmd->add_option("--subject", args->subject,
                  "who to track without background frames: central (default), nearest, largest, "
                  "or the person at pixel X,Y (config keys preprocess.segmentation.subject, "
                  ".pixel)");
  cmd->add_flag("--serve", args->serve,
                "serve the browser viewer and stream live while tracking (docs/viewer.md; the "
                "stream goes to --stream or OUT/stream.artx)");
  cmd->add_option("--serve-wait", args->serve_wait_s,
                  "with --serve: wait up to this many seconds for a viewer before tracking");
  cmd->add_option("--serve-report-wait", args->serve_report_s,
                  "with --serve: after tracking, wait up to this many seconds for the page's "
                  "final report and print it");
  AddServeOptions(cmd, &args->server);
  cmd->callback([args] {
    Config config = args->config.empty() ? Config() : Config::Load(args->config);
    for (const auto& o : args->overrides) {
      const auto eq = o.find('=');
      if (eq == std::string::npos || eq == 0)
        throw Error("--set " + o + ": expected key=value (e.g. texture.lambda=0)");
      config.Set(o.substr(0, eq), o.substr(eq + 1));
    }
    if (!args->subject.empty()) {
      const auto comma = args->subject.find(',');
      if (comma == std::string::npos) {
        if (!SubjectChoiceNames().count(args->subject) || args->subject == "pixel")
          throw Error("--subject " + args->subject +
                      ": expected central, nearest, largest or a pixel X,Y");
        config.Set("preprocess.segmentation.subject", args->subject);
      } else {
        char* end = nullptr;
        const long x = std::strtol(args->subject.c_str(), &end, 10);
        const bool x_ok = end == args->subject.c_str() + comma;
        const long y = std::strtol(args->subject.c_str() + comma + 1, &end, 10);
        if (!x_ok || *end != '\0' || x < 0 || y < 0)
          throw Error("--subject " + args->subject + ": expected a pixel X,Y (column, row >= 0)");
        config.Set("preprocess.segmentation.subject", "pixel");
        config.Set("preprocess.segmentation.pixel",
                   "[" + std::to_string(x) + ", " + std::to_string(y) + "]");
      }
    }
    if (args->export_meshes) config.Set("pipeline.export_meshes", "true");
    if (args->live) config.Set("pipeline.live", "true");
    if (args->sequential) config.Set("pipeline.concurrency", "sequential");
    if (args->no_texture) config.Set("pipeline.texture", "false");
    if (!args->stream.empty()) config.Set("pipeline.stream", YamlQuoted(args->stream));
    if (args->max_frames > 0) config.Set("pipeline.max_frames", std::to_string(args->max_frames));
    if (!args->intrinsics.empty())
      config.Set("input.intrinsics", IntrinsicsConfigValue(args->intrinsics));
    const PipelineOptions options = LoadPipelineOptions(config);
    // Before any output: the process may start again, with the same arguments.
    if (options.realtime.huge_pages) ReexecWithHugePageHeap(ProgramArguments());
    const bool quiet = args->quiet;
    if (!quiet) {
      const std::string what = OpenFrameSource(args->sequence, options.input)->Description();
      if (!what.empty()) std::fprintf(stderr, "track: input: %s\n", what.c_str());
    }
    // Written into a temporary sibling, published complete at the end (docs/reliability.md).
    AtomicOutputFolder out(args->out, "track");
    PipelineOptions run_options = options;
    std::unique_ptr<StreamServer> server;
    struct TapGuard {
      ~TapGuard() { SetStreamTap(nullptr); }
    } tap_guard;
    if (args->serve) {
      if (run_options.stream_path.empty()) run_options.stream_path = out.path() + "/stream.artx";
      server = std::make_unique<StreamServer>(args->server);
      SetStreamTap(server.get());
      std::fprintf(stderr, "track: viewer at %s?live=1\n", server->Url().c_str());
      if (args->serve_wait_s > 0 && !server->WaitForViewer(args->serve_wait_s))
        std::fprintf(stderr, "track: no viewer after %.0f s; tracking anyway\n", args->serve_wait_s);
    }
    const PipelineResult result = RunPipeline(
        args->sequence, args->template_path, run_options, config, out.path(),
        [quiet](const PipelineProgress& p) {
          if (quiet) return;
          std::fprintf(stderr, "\rtrack: frame %d/%d  %.1f frames/s  EM iterations %d", p.done,
                       p.total, p.frames_per_second, p.last ? p.last->fit.iterations : 0);
          if (p.last && !p.last->skipped) {
            const FitQuality& q = p.last->quality;
            std::fprintf(stderr, "  %s%s (inliers %.2f, support %.2f, residual %.0f mm)",
                         FitQualityLabelName(q.label), p.last->reinitialised ? ", initialised" : "",
                         q.inlier_fraction, q.support_fraction, 1000 * q.depth_residual_m);
          }
          if (p.last && p.last->mean_vertex_error_mm == p.last->mean_vertex_error_mm)
            std::fprintf(stderr, "  error %.1f mm", p.last->mean_vertex_error_mm);
          else if (std::isfinite(p.latest_evaluated_error_mm))  // evaluated in the background
            std::fprintf(stderr, "  error %.1f mm (evaluated behind)", p.latest_evaluated_error_mm);
          std::fprintf(stderr, "   ");
          std::fflush(stderr);
        });
    if (!quiet) std::fprintf(stderr, "\n");
    if (server) {
      SetStreamTap(nullptr);
      server->EndLive();
      if (args->serve_report_s > 0 && !server->WaitForFinalReport(args->serve_report_s))
        std::fprintf(stderr, "track: no final report from a viewer after %.0f s\n",
                     args->serve_report_s);
      PrintServeReport(*server, "track: serve");
      server->Stop();
    }
    out.Commit();
    for (const auto& w : result.warnings) std::fprintf(stderr, "track: warning: %s\n", w.c_str());
    std::printf("frames: %zu: %d good, %d doubtful, %d lost (%d failed fits), %d skipped\n",
                result.frames.size(), result.good_frames, result.doubtful_frames,
                result.lost_frames, result.failed_frames, result.skipped_frames);
    std::printf("initialisations: %d (%.0f ms each)", result.initialisations,
                result.init_ms_per_initialisation);
    if (result.gap_refits > 0) {
      std::printf(", %d frames fitted again after dropped frames", result.gap_refits);
    }
    std::printf("\n");
    std::printf("EM iterations per frame: %.1f\n", result.mean_em_iterations);
    std::printf("fitting: %.1f ms/frame, texturing: %.1f ms/frame\n", result.fit_ms_per_frame,
                result.texture_ms_per_frame);
    if (std::isfinite(result.stream_kbit_per_s)) {
      std::printf("stream estimate: %.1f kbit/s (raw pose + JPEG of the changed atlas patch)\n",
                  result.stream_kbit_per_s);
    }
    if (result.has_stream) {
      const StreamSummary& s = result.stream;
      std::printf(
          "stream: %s: pose %.2f kbit/s, texture %.1f kbit/s, total %.1f kbit/s, %d "
          "keyframes, hand error <= %.3f mm; per frame: atlas picture %.1f ms, encoding %.1f "
          "ms (max %.1f; video CPU %.1f ms)\n",
          args->stream.empty() ? (args->out + "/stream.artx").c_str() : args->stream.c_str(),
          s.pose_kbps, s.texture_kbps, s.total_kbps, s.keyframes, s.max_hand_error_mm,
          s.mean_compose_ms, s.mean_encode_ms, s.max_encode_ms, s.mean_encode_cpu_ms);
      if (s.shapes > 0) {
        std::printf("stream: %d rest shapes of the subject (%.1f kB, in the total)\n", s.shapes,
                    s.shape_bytes / 1000.0);
      }
    }
    if (result.has_ground_truth && result.novel_view_psnr_db == result.novel_view_psnr_db) {
      std::printf(
          "texture vs ground truth (held-out views): PSNR %.2f dB, SSIM %.4f, coverage "
          "%.1f%% (last evaluation; mean PSNR %.2f dB)\n",
          result.novel_view_psnr_db, result.novel_view_ssim, 100.0 * result.texture_coverage,
          result.mean_novel_view_psnr_db);
    }
    if (result.has_ground_truth) {
      std::printf(
          "mean vertex error: %.2f mm (max %.2f mm), mean joint error: %.2f mm, lost: %.1f%% "
          "(errors over %d evaluated frames; %d failed fits count as lost)\n",
          result.mean_vertex_error_mm, result.max_vertex_error_mm, result.mean_joint_error_mm,
          100.0 * result.lost_fraction, result.evaluated_frames, result.failed_frames);
    }
    const RealtimeStats& rt = result.realtime;
    std::printf(
        "%s%s: %d frames processed, %d dropped (%d after the first textured), %d not textured "
        "(%d by texture_every); "
        "%.1f frames/s (%.1f after the first frame), latency median %.0f ms, p95 %.0f ms, "
        "CPU %.0f%%\n",
        rt.concurrency == PipelineConcurrency::kPipelined ? "pipelined" : "sequential",
        rt.live ? " live" : "", rt.frames_processed, rt.frames_dropped,
        rt.frames_dropped_after_first, rt.frames_texture_skipped + rt.frames_texture_not_due,
        rt.frames_texture_not_due, rt.frames_per_second,
        rt.steady_frames_per_second, rt.latency_median_ms, rt.latency_p95_ms,
        100.0 * rt.cpu_utilisation);
    std::printf("results in %s\n", args->out.c_str());
  });
}

}  // namespace artex
