// artex render RUN/ -o OUT/: renders the tracked, textured model of a run (RUN/tracked.glb)
// from novel viewpoints (an orbit) and re-animated in new poses (a built-in motion or a pose
// file), as in the paper's Fig. 2.
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "experiments/atomic_output.h"
#include "experiments/commands.h"
#include "experiments/pipeline_stages.h"  // WritePngFile
#include "experiments/pose_csv.h"
#include "models/error.h"
#include "models/skinning.h"
#include "models/template_io.h"
#include "sensors/image_codec.h"
#include "sensors/motion.h"
#include "texture/texturer.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

// Last pose of RUN/poses.csv.
Pose LastPose(const std::string& path, int num_joints) {
  return ReadPoseCsv(path, num_joints).back().second;
}

PinholeCamera OrbitCamera(const Eigen::Vector3d& center, double radius, double angle, int width,
                          int height, double elevation) {
  PinholeCamera camera;
  camera.width = width;
  camera.height = height;
  camera.fx = camera.fy = 1.1 * height;
  camera.cx = (width - 1) / 2.0;
  camera.cy = (height - 1) / 2.0;
  const Eigen::Vector3d eye =
      center + radius * Eigen::Vector3d(std::sin(angle), elevation, std::cos(angle));
  camera.world_to_camera = PinholeCamera::LookAt(eye, center, Eigen::Vector3d::UnitY());
  return camera;
}

}  // namespace

void RegisterRenderCommand(CLI::App* app) {
  struct Args {
    std::string run, out, motion, view = "orbit";
    int frames = 8, width = 480, height = 640;
    double distance = 2.8, elevation = 0.15;
  };
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app->add_subcommand(
      "render", "Render a tracked, textured model from new viewpoints and in new poses");
  cmd->add_option("run", args->run, "output folder of `artex track` (reads tracked.glb, poses.csv)")
      ->required();
  cmd->add_option("-o,--output", args->out, "output folder for PNG images")->required();
  cmd->add_option("--view", args->view, "orbit: views around the model in its last tracked pose");
  cmd->add_option("--frames", args->frames, "number of orbit views / re-animated frames");
  cmd->add_option("--motion", args->motion,
                  "re-animate with a built-in motion (walk, arm_raise, turn, bend) instead");
  cmd->add_option("--width", args->width, "image width (pixels)");
  cmd->add_option("--height", args->height, "image height (pixels)");
  cmd->add_option("--distance", args->distance, "camera distance (m)");
  cmd->callback([args] {
    if (args->view != "orbit") throw Error("--view: unknown value '" + args->view + "'; valid: orbit");
    if (args->frames < 1) throw Error("--frames: expected >= 1, found " + std::to_string(args->frames));
    if (args->width < 16 || args->height < 16) throw Error("--width/--height: expected >= 16 pixels");
    const std::string glb = args->run + "/tracked.glb";
    GlbTexture texture;
    const Template tmpl = ReadTemplateGlb(glb, &texture);
    if (texture.png.empty()) throw Error(glb + ": no embedded texture (was the run made with --no-texture?)");
    cv::Mat atlas;
    std::string error;
    if (!DecodeImage(texture.png.data(), texture.png.size(), ImageRead::kColor, &atlas, &error)) {
      throw Error(glb + ": the embedded texture is not a readable PNG (" + error + ")");
    }
    const Skinning skinning(tmpl);
    std::vector<Pose> poses;
    if (!args->motion.empty()) {
      MotionOptions motion;
      motion.type = ParseMotionType(args->motion);
      motion.frames = args->frames;
      poses = GenerateMotion(tmpl, motion);
      // Keep the tracked subject's place and scale.
      const Pose tracked = LastPose(args->run + "/poses.csv", tmpl.num_joints());
      for (Pose& p : poses) {
        p.scale = tracked.scale;
        p.translation += tracked.translation;
      }
    } else {
      poses.assign(args->frames, LastPose(args->run + "/poses.csv", tmpl.num_joints()));
    }
    std::error_code ec;
    if (fs::equivalent(args->run, args->out, ec)) {
      throw Error(args->out + ": the output folder is the run folder it renders; choose another");
    }
    // Written into a temporary sibling, published complete at the end (docs/reliability.md).
    AtomicOutputFolder out(args->out, "render");
    Eigen::MatrixX3d posed;
    for (int i = 0; i < args->frames; ++i) {
      skinning.Apply(poses[i], &posed);
      const Eigen::Vector3d center = 0.5 * (posed.colwise().minCoeff() + posed.colwise().maxCoeff()).transpose();
      const double angle = args->motion.empty() ? 2.0 * M_PI * i / args->frames : 0.35;
      const PinholeCamera camera =
          OrbitCamera(center, args->distance, angle, args->width, args->height, args->elevation);
      cv::Mat image, mask;
      RenderTextured(tmpl, posed, atlas, camera, &image, &mask);
      image.setTo(cv::Scalar(60, 60, 60), mask == 0);
      char name[64];
      std::snprintf(name, sizeof(name), "/%s_%03d.png", args->motion.empty() ? "view" : "pose", i);
      WritePngFile(out.path() + name, image);
    }
    out.Commit();
    std::printf("%d images in %s\n", args->frames, args->out.c_str());
  });
}

}  // namespace artex
