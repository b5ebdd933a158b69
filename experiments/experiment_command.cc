// `artex experiment FILE -o OUT`: runs every (sequence, configuration) of an experiment file in
// child processes with a progress display, then writes results.csv, summary.md and the plots
// (scripts/plot_results.py). Hidden subcommands `experiment-run` and `experiment-synth` are
// the children's entry points; `artex overlay` draws fitted meshes over input depth frames.
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "experiments/commands.h"
#include "experiments/pose_csv.h"
#include "experiments/runner.h"
#include "models/error.h"
#include "models/normals.h"
#include "models/skinning.h"
#include "models/template_io.h"
#include "render/rasterizer.h"
#include "sensors/sequence.h"

namespace artex {
namespace {
namespace fs = std::filesystem;

struct ExperimentCliOptions {
  std::string file;
  std::string output;
  int jobs = 0;
  int threads = 0;
  bool dry_run = false;
  bool no_plots = false;
  bool replace_changed = false;
};

// A python3 that can import matplotlib ("" when none).
std::string FindPlottingPython() {
  for (const char* candidate : {"python3", "/usr/bin/python3"}) {
    const std::string cmd = std::string(candidate) + " -c 'import matplotlib' >/dev/null 2>&1";
    if (std::system(cmd.c_str()) == 0) return candidate;
  }
  return "";
}

std::string Quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

// Status display: one rewritten line on a terminal, one line per event otherwise.
class ProgressDisplay {
 public:
  ProgressDisplay() : tty_(isatty(STDERR_FILENO)) {}

  void Handle(const RunnerEvent& e) {
    using K = RunnerEvent::Kind;
    switch (e.kind) {
      case K::kPlan:
        Line("experiment: " + std::to_string(e.runs_total) + " runs, " +
             std::to_string(e.runs_skipped) + " already complete (skipped), " +
             std::to_string(e.total) + " to run");
        break;
      case K::kSequenceStarted:
        Line("experiment: generating sequence " + e.label);
        break;
      case K::kSequenceReady:
        Line("experiment: sequence " + e.label + " ready" +
             (e.seconds > 0 ? " (" + Seconds(e.seconds) + ")" : " (reused)"));
        break;
      case K::kRunStarted:
        active_[e.label] = "start";
        Status(e);
        break;
      case K::kRunProgress:
        active_[e.label] = std::to_string(e.done) + "/" + std::to_string(e.total);
        Status(e);
        break;
      case K::kRunSkipped:
        if (!tty_) Line("experiment: skip " + e.label + " (complete)");
        break;
      case K::kRunFinished:
        active_.erase(e.label);
        Line("experiment: [" + std::to_string(e.runs_done) + "/" + std::to_string(e.runs_total) +
             "] done " + e.label + " in " + Seconds(e.seconds));
        break;
      case K::kRunFailed:
        active_.erase(e.label);
        Line("experiment: FAILED " + e.label + ": " + e.message);
        break;
    }
  }

 private:
  static std::string Seconds(double s) {
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%.1f s", s);
    return buf;
  }
  void Line(const std::string& text) {
    if (tty_ && status_shown_) std::fprintf(stderr, "\r\033[K");
    std::fprintf(stderr, "%s\n", text.c_str());
    status_shown_ = false;
    std::fflush(stderr);
  }
  void Status(const RunnerEvent& e) {
    if (!tty_) {
      if (e.kind == RunnerEvent::Kind::kRunStarted) std::fprintf(stderr, "experiment: start %s\n", e.label.c_str());
      return;
    }
    std::string s = "[" + std::to_string(e.runs_done) + "/" + std::to_string(e.runs_total) +
                    " done, " + std::to_string(active_.size()) + " running]";
    for (const auto& kv : active_) s += "  " + kv.first + " " + kv.second;
    if (s.size() > 160) s = s.substr(0, 157) + "...";
    std::fprintf(stderr, "\r\033[K%s", s.c_str());
    status_shown_ = true;
    std::fflush(stderr);
  }

