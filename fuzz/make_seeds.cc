// Writes the seed corpora of the fuzz targets with artex's own writers (nothing binary is
// committed): make_seeds OUT [SOURCE_DIR] -> OUT/<target>/<seed files>. SOURCE_DIR (the
// repository) supplies configs/default.yaml and configs/experiments/*.yaml.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "experiments/pose_csv.h"
#include "fuzz/fuzz_input.h"
#include "models/error.h"
#include "models/template_generator.h"
#include "models/template_cache.h"
#include "models/template_io.h"
#include "sensors/calibration.h"
#include "sensors/image_codec.h"
#include "sensors/sequence.h"
#include "stream/stream_sender.h"
#include "tests/models/small_makehuman.h"

namespace fs = std::filesystem;

namespace {

std::string Read(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

void Put(const fs::path& out, const std::string& target, const std::string& name,
         const std::string& bytes) {
  fs::create_directories(out / target);
  std::ofstream(out / target / name, std::ios::binary).write(bytes.data(), bytes.size());
}

const char* kBvh = R"(HIERARCHY
ROOT Hips
{
  OFFSET 0 90 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT LeftUpLeg
  {
    OFFSET 10 -5 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT LeftLeg
    {
      OFFSET 0 -40 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 -40 0
      }
    }
  }
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 50 0
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.0333333
0 90 0 0 0 0 10 0 0 -20 0 0 5 0 0
1 90 0 0 5 0 12 0 0 -25 0 0 5 2 0
2 90 0 0 10 0 14 0 0 -30 0 0 5 4 0
)";

// A few triangles of `tmpl` per joint (the first ones whose corners all belong to the joint)
// and one with a skin weight the importer drops, with their vertices, UVs, charts and every joint: a template that takes every branch of the
// .glb reader that the whole template does, in about 1/30 of its bytes (a fuzz input costs
// time in proportion to its size).
artex::Template SmallTemplate(const artex::Template& tmpl, int triangles_per_joint) {
  std::vector<int> kept;
  // First, one triangle with a skin weight that the glTF importer drops (below its default
  // min_joint_weight, 1e-4).
  for (int t = 0; t < tmpl.num_triangles() && kept.empty(); ++t) {
    for (int c = 0; c < 3; ++c) {
      const double w = tmpl.lbs_weight(tmpl.triangles(t, c));
      if ((w > 0.0 && w < 1e-4) || (w < 1.0 && w > 1.0 - 1e-4)) {
        kept.push_back(t);
        break;
      }
    }
  }
  std::vector<int> count(tmpl.num_joints(), 0);
  for (int t = 0; t < tmpl.num_triangles(); ++t) {
    if (!kept.empty() && t == kept[0]) continue;
    const int j = tmpl.vertex_joint(tmpl.triangles(t, 0));
    if (tmpl.vertex_joint(tmpl.triangles(t, 1)) != j ||
        tmpl.vertex_joint(tmpl.triangles(t, 2)) != j || count[j] >= triangles_per_joint) {
      continue;
    }
    ++count[j];
    kept.push_back(t);
  }
  std::vector<int> vertex_map(tmpl.num_vertices(), -1), uv_map(tmpl.uvs.rows(), -1);
  std::vector<int> vertices, uvs;
  for (int t : kept) {
    for (int c = 0; c < 3; ++c) {
      int& v = vertex_map[tmpl.triangles(t, c)];
      if (v < 0) {
        v = static_cast<int>(vertices.size());
        vertices.push_back(tmpl.triangles(t, c));
      }
      if (tmpl.has_uvs()) {
        int& u = uv_map[tmpl.uv_triangles(t, c)];
        if (u < 0) {
          u = static_cast<int>(uvs.size());
          uvs.push_back(tmpl.uv_triangles(t, c));
        }
      }
    }
  }
  artex::Template small;
  small.joints = tmpl.joints;
  const int nv = static_cast<int>(vertices.size()), nf = static_cast<int>(kept.size());
  small.vertices.resize(nv, 3);
  small.vertex_joint.resize(nv);
  small.lbs_weight.resize(nv);
  small.slerp_tau.resize(nv);
  for (int i = 0; i < nv; ++i) {
    small.vertices.row(i) = tmpl.vertices.row(vertices[i]);
    small.vertex_joint(i) = tmpl.vertex_joint(vertices[i]);
    small.lbs_weight(i) = tmpl.lbs_weight(vertices[i]);
    small.slerp_tau(i) = tmpl.slerp_tau(vertices[i]);
  }
  small.triangles.resize(nf, 3);
  for (int i = 0; i < nf; ++i) {
    for (int c = 0; c < 3; ++c) small.triangles(i, c) = vertex_map[tmpl.triangles(kept[i], c)];
  }
  if (tmpl.has_uvs()) {
    small.uvs.resize(static_cast<int>(uvs.size()), 2);
    for (int i = 0; i < small.uvs.rows(); ++i) small.uvs.row(i) = tmpl.uvs.row(uvs[i]);
    small.uv_triangles.resize(nf, 3);
    for (int i = 0; i < nf; ++i) {
      for (int c = 0; c < 3; ++c) small.uv_triangles(i, c) = uv_map[tmpl.uv_triangles(kept[i], c)];
    }
  }
  if (tmpl.triangle_chart.size() == tmpl.num_triangles()) {
    small.triangle_chart.resize(nf);
    for (int i = 0; i < nf; ++i) small.triangle_chart(i) = tmpl.triangle_chart(kept[i]);
  }
  return small;
}


}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: make_seeds OUT [SOURCE_DIR]\n");
    return 2;
  }
  const fs::path out = argv[1];
  const fs::path source = argc > 2 ? fs::path(argv[2]) : fs::path(".");
  const std::string sep = artex::fuzz::kPartSeparator;
  try {
    artex::BodyShapeOptions shape;
    shape.resolution = 0;
    const artex::Template tmpl = artex::GenerateTemplate(shape);
    const fs::path scratch = out / "scratch";
    fs::create_directories(scratch);
    artex::WriteTemplateGlb((scratch / "template.glb").string(), tmpl);
    Put(out, "template_glb", "coarse.glb", Read(scratch / "template.glb"));
    // The same template cut to 4 triangles per joint, with and without an embedded 2 x 2
    // base-colour texture (the fuzzer's mutations of the 350 KB whole template run ~25 a second).
    const artex::Template small = SmallTemplate(tmpl, 4);
    std::string why;
    if (!small.IsValid(&why)) throw artex::Error("make_seeds: small template: " + why);
    Put(out, "template_glb", "small.glb", artex::EncodeTemplateGlb(small));
    artex::GlbTexture texture;
    texture.width = texture.height = 2;
    texture.rgb = {255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255};
    Put(out, "template_glb", "small_textured.glb", artex::EncodeTemplateGlb(small, &texture));
    // The binary template file (the default template's cache): the small template's.
    artex::WriteTemplateBinary(small, (scratch / "small.bin").string());
    Put(out, "template_bin", "small.bin", Read(scratch / "small.bin"));

    // A 2-frame sequence of the fuzzers' 8 x 6 rig, with ground truth.
    artex::Calibration c;
    c.depth.width = c.color.width = 8;
    c.depth.height = c.color.height = 6;
    c.depth.cx = c.color.cx = 3.5;
    c.depth.cy = c.color.cy = 2.5;
    artex::WriteCalibration(c, (scratch / "calibration.yaml").string());
    Put(out, "calibration", "calibration.yaml", Read(scratch / "calibration.yaml"));
    const fs::path seq = scratch / "sequence";
    {
      artex::SequenceWriter writer(seq.string(), c);
      for (int i = 0; i < 2; ++i) {
        artex::Frame f;
        f.index = i;
        f.depth_timestamp = f.color_timestamp = 1.0 + i / 30.0;
        f.depth = cv::Mat(6, 8, CV_16UC1, cv::Scalar(1500 + 10 * i));
        f.color = cv::Mat(6, 8, CV_8UC3, cv::Scalar(20, 40, 60 + i));
        writer.AddFrame(f);
        artex::GroundTruthFrame t;
        t.pose = artex::Pose::Identity(tmpl.num_joints());
        t.vertices = tmpl.vertices.topRows(4);
        writer.AddGroundTruth(i, t);
      }
      writer.Finish();
    }
    Put(out, "sequence", "sequence",
        Read(seq / "frames.csv") + sep + Read(seq / "groundtruth/poses.csv") + sep +
            Read(seq / "groundtruth/vertices/000000.bin"));
    for (const auto& e : fs::directory_iterator(seq / "depth")) {
      Put(out, "image", "depth_" + e.path().filename().string(), Read(e.path()));
    }
    for (const auto& e : fs::directory_iterator(seq / "color")) {
      Put(out, "image", "color_" + e.path().filename().string(), Read(e.path()));
    }
    {  // layouts the fast frame decoder declines: libpng's and libjpeg's paths
      std::vector<unsigned char> bytes;
      std::string error;
      artex::EncodeJpeg(cv::Mat(6, 8, CV_8UC3, cv::Scalar(20, 90, 160)), 90, &bytes, &error);
      Put(out, "image", "color.jpg", std::string(bytes.begin(), bytes.end()));
      artex::EncodePng(cv::Mat(6, 8, CV_16UC4, cv::Scalar(100, 2000, 30000, 65535)), &bytes,
                       &error);
      Put(out, "image", "bgra16.png", std::string(bytes.begin(), bytes.end()));
      artex::EncodePng(cv::Mat(6, 8, CV_8UC1, cv::Scalar(77)), &bytes, &error);
      Put(out, "image", "grey.png", std::string(bytes.begin(), bytes.end()));
    }
    Put(out, "tum", "tum",
        "# color images\n1305031102.175304 rgb/1305031102.175304.png\n"
        "1305031102.211214 rgb/1305031102.211214.png\n" +
            sep +
            "# depth maps\n1305031102.160407 depth/1305031102.160407.png\n"
            "1305031102.226738 depth/1305031102.226738.png\n" +
            sep +
            "width: 640\nheight: 480\nfx: 517.3\nfy: 516.5\ncx: 318.6\ncy: 255.3\n"
            "k1: 0.2624\nk2: -0.9531\np1: -0.0054\np2: 0.0026\nk3: 1.1633\ndepth_scale: 5000\n");
    Put(out, "bvh", "small.bvh", kBvh);
    std::vector<artex::Pose> poses(2, artex::Pose::Identity(tmpl.num_joints()));
    artex::WritePoseCsv((scratch / "poses.csv").string(), tmpl, {0, 1}, poses);
    Put(out, "poses_csv", "poses.csv", Read(scratch / "poses.csv"));
    Put(out, "config", "default", "texture.lambda=0.5\n" + Read(source / "configs/default.yaml"));
    for (const auto& e : fs::directory_iterator(source / "configs/experiments")) {
      Put(out, "experiment", e.path().filename().string(), Read(e.path()));
    }
    // Streams of the small template, 3 frames, a keyframe every 2: poses only, and with a
    // 32 x 32 atlas video (VP9, the default codec) and its coverage; the textured one carries a
    // rest shape on frame 1 (the template 2 % larger).
    for (const bool textured : {false, true}) {
      artex::StreamOptions options;
      options.keyframe_interval = 2;
      options.video.bitrate_kbps = 100;
      const fs::path stream = scratch / "stream.artx";
      {
        artex::StreamSender sender(stream.string(), small, artex::PinholeCamera(), 30.0, 32,
                                   textured, options);
        std::vector<int> triangle_frames(small.num_triangles(), 0);
        triangle_frames[0] = -1;
        for (int i = 0; i < 3; ++i) {
          if (textured && i == 1) {
            artex::Template shaped = small;
            shaped.vertices *= 1.02;
            for (artex::Joint& j : shaped.joints) j.center *= 1.02;
            sender.SetRestShape(shaped);
          }
          artex::Pose pose = artex::Pose::Identity(small.num_joints());
          pose.translation.x() = 0.01 * i;
          const cv::Mat atlas(32, 32, CV_8UC3, cv::Scalar(40 * i, 90, 160));
          sender.AddFrame(i, pose, atlas, &triangle_frames);
        }
        sender.Finish();
      }
      Put(out, "stream", textured ? "textured.artx" : "poses.artx", Read(stream));
    }
    const artex::test_data::SmallMakeHuman mh = artex::test_data::MakeSmallMakeHuman();
    Put(out, "makehuman", "box", mh.obj + sep + mh.rig + sep + mh.weights);
    fs::remove_all(scratch);
  } catch (const artex::Error& e) {
    std::fprintf(stderr, "make_seeds: %s\n", e.what());
    return 1;
  }
  return 0;
}
