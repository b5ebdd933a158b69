// artex overlay [SEQ] RUN -o DIR|FILE.png: the fitted template of a run (RUN/poses.csv) drawn over
// the frames of its recording (experiments/overlay.h): DIR/NNNNNN.png per frame and a contact
// sheet DIR/overview.png, or (-o FILE.png) the chosen frames side by side in one image.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "experiments/commands.h"
#include "experiments/config.h"
#include "experiments/file_util.h"
#include "experiments/overlay.h"
#include "experiments/pipeline.h"
#include "experiments/pose_csv.h"
#include "models/error.h"
#include "models/skinning.h"
#include "models/template_cache.h"
#include "models/template_io.h"
#include "sensors/frame_source.h"

namespace artex {
namespace {
namespace fs = std::filesystem;

struct OverlayCli {
  std::vector<std::string> paths;  // [SEQ] RUN
  std::string output;
  std::string template_path;
  std::string intrinsics;
  std::string over = "color";
  std::vector<int> frames;
  int columns = 0;        // contact sheet columns (0: about square)
  int sheet_frames = 12;  // frames in the contact sheet, evenly spread (0: all)
  int tile_width = 320;   // contact sheet tile width (pixels)
  double scale = 1.0;     // -o FILE.png: panel scale
  OverlayOptions overlay;
  bool quiet = false;
};

// A string field of a JSON file of the run ("" when the file or field is absent).
std::string JsonField(const std::string& path, const std::string& key) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return "";
  try {
    const auto j = nlohmann::json::parse(ReadTextOrThrow(path));
    return j.contains(key) && j[key].is_string() ? j[key].get<std::string>() : "";
  } catch (const nlohmann::json::exception& e) {
    throw Error(path + ": not valid JSON: " + e.what());
  }
}

void WritePng(const std::string& path, const cv::Mat& image) { WriteImageAtomic(path, image); }

void RunOverlay(const OverlayCli& cli) {
  if (cli.paths.empty() || cli.paths.size() > 2) {
    throw Error("overlay: expected [SEQUENCE] RUN, found " + std::to_string(cli.paths.size()) +
                " folders");
  }
  const std::string run = cli.paths.back();
  std::error_code ec;
  if (!fs::is_directory(run, ec))
    throw Error(run + ": expected a run folder (artex track -o), found none");
  const std::string run_json = run + "/run.json", summary = run + "/summary.json";
  std::string sequence = cli.paths.size() == 2 ? cli.paths[0] : "";
  if (sequence.empty()) sequence = JsonField(run_json, "sequence_folder");
  if (sequence.empty()) sequence = JsonField(summary, "sequence");
  // Runs of older versions stored the recording as given on the command line: a relative path
  // is tried from here, then next to the run folder.
  if (!sequence.empty() && cli.paths.size() == 1 && fs::path(sequence).is_relative() &&
      !fs::exists(sequence, ec)) {
    const fs::path beside = fs::path(run).parent_path() / sequence;
    if (fs::exists(beside, ec)) sequence = beside.string();
  }
  if (sequence.empty()) {
    throw Error(run +
                ": the run names no recording (no run.json / summary.json); give it: "
                "artex overlay SEQUENCE RUN -o DIR");
  }

  // How the run read its input (its resolved configuration; defaults when absent or from an
  // older version with other keys).
  FrameSourceOptions input;
  const std::string config_path = run + "/config.yaml";
  if (fs::is_regular_file(config_path, ec)) {
    try {
      input = LoadPipelineOptions(Config::Load(config_path)).input;
    } catch (const Error& e) {
      std::fprintf(stderr,
                   "overlay: warning: %s: %s; reading the recording with default input "
                   "options\n",
                   config_path.c_str(), e.what());
    }
  }
  if (!cli.intrinsics.empty()) input.tum.SetIntrinsics(cli.intrinsics);
  std::string template_path = cli.template_path;
  if (template_path.empty()) template_path = JsonField(run_json, "template");
  if (template_path.empty()) template_path = JsonField(summary, "template");
  if (template_path == "default") template_path.clear();
  // A run's own template (shape.retrack: shape_pass/subject.glb) is named relative to the run.
  if (cli.template_path.empty() && !template_path.empty() &&
      fs::path(template_path).is_relative() && fs::exists(fs::path(run) / template_path)) {
    template_path = (fs::path(run) / template_path).string();
  }
  std::string cache_note;
  const Template tmpl =
      template_path.empty() ? DefaultTemplate(TemplateCacheOptions(), &cache_note)
                            : ReadTemplateFile(template_path);
  if (!cache_note.empty()) std::fprintf(stderr, "artex: warning: %s\n", cache_note.c_str());

  std::map<int, Pose> poses;
  for (auto& [frame, pose] : ReadPoseCsv(run + "/poses.csv", tmpl.num_joints()))
    poses[frame] = pose;
  std::vector<int> frames = cli.frames;
  const bool strip = fs::path(cli.output).extension() == ".png";
  if (frames.empty()) {
    if (strip) {
      frames.push_back(poses.rbegin()->first);
    } else {
      for (const auto& kv : poses) frames.push_back(kv.first);
    }
  }
  for (int f : frames) {
    if (!poses.count(f)) {
      throw Error("--frames: frame " + std::to_string(f) + " has no pose in " + run +
                  "/poses.csv (fitted frames " + std::to_string(poses.begin()->first) + ".." +
                  std::to_string(poses.rbegin()->first) + ")");
    }
  }

  const std::unique_ptr<FrameSource> source = OpenFrameSource(sequence, input);
  // The world frame of the poses: the calibration the run used, else the recording's.
  Calibration calibration = source->calibration();
  const std::string run_calibration = run + "/calibration.yaml";
  if (fs::is_regular_file(run_calibration, ec)) calibration = ReadCalibration(run_calibration);
  OverlayOptions options = cli.overlay;
  if (cli.over == "color" || cli.over == "colour") {
    options.background = OverlayBackground::kColor;
  } else if (cli.over == "depth") {
    options.background = OverlayBackground::kDepth;
  } else {
    throw Error("--over " + cli.over + ": expected color or depth");
  }
  if (!strip) {
    fs::create_directories(cli.output, ec);
    if (ec) throw Error(cli.output + ": cannot create the output folder: " + ec.message());
  }

  const Skinning skinning(tmpl);
  std::vector<cv::Mat> panels;
  std::vector<std::string> labels;
  std::vector<int> written;
  int skipped = 0;
  for (size_t k = 0; k < frames.size(); ++k) {
    const int f = frames[k];
    if (f < 0 || f >= source->num_frames()) {
      throw Error("--frames: frame " + std::to_string(f) + " is not in " + sequence + " (0.." +
                  std::to_string(source->num_frames() - 1) + ")");
    }
    Frame frame;
    std::string warning;
    if (!source->ReadFrame(f, &frame, &warning)) {
      if (strip) throw Error(sequence + ": frame " + std::to_string(f) + ": " + warning);
      std::fprintf(stderr, "overlay: warning: %s (skipped)\n", warning.c_str());
      ++skipped;
      continue;
    }
    Eigen::MatrixX3d posed;
    skinning.Apply(poses.at(f), &posed);
    const OverlayImage overlay = RenderOverlay(frame, calibration, tmpl, posed, options);
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.png", f);
    if (!strip) {
      WritePng((fs::path(cli.output) / name).string(), overlay.image);
    }
    panels.push_back(overlay.image);
    labels.push_back("frame " + std::to_string(f));
    written.push_back(f);
    if (!cli.quiet) {
      std::fprintf(stderr, "\roverlay: frame %zu/%zu", k + 1, frames.size());
      std::fflush(stderr);
    }
  }
  if (!cli.quiet) std::fprintf(stderr, "\n");
  if (panels.empty())
    throw Error(sequence + ": no readable frame among the " + std::to_string(frames.size()) +
                " chosen");
  if (strip) {
    const int width = std::max(1, static_cast<int>(std::lround(panels[0].cols * cli.scale)));
    WritePng(cli.output, ContactSheet(panels, labels, static_cast<int>(panels.size()), width));
    std::fprintf(stderr, "overlay: wrote %s (%zu frames)\n", cli.output.c_str(), panels.size());
    return;
  }
  // Contact sheet: evenly spread frames.
  std::vector<cv::Mat> sheet;
  std::vector<std::string> sheet_labels;
  const int n = static_cast<int>(panels.size());
  const int m = cli.sheet_frames > 0 ? std::min(cli.sheet_frames, n) : n;
  for (int i = 0; i < m; ++i) {
    const int j =
        m == 1 ? 0 : static_cast<int>(std::lround(static_cast<double>(i) * (n - 1) / (m - 1)));
    sheet.push_back(panels[j]);
    sheet_labels.push_back(labels[j]);
  }
  const int columns = cli.columns > 0
                          ? cli.columns
                          : static_cast<int>(std::ceil(std::sqrt(static_cast<double>(m))));
  const std::string overview = (fs::path(cli.output) / "overview.png").string();
  WritePng(overview, ContactSheet(sheet, sheet_labels, columns, cli.tile_width));
  std::printf("overlay: %d frames written to %s (%d skipped), contact sheet %s (%d frames)\n",
              static_cast<int>(written.size()), cli.output.c_str(), skipped, overview.c_str(), m);
}

}  // namespace

