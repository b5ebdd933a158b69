// `artex template`: make, inspect, pose, animate and import templates (models/template_io.h).
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "experiments/commands.h"
#include "experiments/pose_csv.h"
#include "models/error.h"
#include "models/makehuman_import.h"
#include "models/mesh_export.h"
#include "models/normals.h"
#include "models/pose.h"
#include "models/skinning.h"
#include "models/so3.h"
#include "models/template_generator.h"
#include "models/template_io.h"

namespace artex {
namespace {

constexpr double kDegrees = 3.14159265358979323846 / 180.0;

struct MakeCli {
  BodyShapeOptions shape;
  std::string output;
};

struct InfoCli {
  std::string input;
  int uv_grid = TemplateSummaryOptions().uv_grid;
};

struct PoseCli {
  std::string input;
  std::string pose;
  std::string pose_file;
  int frame = 0;
  std::vector<std::string> joints;
  bool color_joints = false;
  std::string output;
};

struct AnimateCli {
  std::string input;
  std::string pose_file;
  double frame_rate = 30.0;
  std::string output;
};

struct ImportMakeHumanCli {
  std::string folder;
  std::string joint_positions = "cubes";
  std::string output;
};

struct ImportGltfCli {
  std::string input;
  bool no_weld = false;
  std::string output;
};

void RequireOutput(const std::string& output, const std::vector<std::string>& extensions) {
  if (output.empty()) throw Error("-o/--output: an output file is required");
  const std::string ext = LowerCaseExtension(output);
  if (std::find(extensions.begin(), extensions.end(), ext) == extensions.end()) {
    std::string valid;
    for (const std::string& e : extensions) valid += (valid.empty() ? "" : ", ") + e;
    throw Error(output + ": unsupported output format '" + ext + "' (expected " + valid + ")");
  }
}

// Rotation axis of joint frames after posing: R0 R_root ... R_j.
std::vector<Eigen::Matrix3d> ChainRotations(const Template& tmpl, const Pose& pose) {
  std::vector<Eigen::Matrix3d> r(tmpl.num_joints());
  for (int j = 0; j < tmpl.num_joints(); ++j) {
    const int p = tmpl.joints[j].parent;
    r[j] = (p >= 0 ? r[p] : pose.rotation) * pose.joint_rotations[j];
  }
  return r;
}

const char* kJointColors[] = {"#e6194b", "#3cb44b", "#ffe119", "#4363d8", "#f58231", "#911eb4",
                              "#46f0f0", "#f032e6", "#bcf60c", "#fabebe", "#008080", "#e6beff",
                              "#9a6324", "#fffac8", "#800000", "#aaffc3", "#808000", "#ffd8b1"};

Eigen::Vector3d HexColor(const char* hex) {
  const unsigned value = static_cast<unsigned>(std::strtoul(hex + 1, nullptr, 16));
  return Eigen::Vector3d((value >> 16) & 255, (value >> 8) & 255, value & 255) / 255.0;
}

// ------------------------------------------------------------------------------------------

void RunMake(const MakeCli& cli) {
  RequireOutput(cli.output, {".glb"});
  std::string error;
  if (!cli.shape.IsValid(&error)) throw Error("template make: " + error);
  const Template tmpl = GenerateTemplate(cli.shape);
  WriteTemplateGlb(cli.output, tmpl);
  std::printf("wrote %s: %d vertices, %d triangles, %d joints\n", cli.output.c_str(),
              tmpl.num_vertices(), tmpl.num_triangles(), tmpl.num_joints());
}

void RunInfo(const InfoCli& cli) {
  GlbTexture texture;
  const Template tmpl = ReadTemplateGlb(cli.input, &texture);
  TemplateSummaryOptions options;
  options.uv_grid = cli.uv_grid;
  const TemplateSummary s = SummarizeTemplate(tmpl, options);
  std::printf("file: %s\n", cli.input.c_str());
  std::printf("vertices: %d\n", s.num_vertices);
  std::printf("triangles: %d\n", s.num_triangles);
  std::printf("bounding box (m): min (%.3f, %.3f, %.3f) max (%.3f, %.3f, %.3f), height %.3f\n",
              s.bbox_min.x(), s.bbox_min.y(), s.bbox_min.z(), s.bbox_max.x(), s.bbox_max.y(),
              s.bbox_max.z(), s.bbox_max.y() - s.bbox_min.y());
  std::printf("joints: %d\n", s.num_joints);
  for (int j = 0; j < s.num_joints; ++j) {
    const Joint& joint = tmpl.joints[j];
    const std::string parent =
        joint.parent >= 0 ? tmpl.joints[joint.parent].name : std::string("(root)");
    std::printf("  %2d %-12s parent %-12s centre (%7.3f, %7.3f, %7.3f) twist axis (%6.3f, %6.3f, "
                "%6.3f) vertices %d\n",
                j, joint.name.c_str(), parent.c_str(), joint.center.x(), joint.center.y(),
                joint.center.z(), joint.twist_axis.x(), joint.twist_axis.y(), joint.twist_axis.z(),
                s.vertices_per_joint[j]);
  }
  std::printf("pose parameters: %d (7 global + 3 x %d joints)\n", s.num_pose_parameters,
              s.num_joints);
  if (tmpl.has_uvs()) {
    std::printf("uv atlas: %d uv coordinates, %d charts, coverage %.3f of the unit square, "
                "overlap %.4f\n",
                s.num_uvs, s.num_charts, s.uv_coverage, s.uv_overlap);
  } else {
    std::printf("uv atlas: none\n");
  }
  if (s.closed_manifold()) {
    std::printf("manifold: closed, consistently oriented 2-manifold; %d component(s), Euler "
                "characteristic %d\n",
                s.components, s.euler_characteristic);
  } else {
    std::printf("manifold: no (%d boundary edges, %d non-manifold edges, %d misoriented edges); "
                "%d component(s), Euler characteristic %d\n",
                s.boundary_edges, s.non_manifold_edges, s.misoriented_edges, s.components,
                s.euler_characteristic);
  }
  if (s.unreferenced_vertices > 0) {
    std::printf("unreferenced vertices: %d\n", s.unreferenced_vertices);
  }
  if (!texture.png.empty() && texture.png.size() >= 24) {
    auto be32 = [&texture](size_t o) {
      return (static_cast<unsigned>(texture.png[o]) << 24) |
             (static_cast<unsigned>(texture.png[o + 1]) << 16) |
             (static_cast<unsigned>(texture.png[o + 2]) << 8) | texture.png[o + 3];
    };
    std::printf("texture: %u x %u PNG (%zu bytes)\n", be32(16), be32(20), texture.png.size());
  } else {
    std::printf("texture: none\n");
  }
}

void RunPose(const PoseCli& cli) {
  RequireOutput(cli.output, {".ply", ".obj", ".glb"});
  const Template tmpl = ReadTemplateGlb(cli.input);
  const int num_joints = tmpl.num_joints();
  if (!cli.pose.empty() && !cli.pose_file.empty()) {
    throw Error("template pose: give --pose or --pose-file, not both");
  }
  Pose pose = Pose::Identity(num_joints);
  if (!cli.pose.empty()) {
    pose = Pose::FromVector(ParseNumberList(cli.pose, "--pose"), num_joints, "--pose");
  } else if (!cli.pose_file.empty()) {
    const auto rows = ReadPoseCsv(cli.pose_file, num_joints);
    auto it = std::find_if(rows.begin(), rows.end(),
                           [&cli](const auto& row) { return row.first == cli.frame; });
    if (it == rows.end()) {
      throw Error(cli.pose_file + ": no row for frame " + std::to_string(cli.frame));
    }
    pose = it->second;
  }
  for (const std::string& spec : cli.joints) {
    const size_t eq = spec.find('=');
    const std::string name = spec.substr(0, eq);
    const int j = tmpl.FindJoint(name);
    if (eq == std::string::npos || j < 0) {
      std::string names;
      for (const Joint& joint : tmpl.joints) names += (names.empty() ? "" : ", ") + joint.name;
      throw Error("--joint " + spec + ": expected NAME=rx,ry,rz with NAME one of " + names);
    }
    const Eigen::VectorXd r = ParseNumberList(spec.substr(eq + 1), "--joint " + spec);
    if (r.size() != 3 || !r.allFinite()) {
      throw Error("--joint " + spec + ": expected three finite angles rx,ry,rz (degrees)");
    }
    pose.joint_rotations[j] = ExpSO3(Eigen::Vector3d(r * kDegrees));
  }
  const Skinning skinning(tmpl);
  Eigen::MatrixX3d posed;
  skinning.Apply(pose, &posed);
  const std::string ext = LowerCaseExtension(cli.output);
  if (ext == ".glb") {
    Template out = tmpl;
    out.vertices = posed;
    Eigen::MatrixX3d centers;
    skinning.PosedJointCenters(pose, &centers);
    const std::vector<Eigen::Matrix3d> rotations = ChainRotations(tmpl, pose);
    for (int j = 0; j < num_joints; ++j) {
      out.joints[j].center = centers.row(j).transpose();
      out.joints[j].twist_axis = (rotations[j] * tmpl.joints[j].twist_axis).normalized();
    }
    WriteTemplateGlb(cli.output, out);
  } else {
    Eigen::MatrixX3d normals, colors;
    ComputeVertexNormals(posed, tmpl.triangles, &normals);
    if (cli.color_joints) {
      colors.resize(posed.rows(), 3);
      const int palette = static_cast<int>(sizeof(kJointColors) / sizeof(kJointColors[0]));
      for (int v = 0; v < posed.rows(); ++v) {
        colors.row(v) = HexColor(kJointColors[tmpl.vertex_joint[v] % palette]).transpose();
      }
    }
    WritePosedMesh(cli.output, posed, tmpl.triangles, colors, normals);
  }
  std::printf("wrote %s: %d vertices, %d triangles\n", cli.output.c_str(), tmpl.num_vertices(),
              tmpl.num_triangles());
}

void RunAnimate(const AnimateCli& cli) {
  RequireOutput(cli.output, {".glb"});
  GlbTexture texture;
  const Template tmpl = ReadTemplateGlb(cli.input, &texture);
  const auto rows = ReadPoseCsv(cli.pose_file, tmpl.num_joints());
  std::vector<Pose> poses;
  for (const auto& row : rows) poses.push_back(row.second);
  WriteAnimatedGlb(cli.output, tmpl, poses, cli.frame_rate, texture.empty() ? nullptr : &texture);
  std::printf("wrote %s: %zu frames at %.3g Hz\n", cli.output.c_str(), poses.size(),
              cli.frame_rate);
}

void RunImportMakeHuman(const ImportMakeHumanCli& cli) {
  RequireOutput(cli.output, {".glb"});
  MakeHumanImportOptions options;
  if (cli.joint_positions == "cubes") {
    options.joint_positions = RigPositionSource::kJointCubes;
  } else if (cli.joint_positions == "default") {
    options.joint_positions = RigPositionSource::kDefaultPositions;
  } else {
    throw Error("--joint-positions: expected cubes or default, found '" + cli.joint_positions + "'");
  }
  MakeHumanImportReport report;
  const Template tmpl = ImportMakeHuman(cli.folder, options, nullptr, &report);
  WriteTemplateGlb(cli.output, tmpl);
  std::printf("wrote %s: %d vertices, %d triangles (from %d quads), %d joints, height %.3f m\n",
              cli.output.c_str(), tmpl.num_vertices(), tmpl.num_triangles(), report.group_quads,
              tmpl.num_joints(), report.height_m);
  std::printf("surface: %d boundary edges, %d non-manifold edges; largest skin weight dropped by "
              "the conversion: %.3f\n",
              report.boundary_edges, report.non_manifold_edges, report.max_joint_weight_loss);
}

void RunImportGltf(const ImportGltfCli& cli) {
  RequireOutput(cli.output, {".glb"});
  GltfImportOptions options;
  options.weld_identical_positions = !cli.no_weld;
  const Template tmpl = ImportGltfSkinnedMesh(cli.input, options);
  WriteTemplateGlb(cli.output, tmpl);
  std::printf("wrote %s: %d vertices, %d triangles, %d joints\n", cli.output.c_str(),
              tmpl.num_vertices(), tmpl.num_triangles(), tmpl.num_joints());
}

}  // namespace

void RegisterTemplateCommands(CLI::App* app) {
  CLI::App* group = app->add_subcommand("template", "Make, inspect, pose and import templates");
  group->require_subcommand(1);

  auto make = std::make_shared<MakeCli>();
  CLI::App* sub = group->add_subcommand("make", "Generate the default human template (.glb)");
  sub->add_option("--height", make->shape.height, "Stature (m)")
      ->capture_default_str()
      ->check(CLI::Range(1.0, 2.3));
  sub->add_option("--girth", make->shape.girth, "Circumference factor")
      ->capture_default_str()
      ->check(CLI::Range(0.6, 1.6));
  sub->add_option("--shoulder-width", make->shape.shoulder_width, "Shoulder width factor")
      ->capture_default_str()
      ->check(CLI::Range(0.7, 1.3));
  sub->add_option("--hip-width", make->shape.hip_width, "Hip width factor")
      ->capture_default_str()
      ->check(CLI::Range(0.7, 1.3));
  sub->add_option("--arm-length", make->shape.arm_length, "Arm length factor")
      ->capture_default_str()
      ->check(CLI::Range(0.8, 1.2));
  sub->add_option("--leg-length", make->shape.leg_length, "Leg length factor")
      ->capture_default_str()
      ->check(CLI::Range(0.8, 1.2));
  sub->add_option("--arm-angle", make->shape.arm_angle_deg, "A-pose arm angle below horizontal (deg)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 80.0));
  sub->add_option("--resolution", make->shape.resolution, "0: coarse (~3k vertices), 1: default")
      ->capture_default_str()
      ->check(CLI::Range(0, 1));
  sub->add_option("-o,--output", make->output, "Output template (.glb)")->required();
  sub->callback([make]() { RunMake(*make); });

  auto info = std::make_shared<InfoCli>();
  sub = group->add_subcommand("info", "Print a template's mesh, joints, UV atlas and topology");
  sub->add_option("file", info->input, "Template (.glb)")->required();
  sub->add_option("--uv-grid", info->uv_grid, "Raster size for the UV coverage")
      ->capture_default_str()
      ->check(CLI::Range(16, 8192));
  sub->callback([info]() { RunInfo(*info); });

  auto pose = std::make_shared<PoseCli>();
  sub = group->add_subcommand("pose", "Pose a template and write the mesh (.ply, .obj or .glb)");
  sub->add_option("file", pose->input, "Template (.glb)")->required();
  sub->add_option("--pose", pose->pose,
                  "Pose vector \"s tx ty tz r0x r0y r0z r1x ...\" (rotation vectors, radians)");
  sub->add_option("--pose-file", pose->pose_file,
                  "CSV of pose vectors (optionally with a 'frame' column, as groundtruth/poses.csv)");
  sub->add_option("--frame", pose->frame, "Frame of --pose-file (frame column, else row index)")
      ->capture_default_str();
  sub->add_option("--joint", pose->joints,
                  "NAME=rx,ry,rz: joint rotation vector in degrees (repeatable; overrides)");
  sub->add_flag("--color-joints", pose->color_joints, "PLY: colour vertices by their joint");
  sub->add_option("-o,--output", pose->output, "Output mesh (.ply, .obj, .glb)")->required();
  sub->callback([pose]() { RunPose(*pose); });

  auto animate = std::make_shared<AnimateCli>();
  sub = group->add_subcommand("animate", "Write an animated .glb from a CSV of poses");
  sub->add_option("file", animate->input, "Template (.glb)")->required();
  sub->add_option("--pose-file", animate->pose_file, "CSV of pose vectors, one row per frame")
      ->required();
  sub->add_option("--fps", animate->frame_rate, "Frame rate (Hz)")
      ->capture_default_str()
      ->check(CLI::Range(0.1, 1000.0));
  sub->add_option("-o,--output", animate->output, "Output animation (.glb)")->required();
  sub->callback([animate]() { RunAnimate(*animate); });

  auto mh = std::make_shared<ImportMakeHumanCli>();
  sub = group->add_subcommand("import-makehuman",
                              "Import the MakeHuman base mesh with the mpfb2 cmu_mb rig");
  sub->add_option("folder", mh->folder, "Folder with base.obj and the mpfb rig/weights JSON")
      ->required();
  sub->add_option("--joint-positions", mh->joint_positions,
                  "Joint centres from the OBJ's joint cubes (cubes) or the rig's default "
                  "positions (default)")
      ->capture_default_str();
  sub->add_option("-o,--output", mh->output, "Output template (.glb)")->required();
  sub->callback([mh]() { RunImportMakeHuman(*mh); });

  auto gltf = std::make_shared<ImportGltfCli>();
  sub = group->add_subcommand("import-gltf", "Import any glTF 2.0 skinned mesh as a template");
  sub->add_option("file", gltf->input, "Skinned mesh (.glb or .gltf)")->required();
  sub->add_flag("--no-weld", gltf->no_weld, "Keep UV-seam copies as separate vertices");
  sub->add_option("-o,--output", gltf->output, "Output template (.glb)")->required();
  sub->callback([gltf]() { RunImportGltf(*gltf); });
}

}  // namespace artex