  bool tty_;
  bool status_shown_ = false;
  std::map<std::string, std::string> active_;
};

void RunExperimentCli(const ExperimentCliOptions& cli) {
  if (cli.output.empty()) throw Error("-o/--output: an output folder is required");
  const Experiment experiment = LoadExperiment(cli.file);
  std::fprintf(stderr, "experiment %s: %zu sequences x %zu configurations (validated)\n",
               experiment.name.c_str(), experiment.sequences.size(),
               experiment.combinations.size());
  if (cli.dry_run) {
    for (const auto& s : experiment.sequences) {
      for (const auto& c : experiment.combinations) {
        std::printf("%s\n", RunFolder(cli.output, s.name, c.id).c_str());
      }
    }
  }
  RunnerOptions options;
  options.jobs = cli.jobs;
  options.threads_per_run = cli.threads;
  options.dry_run = cli.dry_run;
  options.replace_changed = cli.replace_changed;
  ProgressDisplay display;
  const ExperimentSummary summary =
      RunExperiment(experiment, cli.output, options, [&](const RunnerEvent& e) { display.Handle(e); });
  if (cli.dry_run) return;
  std::fprintf(stderr,
               "experiment: %d runs: %d completed now, %d skipped (complete before), %d failed; "
               "%.1f s\n",
               summary.runs_total, summary.runs_completed, summary.runs_skipped, summary.runs_failed,
               summary.seconds);
  std::fprintf(stderr, "experiment: wrote %s/results.csv and %s/summary.md\n", cli.output.c_str(),
               cli.output.c_str());
  const std::string script = (fs::path(SourceDirectory()) / "scripts" / "plot_results.py").string();
  if (!cli.no_plots && summary.runs_completed + summary.runs_skipped > 0) {
    const std::string python = FindPlottingPython();
    if (python.empty() || !fs::exists(script)) {
      std::fprintf(stderr,
                   "experiment: plots not made (needs python3 with matplotlib); run:\n"
                   "  python3 %s %s\n",
                   script.c_str(), cli.output.c_str());
    } else {
      const std::string cmd = python + " " + Quote(script) + " " + Quote(cli.output);
      if (std::system(cmd.c_str()) != 0) {
        std::fprintf(stderr, "experiment: plotting failed; rerun: %s\n", cmd.c_str());
      }
    }
  }
  if (summary.runs_failed > 0) {
    std::string msg = std::to_string(summary.runs_failed) + " run(s) failed (rerun to retry):";
    for (const auto& f : summary.failures) msg += "\n  " + f;
    throw Error(msg);
  }
}

// ---- artex overlay ---------------------------------------------------------------------------

struct OverlayCliOptions {
  std::string run;
  std::string sequence;       // default: run.json's sequence_folder
  std::string template_path;  // default: run.json's template
  std::vector<int> frames;
  std::string output;
  double scale = 1.0;         // of each panel relative to the depth image
  double mesh_opacity = 0.45;
  bool wireframe = false;
};

std::string ReadAll(const std::string& path) {
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) throw Error(path + ": cannot open");
  std::string text;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof(buf), f)) > 0) text.append(buf, n);
  std::fclose(f);
  return text;
}

// Rows of RUN/poses.csv by frame index.
std::map<int, Pose> ReadPoses(const std::string& path, int num_joints) {
  std::map<int, Pose> poses;
  for (auto& [frame, pose] : ReadPoseCsv(path, num_joints)) poses[frame] = pose;
  return poses;
}

// Depth (CV_16UC1) -> TURBO colour map over the frame's valid range (near = red), missing black.
cv::Mat ColorMapDepth(const cv::Mat& depth) {
  double lo = 0, hi = 0;
  cv::minMaxLoc(depth, nullptr, &hi);
  cv::Mat valid = depth > 0;
  cv::minMaxLoc(depth, &lo, nullptr, nullptr, nullptr, valid);
  cv::Mat gray;
  depth.convertTo(gray, CV_8U, hi > lo ? -255.0 / (hi - lo) : 0.0, hi > lo ? 255.0 * hi / (hi - lo) : 0.0);
  cv::Mat color;
  cv::applyColorMap(gray, color, cv::COLORMAP_TURBO);
  color.setTo(cv::Scalar(0, 0, 0), ~valid);
  return color;
}

