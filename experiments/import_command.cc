// artex import SRC -o SEQ: converts any readable recording (sensors/frame_source.h: an artex
// sequence or a TUM RGB-D folder) into an artex sequence folder (sensors/sequence.h) with
// calibration.yaml, frames.csv, depth/ and color/ (and background/, groundtruth/ when the
// source has them), reporting what was inferred about the input.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "experiments/commands.h"
#include "experiments/config.h"
#include "experiments/pipeline.h"
#include "models/error.h"
#include "sensors/frame_source.h"
#include "sensors/scene_segmentation.h"
#include "sensors/sequence.h"

namespace artex {
namespace {
namespace fs = std::filesystem;

struct ImportCli {
  std::string source;
  std::string output;
  std::string config;
  std::vector<std::string> overrides;
  std::string intrinsics;
  std::string world_frame;  // "": preprocess.world_frame of the configuration (default auto)
  int first_frame = 0;
  int max_frames = 0;
  bool quiet = false;
};

void CopyFileAtomic(const std::string& from, const std::string& to) {
  std::error_code ec;
  const std::string tmp = to + ".tmp";
  fs::copy_file(from, tmp, fs::copy_options::overwrite_existing, ec);
  if (!ec) fs::rename(tmp, to, ec);
  if (ec) throw Error(to + ": cannot copy from " + from + ": " + ec.message());
}

void RunImport(const ImportCli& cli) {
  std::error_code ec;
  if (fs::exists(cli.output, ec) &&
      !(fs::is_directory(cli.output, ec) && fs::is_empty(cli.output, ec))) {
    throw Error(cli.output + ": expected a new or empty output folder, found " +
                (fs::is_directory(cli.output, ec) ? "a folder with files" : "a file") +
                " (remove it or choose another)");
  }
  if (fs::exists(cli.source, ec) && fs::exists(cli.output, ec) &&
      fs::equivalent(cli.source, cli.output, ec)) {
    throw Error(cli.output + ": the output folder is the source");
  }
  // The input and world-frame options of a configuration, as `artex track` reads them.
  Config config = cli.config.empty() ? Config() : Config::Load(cli.config);
  for (const auto& o : cli.overrides) {
    const auto eq = o.find('=');
    if (eq == std::string::npos || eq == 0)
      throw Error("--set " + o + ": expected key=value (e.g. input.time_offset=0.01)");
    config.Set(o.substr(0, eq), o.substr(eq + 1));
  }
  if (!cli.world_frame.empty()) config.Set("preprocess.world_frame", cli.world_frame);
  const PipelineOptions pipeline = LoadPipelineOptions(config);
  FrameSourceOptions options = pipeline.input;
  if (!cli.intrinsics.empty()) options.tum.SetIntrinsics(cli.intrinsics);
  const std::unique_ptr<FrameSource> source = OpenFrameSource(cli.source, options);
  const std::string description = source->Description();
  if (!description.empty()) std::fprintf(stderr, "import: input: %s\n", description.c_str());
  const int total = source->num_frames();
  if (cli.first_frame >= total) {
    throw Error("--first-frame " + std::to_string(cli.first_frame) + ": expected < " +
                std::to_string(total) + " (frames of " + cli.source + ")");
  }
  const int begin = cli.first_frame;
  const int end = cli.max_frames > 0 ? std::min(total, begin + cli.max_frames) : total;

  // The world frame: the source's calibration, or (preprocess.world_frame auto with a
  // calibration in the camera frame, as TUM's, or estimate) estimated from the first readable
  // frame: floor plane, else gravity, else the camera convention (sensors/scene_segmentation.h).
  Calibration calibration = source->calibration();
  const auto* sequence = dynamic_cast<const SequenceReader*>(source.get());
  const PreprocessOptions& pre = pipeline.preprocess;
  const bool camera_frame =
      calibration.depth.world_to_camera.isApprox(Eigen::Isometry3d::Identity(), 1e-12);
  std::string world =
      camera_frame ? "camera frame (x right, y down, z forward)" : "the source's calibration";
  if (pre.world_frame == WorldFrameMode::kEstimate ||
      (pre.world_frame == WorldFrameMode::kAuto && camera_frame)) {
    Frame first;
    std::string warning;
    int i = begin;
    while (i < end && !source->ReadFrame(i, &first, &warning)) ++i;
    if (i < end) {
      WorldFrameOptions wo;
      wo.planes = pre.segmentation.planes;
      wo.assumed_camera_height = pre.assumed_camera_height;
      const WorldFrameEstimate estimate =
          EstimateWorldFrame(first.depth, calibration.depth, calibration.depth_distortion,
                             calibration.depth_scale, source->gravity(), wo);
      const Eigen::Isometry3d depth_to_color = calibration.DepthToColor();
      calibration.depth.world_to_camera = estimate.world_to_camera;
      calibration.color.world_to_camera = depth_to_color * estimate.world_to_camera;
      world = "estimated from frame " + std::to_string(i) + ": " + estimate.Describe();
    }
  }
  if (!cli.quiet) std::fprintf(stderr, "import: world frame: %s\n", world.c_str());
  SequenceWriter writer(cli.output, calibration);
  const std::vector<cv::Mat> background = source->ReadBackgroundFrames();
  for (const cv::Mat& depth : background) writer.AddBackgroundFrame(depth);
  const bool ground_truth = sequence && sequence->has_ground_truth();
  int written = 0;
  std::vector<std::string> warnings;
  Frame frame;
  for (int i = begin; i < end; ++i) {
    std::string warning;
    if (!source->ReadFrame(i, &frame, &warning)) {
      warnings.push_back(warning);
      if (!cli.quiet) std::fprintf(stderr, "\rimport: warning: %s\n", warning.c_str());
      continue;
    }
    writer.AddFrame(frame);
    if (ground_truth) writer.AddGroundTruth(frame.index, sequence->ReadGroundTruth(i));
    ++written;
    if (!cli.quiet) {
      std::fprintf(stderr, "\rimport: frame %d/%d", i - begin + 1, end - begin);
      std::fflush(stderr);
    }
  }
  if (!cli.quiet) std::fprintf(stderr, "\n");
  if (written == 0) {
    throw Error(cli.source + ": no readable frame among " + std::to_string(end - begin) + " (" +
                std::to_string(warnings.size()) + " skipped" +
                (warnings.empty() ? std::string() : ", first: " + warnings.front()) + ")");
  }
  if (ground_truth) {
    if (!sequence->GroundTruthTexturePath().empty()) {
      CopyFileAtomic(sequence->GroundTruthTexturePath(),
                     (fs::path(cli.output) / "groundtruth" / "texture.png").string());
    }
    if (!sequence->GroundTruthSubjectPath().empty()) {
      CopyFileAtomic(sequence->GroundTruthSubjectPath(), writer.subject_path());
    }
  }
  writer.Finish();
  std::printf("import: %d frames written to %s (%zu skipped", written, cli.output.c_str(),
              warnings.size());
  if (end - begin < total) std::printf(", %d of %d source frames chosen", end - begin, total);
  std::printf("), %zu background frames%s; world frame: %s\n", background.size(),
              ground_truth ? ", ground truth" : "", world.c_str());
  if (const auto up = source->gravity()) {
    std::printf("import: up (against gravity) in the depth camera frame: (%.4f, %.4f, %.4f)\n",
                (*up)[0], (*up)[1], (*up)[2]);
  }
}

}  // namespace

void RegisterImportCommand(CLI::App* app) {
  auto cli = std::make_shared<ImportCli>();
  CLI::App* cmd = app->add_subcommand(
      "import",
      "Convert a recording into an artex sequence folder (calibration.yaml, frames.csv, depth/, "
      "color/). Detected by its files: an artex sequence (calibration.yaml + frames.csv; copied "
      "with its background and ground truth), a TUM RGB-D folder (rgb.txt + depth.txt) or a "
      "Matroska .mkv file (16-bit depth + colour tracks, e.g. Azure Kinect; calibration from "
      "<file>.yaml or calibration.yaml beside it, input.calibration). For "
      "TUM it infers: depth/colour pairs by nearest timestamp within --max-time-difference "
      "(unpaired entries counted); one camera for depth and colour (the benchmark's depth is "
      "registered to colour) with the intrinsics of camera.yaml, --intrinsics FILE or a "
      "preset (fr1, fr2, fr3, kinect); 5000 depth units per metre unless camera.yaml says "
      "depth_scale; 'up' from accelerometer.txt when present. The world frame (Y up, as "
      "`artex track` uses it): a source calibration in the camera frame (TUM) gets one "
      "estimated from the first frame (floor plane, else gravity, else an upright camera); "
      "--world-frame calibration keeps the camera frame. Everything inferred is printed. "
      "Frames with missing or unreadable files are skipped with a warning and counted.");
  cmd->add_option("source", cli->source,
                  "recording: artex sequence or TUM RGB-D folder, or a .mkv file")
      ->required();
  cmd->add_option("-o,--output", cli->output, "new artex sequence folder")->required();
  cmd->add_option("--intrinsics", cli->intrinsics,
                  "TUM intrinsics: a YAML file or a preset fr1|fr2|fr3|kinect (default: "
                  "<source>/camera.yaml)");
  cmd->add_option("-c,--config", cli->config,
                  "configuration (YAML): its input and preprocess.world_frame keys apply");
  cmd->add_option("-s,--set", cli->overrides,
                  "override an option: key=value (e.g. input.max_time_difference=0.03)");
  cmd->add_option("--world-frame", cli->world_frame,
                  "auto (estimate when the source's is the camera frame), estimate, calibration "
                  "(default: preprocess.world_frame, auto)");
  cmd->add_option("--first-frame", cli->first_frame, "first source frame to import")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--max-frames", cli->max_frames, "import at most this many frames (0: all)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_flag("-q,--quiet", cli->quiet, "no progress line");
  cmd->callback([cli] { RunImport(*cli); });
}

}  // namespace artex