void RegisterOverlayCommand(CLI::App* app) {
  auto cli = std::make_shared<OverlayCli>();
  CLI::App* cmd = app->add_subcommand(
      "overlay",
      "Draw the fitted template of a run over the frames of its recording (paper Fig. 3): "
      "shaded, semi-transparent, silhouette outlined. -o DIR writes DIR/NNNNNN.png per frame "
      "and the contact sheet DIR/overview.png; -o FILE.png writes the frames side by side. The "
      "recording (an artex sequence or TUM RGB-D folder) defaults to the one the run names; the "
      "template to the run's (summary.json), else the default generated one; the world frame to "
      "RUN/calibration.yaml, else the recording's calibration");
  cmd->add_option("folders", cli->paths, "[SEQUENCE] RUN: recording (optional) and run folder")
      ->required()
      ->expected(1, 2);
  cmd->add_option("-o,--output", cli->output, "output folder, or a .png file for one strip")
      ->required();
  cmd->add_option("--frames", cli->frames,
                  "frame indices (default: every fitted frame; with FILE.png the last one)")
      ->delimiter(',');
  cmd->add_option("-t,--template", cli->template_path,
                  "tracking template .glb (default: the run's)");
  cmd->add_option("--over", cli->over,
                  "background: color (colour image, colour camera) or depth "
                  "(colour-mapped depth, depth camera)")
      ->capture_default_str();
  cmd->add_option("--intrinsics", cli->intrinsics,
                  "TUM RGB-D intrinsics: a YAML file or fr1|fr2|fr3|kinect (default: as the run)");
  cmd->add_option("--mesh-opacity", cli->overlay.mesh_opacity, "opacity of the shaded template")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  cmd->add_flag("--wireframe", cli->overlay.wireframe, "also draw the visible triangle edges");
  cmd->add_option("--columns", cli->columns, "contact sheet columns (0: about square)")
      ->check(CLI::Range(0, 64));
  cmd->add_option("--sheet-frames", cli->sheet_frames,
                  "frames in the contact sheet, evenly spread (0: all)")
      ->capture_default_str()
      ->check(CLI::Range(0, 10000));
  cmd->add_option("--tile-width", cli->tile_width, "contact sheet tile width (pixels)")
      ->capture_default_str()
      ->check(CLI::Range(16, 4096));
  cmd->add_option("--scale", cli->scale, "with FILE.png: panel scale relative to the camera image")
      ->capture_default_str()
      ->check(CLI::Range(0.1, 4.0));
  cmd->add_flag("-q,--quiet", cli->quiet, "no progress line");
  cmd->callback([cli] { RunOverlay(*cli); });
}

}  // namespace artex