// One panel: the depth image colour-mapped, the fitted mesh shaded (Lambert, grey) blended on
// top, its silhouette outlined in white and optionally its visible wireframe.
cv::Mat OverlayPanel(const cv::Mat& depth, const PinholeCamera& camera, const Template& tmpl,
                     const Eigen::MatrixX3d& posed, const OverlayCliOptions& cli) {
  cv::Mat panel = ColorMapDepth(depth);
  RasterBuffers buffers;
  Rasterize(posed, tmpl.triangles, camera, RasterOptions(), &buffers);
  Eigen::MatrixX3d normals;
  ComputeVertexNormals(posed, tmpl.triangles, &normals);
  const Eigen::Matrix3d r = camera.world_to_camera.linear();
  cv::Mat mask(camera.height, camera.width, CV_8UC1, cv::Scalar(0));
  cv::Mat shade = panel.clone();
  std::vector<uint8_t> visible(tmpl.num_triangles(), 0);
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      const int i = buffers.index(x, y);
      const int f = buffers.triangle_id[i];
      if (f < 0) continue;
      visible[f] = 1;
      const double b1 = buffers.barycentric[i].x(), b2 = buffers.barycentric[i].y();
      Eigen::Vector3d n = (1 - b1 - b2) * normals.row(tmpl.triangles(f, 0)).transpose() +
                          b1 * normals.row(tmpl.triangles(f, 1)).transpose() +
                          b2 * normals.row(tmpl.triangles(f, 2)).transpose();
      n = r * n.normalized();
      const double lambert = 0.25 + 0.75 * std::max(0.0, -n.z());
      const auto g = static_cast<uint8_t>(255 * lambert);
      shade.at<cv::Vec3b>(y, x) = cv::Vec3b(g, g, g);
      mask.at<uint8_t>(y, x) = 255;
    }
  }
  cv::Mat blended;
  cv::addWeighted(panel, 1.0 - cli.mesh_opacity, shade, cli.mesh_opacity, 0.0, blended);
  blended.copyTo(panel, mask);
  if (cli.wireframe) {
    for (int f = 0; f < tmpl.num_triangles(); ++f) {
      if (!visible[f]) continue;
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector2d a = camera.Project(posed.row(tmpl.triangles(f, k)).transpose());
        const Eigen::Vector2d b = camera.Project(posed.row(tmpl.triangles(f, (k + 1) % 3)).transpose());
        cv::line(panel, cv::Point2d(a.x(), a.y()), cv::Point2d(b.x(), b.y()), cv::Scalar(40, 40, 40), 1,
                 cv::LINE_AA);
      }
    }
  }
  std::vector<std::vector<cv::Point>> contours;
  cv::findContours(mask, contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_NONE);
  cv::drawContours(panel, contours, -1, cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  return panel;
}

void RunOverlay(const OverlayCliOptions& cli) {
  std::string sequence = cli.sequence, template_path = cli.template_path;
  const std::string run_json = cli.run + "/run.json";
  if ((sequence.empty() || template_path.empty()) && fs::exists(run_json)) {
    const auto info = nlohmann::json::parse(ReadAll(run_json));
    if (sequence.empty()) sequence = info.value("sequence_folder", "");
    if (template_path.empty()) template_path = info.value("template", "");
  }
  if (sequence.empty()) throw Error("--sequence: required (the run has no run.json naming it)");
  const Template tmpl = template_path.empty() ? ReadTemplateGlb(cli.run + "/tracked.glb")
                                              : ReadTemplateGlb(template_path);
  const std::map<int, Pose> poses = ReadPoses(cli.run + "/poses.csv", tmpl.num_joints());
  if (poses.empty()) throw Error(cli.run + "/poses.csv: no poses");
  std::vector<int> frames = cli.frames;
  if (frames.empty()) frames.push_back(poses.rbegin()->first);
  SequenceReader reader(sequence);
  const Skinning skinning(tmpl);
  std::vector<cv::Mat> panels;
  for (int f : frames) {
    auto it = poses.find(f);
    if (it == poses.end()) {
      throw Error("--frames: frame " + std::to_string(f) + " has no pose in " + cli.run +
                  "/poses.csv (fitted frames " + std::to_string(poses.begin()->first) + ".." +
                  std::to_string(poses.rbegin()->first) + ")");
    }
    Frame frame;
    std::string warning;
    if (!reader.ReadFrame(f, &frame, &warning)) throw Error(sequence + ": frame " + std::to_string(f) + ": " + warning);
    Eigen::MatrixX3d posed;
    skinning.Apply(it->second, &posed);
    cv::Mat panel = OverlayPanel(frame.depth, reader.calibration().depth, tmpl, posed, cli);
    if (cli.scale != 1.0) cv::resize(panel, panel, cv::Size(), cli.scale, cli.scale, cv::INTER_AREA);
    const std::string text = "frame " + std::to_string(f);
    cv::putText(panel, text, cv::Point(6, 18), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(0, 0, 0), 3, cv::LINE_AA);
    cv::putText(panel, text, cv::Point(6, 18), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1,
                cv::LINE_AA);
    panels.push_back(panel);
  }
  cv::Mat strip;
  cv::hconcat(panels, strip);
  WriteImageAtomic(cli.output, strip);
  std::fprintf(stderr, "overlay: wrote %s (%zu frames)\n", cli.output.c_str(), panels.size());
}

void PrintProgress(int done, int total) {
  std::printf("progress %d %d\n", done, total);
  std::fflush(stdout);
}

}  // namespace

void RegisterExperimentCommand(CLI::App* app) {
  auto cli = std::make_shared<ExperimentCliOptions>();
  CLI::App* sub = app->add_subcommand(
      "experiment",
      "Run every sequence x configuration of an experiment file (resumable), then write "
      "results.csv, summary.md and plots");
  sub->add_option("file", cli->file, "Experiment file (YAML; docs/experiments.md)")
      ->required()
      ->check(CLI::ExistingFile);
  sub->add_option("-o,--output", cli->output, "Output folder (runs, sequences, results)")->required();
  sub->add_option("-j,--jobs", cli->jobs, "Runs at a time (0: number of cores)")
      ->capture_default_str()
      ->check(CLI::Range(0, 256));
  sub->add_option("--threads-per-run", cli->threads,
                  "Worker threads per run (0: cores / jobs, at least 1)")
      ->capture_default_str()
      ->check(CLI::Range(0, 256));
  sub->add_flag("--dry-run", cli->dry_run, "Validate and list the run folders; run nothing");
  sub->add_flag("--no-plots", cli->no_plots, "Do not call scripts/plot_results.py");
  sub->add_flag("--replace-changed", cli->replace_changed,
                "Recompute complete runs (and regenerate sequences) whose inputs changed instead of "
                "stopping with an error");
  sub->callback([cli]() { RunExperimentCli(*cli); });

  // Child entry points (not listed in the help).
  struct RunArgs {
    std::string config, sequence, template_path, out;
    int threads = 0;
  };
  auto run = std::make_shared<RunArgs>();
  CLI::App* run_sub = app->add_subcommand("experiment-run", "One run of an experiment (internal)");
  run_sub->group("");
  run_sub->add_option("--config", run->config)->required();
  run_sub->add_option("--sequence", run->sequence)->required();
  run_sub->add_option("--template", run->template_path);
  run_sub->add_option("--out", run->out)->required();
  run_sub->add_option("--threads", run->threads);
  run_sub->callback([run]() {
    RunSingle(run->config, run->sequence, run->template_path, run->out, run->threads, PrintProgress);
  });

  struct SynthArgs {
    std::string spec, name, out;
  };
  auto synth = std::make_shared<SynthArgs>();
  CLI::App* synth_sub =
      app->add_subcommand("experiment-synth", "Generate an experiment's synthetic sequence (internal)");
  synth_sub->group("");
  synth_sub->add_option("--spec", synth->spec)->required();
  synth_sub->add_option("--name", synth->name);
  synth_sub->add_option("--out", synth->out)->required();
  synth_sub->callback([synth]() {
    std::string text;
    {
      FILE* f = std::fopen(synth->spec.c_str(), "rb");
      if (!f) throw Error(synth->spec + ": cannot open the synthesis spec");
      char buf[4096];
      std::size_t n;
      while ((n = std::fread(buf, 1, sizeof(buf), f)) > 0) text.append(buf, n);
      std::fclose(f);
    }
    while (!text.empty() && text.back() == '\n') text.pop_back();
    GenerateSyntheticSequence(text, synth->name.empty() ? synth->spec : synth->name, synth->out,
                              PrintProgress);
  });

  auto overlay = std::make_shared<OverlayCliOptions>();
  CLI::App* overlay_sub = app->add_subcommand(
      "overlay",
      "Draw the fitted template of a run over its input depth frames (paper Fig. 3): one panel "
      "per frame, side by side");
  overlay_sub->add_option("run", overlay->run, "Run folder (artex track / experiment run)")
      ->required()
      ->check(CLI::ExistingDirectory);
  overlay_sub->add_option("--sequence", overlay->sequence, "Sequence folder (default: from run.json)");
  overlay_sub->add_option("--template", overlay->template_path,
                          "Tracking template .glb (default: from run.json, else RUN/tracked.glb)");
  overlay_sub->add_option("--frames", overlay->frames, "Frame indices (default: the last fitted frame)")
      ->delimiter(',');
  overlay_sub->add_option("-o,--output", overlay->output, "Output PNG")->required();
  overlay_sub->add_option("--scale", overlay->scale, "Panel scale relative to the depth image")
      ->capture_default_str()
      ->check(CLI::Range(0.1, 4.0));
  overlay_sub->add_option("--mesh-opacity", overlay->mesh_opacity, "Opacity of the shaded mesh")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  overlay_sub->add_flag("--wireframe", overlay->wireframe, "Also draw the visible triangle edges");
  overlay_sub->callback([overlay]() { RunOverlay(*overlay); });

}

}  // namespace artex
