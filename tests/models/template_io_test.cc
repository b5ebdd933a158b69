#include "models/template_io.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "models/error.h"
#include "models/makehuman_import.h"
#include "models/mesh_export.h"
#include "models/skinning.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// ---------------------------------------------------------------------------------------------
// A hand-built template: a tube along +Y over three chained joints (plus a side joint without
// vertices), with a UV seam, two charts and one unreferenced vertex.
Template MakeTube(int rings = 8, int segments = 8) {
  Template t;
  const int num_surface = (rings + 1) * segments;
  t.vertices.resize(num_surface + 1, 3);
  for (int r = 0; r <= rings; ++r) {
    const double y = 2.0 * r / rings;
    const double radius = 0.1 + 0.02 * std::sin(3.0 * y);
    for (int s = 0; s < segments; ++s) {
      const double a = 2.0 * M_PI * s / segments;
      t.vertices.row(r * segments + s) << radius * std::cos(a), y, -radius * std::sin(a);
    }
  }
  t.vertices.row(num_surface) << 0.0, 2.5, 0.0;  // not used by any triangle
  t.uvs.resize((rings + 1) * (segments + 1), 2);
  for (int r = 0; r <= rings; ++r) {
    for (int s = 0; s <= segments; ++s) {
      t.uvs.row(r * (segments + 1) + s) << 0.05 + 0.9 * s / segments, 0.95 - 0.9 * r / rings;
    }
  }
  const int f = 2 * rings * segments;
  t.triangles.resize(f, 3);
  t.uv_triangles.resize(f, 3);
  t.triangle_chart.resize(f);
  int n = 0;
  for (int r = 0; r < rings; ++r) {
    for (int s = 0; s < segments; ++s) {
      const int s1 = (s + 1) % segments;
      const int a = r * segments + s, b = r * segments + s1, c = (r + 1) * segments + s1,
                d = (r + 1) * segments + s;
      const int ua = r * (segments + 1) + s, ub = ua + 1, uc = ub + segments + 1,
                ud = ua + segments + 1;
      t.triangles.row(n) << a, b, c;
      t.uv_triangles.row(n) << ua, ub, uc;
      t.triangle_chart[n++] = s < segments / 2 ? 0 : 1;
      t.triangles.row(n) << a, c, d;
      t.uv_triangles.row(n) << ua, uc, ud;
      t.triangle_chart[n++] = s < segments / 2 ? 0 : 1;
    }
  }
  auto add_joint = [&t](const std::string& name, int parent, const Eigen::Vector3d& center,
                        const Eigen::Vector3d& axis) {
    Joint joint;
    joint.name = name;
    joint.parent = parent;
    joint.center = center;
    joint.twist_axis = axis.normalized();
    t.joints.push_back(joint);
  };
  add_joint("root", -1, {0.0, 0.1, 0.0}, {0.0, 1.0, 0.0});
  add_joint("mid", 0, {0.01, 0.8, 0.0}, {0.0, 1.0, 0.05});
  add_joint("tip", 1, {0.0, 1.5, 0.02}, {0.02, 1.0, 0.0});
  add_joint("side", 0, {0.3, 0.5, 0.0}, {1.0, 0.0, 0.0});
  const int v_count = t.num_vertices();
  t.vertex_joint.resize(v_count);
  t.lbs_weight.resize(v_count);
  t.slerp_tau.resize(v_count);
  for (int v = 0; v < v_count; ++v) {
    const double y = t.vertices(v, 1);
    const int k = y < 0.6 ? 0 : (y < 1.3 ? 1 : 2);
    t.vertex_joint[v] = k;
    const double base = k == 0 ? 0.1 : (k == 1 ? 0.8 : 1.5);
    t.lbs_weight[v] = std::clamp((y - base + 0.2) / 0.5, 0.0, 1.0);  // includes 0 and 1
    t.slerp_tau[v] = std::clamp(0.2 + 0.3 * y, 0.0, 1.0);
  }
  std::string error;
  EXPECT_TRUE(t.IsValid(&error)) << error;
  return t;
}

// ---------------------------------------------------------------------------------------------
// GLB container helpers for building corrupted files.
struct Glb {
  json gltf;
  std::string bin;
};

uint32_t U32(const std::string& s, size_t offset) {
  uint32_t v;
  std::memcpy(&v, s.data() + offset, 4);
  return v;
}

Glb ParseGlb(const std::string& bytes) {
  Glb glb;
  const uint32_t json_length = U32(bytes, 12);
  glb.gltf = json::parse(bytes.substr(20, json_length));
  const size_t bin_header = 20 + json_length;
  if (bin_header + 8 <= bytes.size()) glb.bin = bytes.substr(bin_header + 8, U32(bytes, bin_header));
  return glb;
}

void AppendU32(std::string* s, uint32_t v) { s->append(reinterpret_cast<const char*>(&v), 4); }

std::string BuildGlb(const Glb& glb) {
  std::string text = glb.gltf.dump();
  while (text.size() % 4) text.push_back(' ');
  std::string bin = glb.bin;
  while (bin.size() % 4) bin.push_back('\0');
  std::string out = "glTF";
  AppendU32(&out, 2);
  AppendU32(&out, static_cast<uint32_t>(12 + 8 + text.size() + (bin.empty() ? 0 : 8 + bin.size())));
  AppendU32(&out, static_cast<uint32_t>(text.size()));
  AppendU32(&out, 0x4E4F534A);
  out += text;
  if (!bin.empty()) {
    AppendU32(&out, static_cast<uint32_t>(bin.size()));
    AppendU32(&out, 0x004E4942);
    out += bin;
  }
  return out;
}

int AttributeAccessor(const Glb& glb, const std::string& name) {
  return glb.gltf["meshes"][0]["primitives"][0]["attributes"][name].get<int>();
}

// Byte offset of element `i`, component `c` of a tightly packed accessor in the BIN chunk.
size_t ElementOffset(const Glb& glb, int accessor, size_t i, int c, size_t component_size,
                     int components) {
  const json& a = glb.gltf["accessors"][accessor];
  const json& view = glb.gltf["bufferViews"][a["bufferView"].get<int>()];
  return view.value("byteOffset", size_t{0}) + a.value("byteOffset", size_t{0}) +
         (i * components + c) * component_size;
}

float ReadFloat(const Glb& glb, int accessor, size_t i, int c, int components) {
  float v;
  std::memcpy(&v, glb.bin.data() + ElementOffset(glb, accessor, i, c, 4, components), 4);
  return v;
}

void WriteFloat(Glb* glb, int accessor, size_t i, int c, int components, float v) {
  std::memcpy(&glb->bin[ElementOffset(*glb, accessor, i, c, 4, components)], &v, 4);
}

uint16_t ReadU16(const Glb& glb, int accessor, size_t i, int c, int components) {
  uint16_t v;
  std::memcpy(&v, glb.bin.data() + ElementOffset(glb, accessor, i, c, 2, components), 2);
  return v;
}

void WriteU16(Glb* glb, int accessor, size_t i, int c, int components, uint16_t v) {
  std::memcpy(&glb->bin[ElementOffset(*glb, accessor, i, c, 2, components)], &v, 2);
}

// Removes every _ARTEX_* attribute: a plain glTF skinned mesh.
Glb StripArtexAttributes(Glb glb) {
  json& attributes = glb.gltf["meshes"][0]["primitives"][0]["attributes"];
  std::vector<std::string> names;
  for (auto it = attributes.begin(); it != attributes.end(); ++it) {
    if (it.key().rfind("_ARTEX", 0) == 0) names.push_back(it.key());
  }
  for (const std::string& name : names) attributes.erase(name);
  return glb;
}

class TemplateIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("artex_template_io_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  static std::string ReadBytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
  }
  static void WriteBytes(const std::string& path, const std::string& bytes) {
    std::ofstream out(path, std::ios::binary);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  }

  // Expects ReadTemplateGlb(path) to throw artex::Error whose message names the file and
  // contains `fragment`.
  static void ExpectReadError(const std::string& path, const std::string& fragment) {
    try {
      ReadTemplateGlb(path);
      ADD_FAILURE() << "no error for " << path << " (expected '" << fragment << "')";
    } catch (const Error& e) {
      const std::string message = e.what();
      EXPECT_NE(message.find(path), std::string::npos) << message;
      EXPECT_NE(message.find(fragment), std::string::npos) << message;
    }
  }

  fs::path dir_;
};

void ExpectSameTemplate(const Template& a, const Template& b) {
  ASSERT_EQ(a.num_vertices(), b.num_vertices());
  ASSERT_EQ(a.num_triangles(), b.num_triangles());
  ASSERT_EQ(a.num_joints(), b.num_joints());
  // Positions and per-vertex constants are stored as float: exact up to float rounding.
  EXPECT_LE((a.vertices - b.vertices).cwiseAbs().maxCoeff(), 1e-6 * a.vertices.cwiseAbs().maxCoeff());
  EXPECT_TRUE((a.triangles.array() == b.triangles.array()).all());
  EXPECT_EQ(a.uvs.rows(), b.uvs.rows());
  if (a.uvs.rows() == b.uvs.rows() && a.uvs.rows() > 0) {
    EXPECT_LE((a.uvs - b.uvs).cwiseAbs().maxCoeff(), 1e-7);
  }
  ASSERT_EQ(a.uv_triangles.rows(), b.uv_triangles.rows());
  EXPECT_TRUE((a.uv_triangles.array() == b.uv_triangles.array()).all());
  ASSERT_EQ(a.triangle_chart.size(), b.triangle_chart.size());
  EXPECT_TRUE((a.triangle_chart.array() == b.triangle_chart.array()).all());
  for (int j = 0; j < a.num_joints(); ++j) {
    EXPECT_EQ(a.joints[j].name, b.joints[j].name);
    EXPECT_EQ(a.joints[j].parent, b.joints[j].parent);
    EXPECT_EQ(a.joints[j].center, b.joints[j].center);          // JSON doubles: exact
    EXPECT_EQ(a.joints[j].twist_axis, b.joints[j].twist_axis);  // JSON doubles: exact
  }
  EXPECT_TRUE((a.vertex_joint.array() == b.vertex_joint.array()).all());
  EXPECT_LE((a.lbs_weight - b.lbs_weight).cwiseAbs().maxCoeff(), 1e-7);
  EXPECT_LE((a.slerp_tau - b.slerp_tau).cwiseAbs().maxCoeff(), 1e-7);
}

TEST_F(TemplateIoTest, RoundTripIsExactUpToFloatPrecision) {
  const Template tmpl = MakeTube();
  const std::string path = Path("tube.glb");
  WriteTemplateGlb(path, tmpl);
  ASSERT_TRUE(fs::exists(path));
  const Template back = ReadTemplateGlb(path);
  ExpectSameTemplate(tmpl, back);
  // Once at float precision, further round trips reproduce the file byte for byte.
  const std::string again = Path("again.glb"), again2 = Path("again2.glb");
  WriteTemplateGlb(again, back);
  WriteTemplateGlb(again2, ReadTemplateGlb(again));
  EXPECT_EQ(ReadBytes(again), ReadBytes(again2));
  // No temporary files are left behind.
  int files = 0;
  for (const auto& entry : fs::directory_iterator(dir_)) files += entry.is_regular_file();
  EXPECT_EQ(files, 3);
}

TEST_F(TemplateIoTest, UvSeamVerticesAreSplitInTheFileAndMergedOnRead) {
  const Template tmpl = MakeTube(4, 6);
  const Glb glb = ParseGlb(EncodeTemplateGlb(tmpl));
  const int position = AttributeAccessor(glb, "POSITION");
  const int count = glb.gltf["accessors"][position]["count"].get<int>();
  // One extra copy per ring at the seam (segments + 1 UV columns), plus the loose vertex.
  EXPECT_EQ(count, (4 + 1) * (6 + 1) + 1);
  const int ids = AttributeAccessor(glb, "_ARTEX_VERTEX");
  std::vector<int> copies(tmpl.num_vertices(), 0);
  for (int i = 0; i < count; ++i) ++copies[static_cast<int>(ReadFloat(glb, ids, i, 0, 1))];
  for (int v = 0; v < tmpl.num_vertices(); ++v) EXPECT_GE(copies[v], 1);
  EXPECT_EQ(copies[0], 2);  // seam vertex
  EXPECT_EQ(copies[1], 1);
  // Skin: global node + 4 joints, weights sum to one, joint nodes carry the twist axes.
  EXPECT_EQ(glb.gltf["skins"][0]["joints"].size(), 5u);
  const json& tip = glb.gltf["nodes"][2 + 2];
  EXPECT_EQ(tip["name"], "tip");
  EXPECT_NEAR(tip["extras"]["artex_twist_axis"][0].get<double>(), tmpl.joints[2].twist_axis.x(),
              0.0);
  const int weights = AttributeAccessor(glb, "WEIGHTS_0");
  for (int i = 0; i < count; ++i) {
    double sum = 0.0;
    for (int c = 0; c < 4; ++c) sum += ReadFloat(glb, weights, i, c, 4);
    EXPECT_NEAR(sum, 1.0, 1e-7);
  }
}

TEST_F(TemplateIoTest, RoundTripWithoutUvsOrCharts) {
  Template tmpl = MakeTube(3, 5);
  tmpl.uvs.resize(0, 2);
  tmpl.uv_triangles.resize(0, 3);
  tmpl.triangle_chart.resize(0);
  const std::string path = Path("plain.glb");
  WriteTemplateGlb(path, tmpl);
  ExpectSameTemplate(tmpl, ReadTemplateGlb(path));
}

TEST_F(TemplateIoTest, TextureIsEmbeddedAsPngAndReturned) {
  const Template tmpl = MakeTube(2, 4);
  GlbTexture texture;
  texture.width = 8;
  texture.height = 4;
  for (int i = 0; i < 8 * 4; ++i) {
    texture.rgb.insert(texture.rgb.end(), {static_cast<unsigned char>(i * 7),
                                           static_cast<unsigned char>(255 - i), 40});
  }
  const std::string path = Path("textured.glb");
  WriteTemplateGlb(path, tmpl, &texture);
  GlbTexture back;
  const Template read = ReadTemplateGlb(path, &back);
  ExpectSameTemplate(tmpl, read);
  ASSERT_GT(back.png.size(), 8u);
  EXPECT_EQ(back.png[1], 'P');
  EXPECT_EQ(back.png[2], 'N');
  EXPECT_EQ(back.png[3], 'G');
  // Encoded PNG bytes are embedded unchanged.
  GlbTexture encoded;
  encoded.png = back.png;
  const std::string path2 = Path("textured2.glb");
  WriteTemplateGlb(path2, tmpl, &encoded);
  GlbTexture back2;
  ReadTemplateGlb(path2, &back2);
  EXPECT_EQ(back2.png, back.png);
  // A file without texture returns an empty one.
  const std::string plain = Path("plain.glb");
  WriteTemplateGlb(plain, tmpl);
  GlbTexture none;
  none.png = {1, 2, 3};
  ReadTemplateGlb(plain, &none);
  EXPECT_TRUE(none.empty());
  // Bad textures are rejected, naming the file, and leave no file behind.
  GlbTexture bad;
  bad.width = 3;
  bad.height = 3;
  bad.rgb.assign(5, 0);
  const std::string bad_path = Path("bad_texture.glb");
  EXPECT_THROW(WriteTemplateGlb(bad_path, tmpl, &bad), Error);
  EXPECT_FALSE(fs::exists(bad_path));
}

// Evaluates glTF linear-blend skinning from the file's skin, nodes and animation key `frame`,
// as a viewer would, returning the posed position of every template vertex.
Eigen::MatrixX3d EvaluateGltfSkinning(const Glb& glb, int frame, int num_vertices) {
  const json& g = glb.gltf;
  const int num_nodes = static_cast<int>(g["nodes"].size());
  std::vector<Eigen::Vector3d> translation(num_nodes, Eigen::Vector3d::Zero());
  std::vector<Eigen::Quaterniond> rotation(num_nodes, Eigen::Quaterniond::Identity());
  std::vector<Eigen::Vector3d> scale(num_nodes, Eigen::Vector3d::Ones());
  std::vector<int> parent(num_nodes, -1);
  for (int n = 0; n < num_nodes; ++n) {
    const json& node = g["nodes"][n];
    if (node.contains("translation")) {
      for (int c = 0; c < 3; ++c) translation[n][c] = node["translation"][c].get<double>();
    }
    if (node.contains("children")) {
      for (const json& child : node["children"]) parent[child.get<int>()] = n;
    }
  }
  for (const json& channel : g["animations"][0]["channels"]) {
    const json& sampler = g["animations"][0]["samplers"][channel["sampler"].get<int>()];
    const int node = channel["target"]["node"].get<int>();
    const std::string path = channel["target"]["path"];
    const int out = sampler["output"].get<int>();
    if (path == "translation") {
      for (int c = 0; c < 3; ++c) translation[node][c] = ReadFloat(glb, out, frame, c, 3);
    } else if (path == "scale") {
      for (int c = 0; c < 3; ++c) scale[node][c] = ReadFloat(glb, out, frame, c, 3);
    } else {
      rotation[node] = Eigen::Quaterniond(
          ReadFloat(glb, out, frame, 3, 4), ReadFloat(glb, out, frame, 0, 4),
          ReadFloat(glb, out, frame, 1, 4), ReadFloat(glb, out, frame, 2, 4));
    }
  }
  std::function<Eigen::Matrix4d(int)> world = [&](int n) -> Eigen::Matrix4d {
    Eigen::Matrix4d local = Eigen::Matrix4d::Identity();
    local.block<3, 3>(0, 0) = rotation[n].normalized().toRotationMatrix() * scale[n].asDiagonal();
    local.block<3, 1>(0, 3) = translation[n];
    return parent[n] >= 0 ? Eigen::Matrix4d(world(parent[n]) * local) : local;
  };
  const json& skin = g["skins"][0];
  const int ibm = skin["inverseBindMatrices"].get<int>();
  std::vector<Eigen::Matrix4d> joint_matrix;
  for (size_t j = 0; j < skin["joints"].size(); ++j) {
    Eigen::Matrix4d inverse_bind;
    for (int k = 0; k < 16; ++k) inverse_bind(k % 4, k / 4) = ReadFloat(glb, ibm, j, k, 16);
    joint_matrix.push_back(world(skin["joints"][j].get<int>()) * inverse_bind);
  }
  const int pos = AttributeAccessor(glb, "POSITION"), joints = AttributeAccessor(glb, "JOINTS_0"),
            weights = AttributeAccessor(glb, "WEIGHTS_0"),
            ids = AttributeAccessor(glb, "_ARTEX_VERTEX");
  Eigen::MatrixX3d posed = Eigen::MatrixX3d::Zero(num_vertices, 3);
  const int count = g["accessors"][pos]["count"].get<int>();
  for (int i = 0; i < count; ++i) {
    const Eigen::Vector4d x(ReadFloat(glb, pos, i, 0, 3), ReadFloat(glb, pos, i, 1, 3),
                            ReadFloat(glb, pos, i, 2, 3), 1.0);
    Eigen::Vector4d y = Eigen::Vector4d::Zero();
    for (int c = 0; c < 4; ++c) {
      y += ReadFloat(glb, weights, i, c, 4) * (joint_matrix[ReadU16(glb, joints, i, c, 4)] * x);
    }
    posed.row(static_cast<int>(ReadFloat(glb, ids, i, 0, 1))) = y.head<3>().transpose();
  }
  return posed;
}

// Random pose whose joint rotations have no twist about the joints' axes (there the glTF
// linear-blend skin reproduces the paper's model exactly).
Pose RandomSwingPose(const Template& tmpl, std::mt19937_64& rng, double max_angle) {
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  Pose pose = Pose::Identity(tmpl.num_joints());
  pose.scale = 1.0 + 0.2 * uniform(rng);
  pose.translation = Eigen::Vector3d(uniform(rng), uniform(rng), uniform(rng));
  pose.rotation = Eigen::AngleAxisd(M_PI * uniform(rng),
                                    Eigen::Vector3d(uniform(rng), uniform(rng), 1.0).normalized())
                      .toRotationMatrix();
  for (int j = 0; j < tmpl.num_joints(); ++j) {
    const Eigen::Vector3d a = tmpl.joints[j].twist_axis;
    Eigen::Vector3d d(uniform(rng), uniform(rng), uniform(rng));
    d -= a * a.dot(d);
    pose.joint_rotations[j] =
        Eigen::AngleAxisd(max_angle * uniform(rng), d.normalized()).toRotationMatrix();
  }
  return pose;
}

TEST_F(TemplateIoTest, AnimatedGlbPosesLikeTheSkinningModelWithoutTwist) {
  const Template tmpl = MakeTube();
  std::mt19937_64 rng(7);
  std::vector<Pose> poses;
  for (int f = 0; f < 4; ++f) poses.push_back(RandomSwingPose(tmpl, rng, 0.8));
  const std::string path = Path("animated.glb");
  WriteAnimatedGlb(path, tmpl, poses, 30.0);
  ExpectSameTemplate(tmpl, ReadTemplateGlb(path));  // the animation is ignored on read
  const Glb glb = ParseGlb(ReadBytes(path));
  const json& animation = glb.gltf["animations"][0];
  EXPECT_EQ(animation["channels"].size(), 3u + tmpl.num_joints());
  const int input = animation["samplers"][0]["input"].get<int>();
  EXPECT_EQ(glb.gltf["accessors"][input]["count"].get<int>(), 4);
  EXPECT_NEAR(glb.gltf["accessors"][input]["max"][0].get<double>(), 3.0 / 30.0, 1e-7);
  const Skinning skinning(tmpl);
  for (int f = 0; f < 4; ++f) {
    Eigen::MatrixX3d expected;
    skinning.Apply(poses[f], &expected);
    const Eigen::MatrixX3d gltf = EvaluateGltfSkinning(glb, f, tmpl.num_vertices());
    EXPECT_LT((gltf - expected).rowwise().norm().maxCoeff(), 2e-5) << "frame " << f;
  }
}

TEST_F(TemplateIoTest, AnimatedGlbRejectsBadPoses) {
  const Template tmpl = MakeTube(2, 4);
  const std::string path = Path("bad_animation.glb");
  std::vector<Pose> poses = {Pose::Identity(tmpl.num_joints())};
  EXPECT_THROW(WriteAnimatedGlb(path, tmpl, {}, 30.0), Error);
  EXPECT_THROW(WriteAnimatedGlb(path, tmpl, poses, 0.0), Error);
  EXPECT_THROW(WriteAnimatedGlb(path, tmpl, {Pose::Identity(2)}, 30.0), Error);
  poses[0].scale = std::nan("");
  try {
    WriteAnimatedGlb(path, tmpl, poses, 30.0);
    ADD_FAILURE() << "NaN pose accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(path));
}

TEST_F(TemplateIoTest, InvalidTemplateIsNotWritten) {
  Template tmpl = MakeTube(2, 4);
  tmpl.lbs_weight[3] = 1.5;
  const std::string path = Path("invalid.glb");
  try {
    WriteTemplateGlb(path, tmpl);
    ADD_FAILURE() << "invalid template written";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("lbs_weight"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(path));
  EXPECT_THROW(WriteTemplateGlb(Path("missing_folder/x.glb"), MakeTube(2, 4)), Error);
}

TEST_F(TemplateIoTest, MissingTruncatedAndMalformedFilesAreReported) {
  ExpectReadError(Path("does_not_exist.glb"), "no such file");
  const std::string good = EncodeTemplateGlb(MakeTube(3, 4));
  const std::string truncated = Path("truncated.glb");
  WriteBytes(truncated, good.substr(0, good.size() / 2));
  ExpectReadError(truncated, "truncated");
  const std::string tiny = Path("tiny.glb");
  WriteBytes(tiny, good.substr(0, 7));
  ExpectReadError(tiny, "glTF");
  const std::string text = Path("text.glb");
  WriteBytes(text, "solid cube\nfacet normal 0 0 1\n");
  ExpectReadError(text, "not a glTF binary");
  // A valid container with broken JSON.
  std::string broken = good;
  const uint32_t json_length = U32(good, 12);
  broken[20 + json_length / 2] = '{';
  broken[20 + json_length / 2 + 1] = '{';
  const std::string bad_json = Path("bad_json.glb");
  WriteBytes(bad_json, broken);
  ExpectReadError(bad_json, "malformed glTF");
}

TEST_F(TemplateIoTest, MissingAttributesAreReported) {
  const Glb glb = ParseGlb(EncodeTemplateGlb(MakeTube(3, 4)));
  for (const std::string name : {"_ARTEX_JOINT", "_ARTEX_LBS_WEIGHT", "_ARTEX_SLERP_TAU",
                                 "WEIGHTS_0", "POSITION"}) {
    Glb broken = glb;
    broken.gltf["meshes"][0]["primitives"][0]["attributes"].erase(name);
    const std::string path = Path("missing" + name + ".glb");
    WriteBytes(path, BuildGlb(broken));
    ExpectReadError(path, name);
  }
  // Without any artex attribute the reader points to the generic importer.
  const std::string plain = Path("plain_skin.glb");
  WriteBytes(plain, BuildGlb(StripArtexAttributes(glb)));
  ExpectReadError(plain, "import-gltf");
}

TEST_F(TemplateIoTest, NonFiniteValuesAreReported) {
  const Glb glb = ParseGlb(EncodeTemplateGlb(MakeTube(3, 4)));
  Glb broken = glb;
  WriteFloat(&broken, AttributeAccessor(glb, "POSITION"), 5, 1, 3, std::nanf(""));
  const std::string path = Path("nan_position.glb");
  WriteBytes(path, BuildGlb(broken));
  ExpectReadError(path, "non-finite");
  Glb broken_tau = glb;
  WriteFloat(&broken_tau, AttributeAccessor(glb, "_ARTEX_SLERP_TAU"), 2, 0, 1,
             std::numeric_limits<float>::infinity());
  const std::string tau_path = Path("inf_tau.glb");
  WriteBytes(tau_path, BuildGlb(broken_tau));
  ExpectReadError(tau_path, "_ARTEX_SLERP_TAU");
}

TEST_F(TemplateIoTest, WeightsThatDoNotSumToOneAreReported) {
  const Glb glb = ParseGlb(EncodeTemplateGlb(MakeTube(3, 4)));
  Glb broken = glb;
  const int weights = AttributeAccessor(glb, "WEIGHTS_0");
  WriteFloat(&broken, weights, 7, 0, 4, ReadFloat(glb, weights, 7, 0, 4) + 0.25f);
  const std::string path = Path("weights.glb");
  WriteBytes(path, BuildGlb(broken));
  ExpectReadError(path, "sum to");
  Glb out_of_range = glb;
  WriteFloat(&out_of_range, AttributeAccessor(glb, "_ARTEX_LBS_WEIGHT"), 3, 0, 1, 1.5f);
  const std::string lbs_path = Path("lbs.glb");
  WriteBytes(lbs_path, BuildGlb(out_of_range));
  ExpectReadError(lbs_path, "_ARTEX_LBS_WEIGHT");
}

TEST_F(TemplateIoTest, JointHierarchyCyclesAndBadIndicesAreReported) {
  const Glb glb = ParseGlb(EncodeTemplateGlb(MakeTube(3, 4)));
  // Nodes: 0 mesh, 1 global, 2 root, 3 mid, 4 tip, 5 side. Make the global node a child of
  // "tip": global -> root -> mid -> tip -> global.
  Glb cycle = glb;
  cycle.gltf["nodes"][4]["children"] = json::array({1});
  cycle.gltf["scenes"][0]["nodes"] = json::array({0});
  const std::string path = Path("cycle.glb");
  WriteBytes(path, BuildGlb(cycle));
  ExpectReadError(path, "cycle");
  Glb self = glb;
  self.gltf["nodes"][3]["children"] = json::array({3, 4});
  const std::string self_path = Path("self.glb");
  WriteBytes(self_path, BuildGlb(self));
  ExpectReadError(self_path, "cycle");
  Glb bad_joint = glb;
  WriteFloat(&bad_joint, AttributeAccessor(glb, "_ARTEX_JOINT"), 1, 0, 1, 9.0f);
  const std::string joint_path = Path("bad_joint.glb");
  WriteBytes(joint_path, BuildGlb(bad_joint));
  ExpectReadError(joint_path, "_ARTEX_JOINT");
  Glb bad_index = glb;
  bad_index.gltf["accessors"][AttributeAccessor(glb, "POSITION")]["count"] = 100000;
  const std::string index_path = Path("bad_count.glb");
  WriteBytes(index_path, BuildGlb(bad_index));
  ExpectReadError(index_path, "beyond");
}

// Issue 20: files that made the reader crash, allocate gigabytes or run for minutes.
TEST_F(TemplateIoTest, DeeplyNestedJsonIsRejectedBeforeParsing) {
  const Glb glb = ParseGlb(EncodeTemplateGlb(MakeTube(3, 4)));
  constexpr int kDepth = 1000000;  // overflowed the stack inside tinygltf (SIGSEGV)
  std::string text = glb.gltf.dump();
  ASSERT_EQ(text[0], '{');
  text =
      "{\"extras\":" + std::string(kDepth, '[') + std::string(kDepth, ']') + "," + text.substr(1);
  const std::string bytes = BuildGlb(glb);  // its JSON chunk replaced by `text`
  const uint32_t old_length = U32(bytes, 12);
  while (text.size() % 4) text.push_back(' ');
  std::string out = bytes.substr(0, 12);
  AppendU32(&out, static_cast<uint32_t>(text.size()));
  AppendU32(&out, 0x4E4F534A);
  out += text + bytes.substr(20 + old_length);
  const uint32_t total = static_cast<uint32_t>(out.size());
  std::memcpy(&out[8], &total, 4);
  const std::string path = Path("deep.glb");
  WriteBytes(path, out);
  ExpectReadError(path, "nests deeper than 64");
  // Brackets inside strings do not count.
  Glb strings = glb;
  strings.gltf["extras"] = {{"note", std::string(1000, '[')}};
  const std::string strings_path = Path("brackets_in_strings.glb");
  WriteBytes(strings_path, BuildGlb(strings));
  EXPECT_NO_THROW(ReadTemplateGlb(strings_path));
}

TEST_F(TemplateIoTest, SkinListingAJointTwiceIsAnError) {
  Glb glb = ParseGlb(EncodeTemplateGlb(MakeTube(3, 4)));
  json& joints = glb.gltf["skins"][0]["joints"];
  ASSERT_GE(joints.size(), 3u);
  joints[joints.size() - 1] = joints[1];  // loaded with a joint missing before
  const std::string path = Path("twice.glb");
  WriteBytes(path, BuildGlb(glb));
  ExpectReadError(path, "listed twice");
}

TEST_F(TemplateIoTest, DeclaredCountsAreCappedByTheFileSize) {
  const Glb glb = ParseGlb(EncodeTemplateGlb(MakeTube(3, 4)));
  // A vertex count in extras far beyond the glTF vertices (allocated before).
  Glb vertices = glb;
  vertices.gltf["meshes"][0]["extras"]["artex_num_vertices"] = 1000000000;
  const std::string vertices_path = Path("many_vertices.glb");
  WriteBytes(vertices_path, BuildGlb(vertices));
  ExpectReadError(vertices_path, "artex_num_vertices");
  Glb huge = glb;
  huge.gltf["meshes"][0]["extras"]["artex_num_vertices"] = 1e300;  // no undefined cast
  const std::string huge_path = Path("huge_count.glb");
  WriteBytes(huge_path, BuildGlb(huge));
  ExpectReadError(huge_path, "artex_num_vertices");
  // An accessor without data (all zeros) declaring 2^27 elements: 3 GB of doubles before.
  Glb zeros = glb;
  json& position = zeros.gltf["accessors"][AttributeAccessor(glb, "POSITION")];
  position.erase("bufferView");
  position.erase("byteOffset");
  position["count"] = 1 << 27;
  const std::string zeros_path = Path("zeros.glb");
  WriteBytes(zeros_path, BuildGlb(zeros));
  ExpectReadError(zeros_path, "without a buffer view");
}

TEST_F(TemplateIoTest, LongNodeChainsAreCheckedInLinearTime) {
  // 200,000 plain nodes in a chain above the global node: the cycle check walked every node to
  // the root (quadratic, minutes) and the world transforms recursed once per level.
  constexpr int kChain = 200000;
  Glb glb = ParseGlb(EncodeTemplateGlb(MakeTube(3, 4)));
  json& nodes = glb.gltf["nodes"];
  const int first = static_cast<int>(nodes.size());
  for (int k = 0; k < kChain; ++k) {
    const int child = k + 1 < kChain ? first + k + 1 : 1;  // the last holds the global node
    nodes.push_back({{"children", json::array({child})}});
  }
  json& scene = glb.gltf["scenes"][0]["nodes"];
  for (auto& n : scene) {
    if (n.get<int>() == 1) n = first;
  }
  const std::string path = Path("chain.glb");
  WriteBytes(path, BuildGlb(glb));
  const Template read = ReadTemplateGlb(path);
  EXPECT_EQ(read.num_joints(), MakeTube(3, 4).num_joints());
}

// ---------------------------------------------------------------------------------------------
// Generic glTF import.

TEST_F(TemplateIoTest, ImportOfAPlainSkinRecoversTheSkinningConstants) {
  const Template tmpl = MakeTube();
  const std::string path = Path("plain_skin.glb");
  WriteBytes(path, BuildGlb(StripArtexAttributes(ParseGlb(EncodeTemplateGlb(tmpl)))));
  VertexJointWeights weights;
  const Template imported = ImportGltfSkinnedMesh(path, GltfImportOptions(), &weights);
  // The global-similarity node becomes an extra root joint; everything else maps through.
  ASSERT_EQ(imported.num_joints(), tmpl.num_joints() + 1);
  EXPECT_EQ(imported.joints[0].name, "artex_global");
  EXPECT_EQ(imported.joints[1].name, "root");
  for (int j = 0; j < tmpl.num_joints(); ++j) {
    EXPECT_LT((imported.joints[j + 1].center - tmpl.joints[j].center).norm(), 1e-12);
  }
  // Welding merges the seam copies back into one vertex each; compare corner by corner.
  ASSERT_EQ(imported.num_vertices(), tmpl.num_vertices());
  ASSERT_EQ(imported.num_triangles(), tmpl.num_triangles());
  int checked = 0;
  for (int f = 0; f < tmpl.num_triangles(); ++f) {
    for (int c = 0; c < 3; ++c) {
      const int a = tmpl.triangles(f, c), b = imported.triangles(f, c);
      EXPECT_LT((tmpl.vertices.row(a) - imported.vertices.row(b)).norm(), 1e-6);
      EXPECT_EQ(imported.vertex_joint[b], tmpl.vertex_joint[a] + 1);
      EXPECT_NEAR(imported.lbs_weight[b], tmpl.lbs_weight[a], 1e-6);
      ++checked;
    }
  }
  EXPECT_GT(checked, 0);
  EXPECT_TRUE(imported.has_uvs());
  EXPECT_EQ(imported.triangle_chart.maxCoeff() + 1, 1);  // one UV island (seam only at the sides)
}

// Up to three joints per vertex with smooth falloff along the tube: a typical LBS rig.
void WriteSmoothWeights(Glb* glb, const Template& tmpl) {
  const int joints = AttributeAccessor(*glb, "JOINTS_0"), weights = AttributeAccessor(*glb, "WEIGHTS_0"),
            ids = AttributeAccessor(*glb, "_ARTEX_VERTEX");
  const int count = glb->gltf["accessors"][joints]["count"].get<int>();
  const double centers[3] = {0.1, 0.8, 1.5};
  for (int i = 0; i < count; ++i) {
    const int v = static_cast<int>(ReadFloat(*glb, ids, i, 0, 1));
    const double y = tmpl.vertices(v, 1);
    double w[3], sum = 0.0;
    for (int j = 0; j < 3; ++j) {
      w[j] = std::exp(-std::pow((y - centers[j]) / 0.35, 2));
      sum += w[j];
    }
    for (int j = 0; j < 3; ++j) {
      WriteU16(glb, joints, i, j, 4, static_cast<uint16_t>(j + 1));  // skin joint j+1 = joint j
      WriteFloat(glb, weights, i, j, 4, static_cast<float>(w[j] / sum));
    }
    WriteU16(glb, joints, i, 3, 4, 0);
    WriteFloat(glb, weights, i, 3, 4, 0.0f);
  }
}

TEST_F(TemplateIoTest, ImportedLbsApproximationErrorIsSmall) {
  const Template tmpl = MakeTube(16, 12);
  Glb glb = ParseGlb(EncodeTemplateGlb(tmpl));
  WriteSmoothWeights(&glb, tmpl);
  const std::string path = Path("smooth_skin.glb");
  WriteBytes(path, BuildGlb(StripArtexAttributes(glb)));
  VertexJointWeights weights;
  const Template imported = ImportGltfSkinnedMesh(path, GltfImportOptions(), &weights);
  const Skinning skinning(imported);
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  double sum = 0.0, max_error = 0.0;
  int n = 0;
  for (int trial = 0; trial < 20; ++trial) {
    Pose pose = Pose::Identity(imported.num_joints());
    for (int j = 1; j < imported.num_joints(); ++j) {  // joint 0: the (static) global node
      pose.joint_rotations[j] =
          Eigen::AngleAxisd(0.5 * uniform(rng),
                            Eigen::Vector3d(uniform(rng), uniform(rng), uniform(rng)).normalized())
              .toRotationMatrix();
    }
    Eigen::MatrixX3d artex;
    skinning.Apply(pose, &artex);
    const Eigen::MatrixX3d lbs = PoseLinearBlend(imported, weights, pose);
    const Eigen::VectorXd d = (artex - lbs).rowwise().norm();
    sum += d.sum();
    n += static_cast<int>(d.size());
    max_error = std::max(max_error, d.maxCoeff());
  }
  const double mean = sum / n;
  std::printf("LBS -> artex conversion on a 2 m tube, 3 joints, rotations up to 29 deg: "
              "mean %.2f mm, max %.2f mm\n", 1e3 * mean, 1e3 * max_error);
  EXPECT_LT(mean, 0.02);
  EXPECT_LT(max_error, 0.1);
  // Conversion sanity: vertices at a joint centre's height belong to that joint.
  for (int v = 0; v < imported.num_vertices(); ++v) {
    if (std::abs(imported.vertices(v, 1) - 1.5) < 0.05) {
      EXPECT_EQ(imported.vertex_joint[v], 3);
    }
  }
}

TEST_F(TemplateIoTest, ImportRejectsFilesWithoutSkinOrWithSeveralRoots) {
  const Glb glb = StripArtexAttributes(ParseGlb(EncodeTemplateGlb(MakeTube(3, 4))));
  Glb no_skin = glb;
  no_skin.gltf["nodes"][0].erase("skin");
  const std::string path = Path("no_skin.glb");
  WriteBytes(path, BuildGlb(no_skin));
  try {
    ImportGltfSkinnedMesh(path);
    ADD_FAILURE() << "file without skin accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no skinned mesh"), std::string::npos) << e.what();
  }
  Glb two_roots = glb;
  two_roots.gltf["skins"][0]["joints"] = json::array({2, 3, 4, 5});  // without the global node
  two_roots.gltf["nodes"][1]["children"] = json::array({2});
  two_roots.gltf["nodes"][2]["children"] = json::array({5});  // "mid" (3) detached
  two_roots.gltf["scenes"][0]["nodes"] = json::array({0, 1, 3});
  const std::string roots_path = Path("two_roots.glb");
  WriteBytes(roots_path, BuildGlb(two_roots));
  try {
    ImportGltfSkinnedMesh(roots_path);
    ADD_FAILURE() << "two root joints accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("root joint"), std::string::npos) << e.what();
  }
}

// ---------------------------------------------------------------------------------------------
// Khronos validator (skipped when node or the gltf-validator module is unavailable).

std::string NodeModulesDir() {
  if (const char* env = std::getenv("ARTEX_NODE_MODULES")) return env;
  return std::string(ARTEX_SOURCE_DIR) + "/build/node/node_modules";
}

TEST_F(TemplateIoTest, KhronosValidatorAcceptsTheFiles) {
  if (std::system("node --version > /dev/null 2>&1") != 0) GTEST_SKIP() << "node not found";
  const std::string modules = NodeModulesDir();
  if (!fs::exists(modules + "/gltf-validator/package.json")) {
    GTEST_SKIP() << "gltf-validator not installed in " << modules
                 << " (run scripts/install_gltf_validator)";
  }
  const Template tmpl = MakeTube();
  GlbTexture texture;
  texture.width = 4;
  texture.height = 4;
  texture.rgb.assign(4 * 4 * 3, 128);
  std::mt19937_64 rng(3);
  std::vector<Pose> poses;
  for (int f = 0; f < 3; ++f) poses.push_back(RandomSwingPose(tmpl, rng, 0.5));
  WriteTemplateGlb(Path("static.glb"), tmpl);
  WriteTemplateGlb(Path("textured.glb"), tmpl, &texture);
  WriteAnimatedGlb(Path("animated.glb"), tmpl, poses, 24.0, &texture);
  // With a morph target per frame (appended after the buffer's own data) and their weights
  // as a sparse accessor.
  AnimatedGlbSummary exact;
  WriteAnimatedGlb(Path("exact.glb"), tmpl, poses, 24.0, &texture, AnimatedGlbOptions(), &exact);
  EXPECT_EQ(exact.morph_targets, 3);
  EXPECT_EQ(exact.bytes, fs::file_size(Path("exact.glb")));
  Eigen::MatrixX3d posed = tmpl.vertices;
  WritePosedMesh(Path("posed.glb"), posed, tmpl.triangles);
  const std::string report = Path("report.txt");
  const std::string command = "node '" + std::string(ARTEX_SOURCE_DIR) +
                              "/scripts/validate_gltf.mjs' --node-modules '" + modules + "' '" +
                              Path("static.glb") + "' '" + Path("textured.glb") + "' '" +
                              Path("animated.glb") + "' '" + Path("exact.glb") + "' '" +
                              Path("posed.glb") + "' > '" + report + "' 2>&1";
  const int status = std::system(command.c_str());
  const std::string output = ReadBytes(report);
  std::printf("%s", output.c_str());
  EXPECT_EQ(status, 0) << output;
  EXPECT_NE(output.find("static.glb: 0 errors"), std::string::npos) << output;
  EXPECT_NE(output.find("animated.glb: 0 errors"), std::string::npos) << output;
  EXPECT_NE(output.find("exact.glb: 0 errors, 0 warnings"), std::string::npos) << output;
  // And the validator does flag a corrupted file (the check can fail).
  Glb broken = ParseGlb(ReadBytes(Path("static.glb")));
  WriteFloat(&broken, AttributeAccessor(broken, "WEIGHTS_0"), 0, 0, 4, 0.25f);
  WriteBytes(Path("broken.glb"), BuildGlb(broken));
  const std::string command2 = "node '" + std::string(ARTEX_SOURCE_DIR) +
                               "/scripts/validate_gltf.mjs' --node-modules '" + modules + "' '" +
                               Path("broken.glb") + "' > /dev/null 2>&1";
  EXPECT_NE(std::system(command2.c_str()), 0);
}

// ---------------------------------------------------------------------------------------------
// Summary (artex template info).

TEST(TemplateSummaryTest, CountsTopologyAndUvCoverage) {
  const Template tube = MakeTube(4, 6);
  const TemplateSummary s = SummarizeTemplate(tube);
  EXPECT_EQ(s.num_vertices, tube.num_vertices());
  EXPECT_EQ(s.num_pose_parameters, 7 + 3 * 4);
  EXPECT_EQ(s.boundary_edges, 2 * 6);  // the two open ends
  EXPECT_EQ(s.non_manifold_edges, 0);
  EXPECT_EQ(s.misoriented_edges, 0);
  EXPECT_EQ(s.components, 1);
  EXPECT_EQ(s.unreferenced_vertices, 1);
  EXPECT_EQ(s.euler_characteristic, 0);  // an open cylinder
  EXPECT_FALSE(s.closed_manifold());
  EXPECT_NEAR(s.uv_coverage, 0.81, 0.01);  // the UV rectangle is 0.9 x 0.9
  EXPECT_EQ(s.uv_overlap, 0.0);
  EXPECT_EQ(s.num_charts, 2);
  EXPECT_EQ(s.vertices_per_joint[3], 0);

  // A closed tetrahedron; then one triangle flipped.
  Template tet = tube;
  tet.vertices.resize(4, 3);
  tet.vertices << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  tet.triangles.resize(4, 3);
  tet.triangles << 0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3;
  tet.uvs.resize(3, 2);
  tet.uvs << 0, 0, 1, 0, 0, 1;
  tet.uv_triangles.resize(4, 3);
  tet.uv_triangles << 0, 1, 2, 0, 1, 2, 0, 1, 2, 0, 1, 2;  // four copies of one UV triangle
  tet.triangle_chart.resize(0);
  tet.vertex_joint = Eigen::VectorXi::Zero(4);
  tet.lbs_weight = Eigen::VectorXd::Ones(4);
  tet.slerp_tau = Eigen::VectorXd::Zero(4);
  const TemplateSummary closed = SummarizeTemplate(tet);
  EXPECT_TRUE(closed.closed_manifold());
  EXPECT_EQ(closed.euler_characteristic, 2);
  EXPECT_NEAR(closed.uv_coverage, 0.5, 0.01);
  EXPECT_NEAR(closed.uv_overlap, 1.0, 1e-12);
  tet.triangles.row(3) << 1, 3, 2;
  EXPECT_EQ(SummarizeTemplate(tet).misoriented_edges, 3);
  TemplateSummaryOptions bad;
  bad.uv_grid = 4;
  EXPECT_THROW(SummarizeTemplate(tet, bad), Error);
}

// ---------------------------------------------------------------------------------------------
// Posed mesh export.

TEST_F(TemplateIoTest, PosedMeshExportWritesPlyObjAndGlb) {
  const Template tmpl = MakeTube(3, 6);
  Eigen::MatrixX3d colors = Eigen::MatrixX3d::Constant(tmpl.num_vertices(), 3, 0.5);
  colors(0, 0) = 1.0;
  WritePosedMesh(Path("posed.ply"), tmpl.vertices, tmpl.triangles, colors);
  WritePosedMesh(Path("posed.obj"), tmpl.vertices, tmpl.triangles);
  WritePosedMesh(Path("posed.glb"), tmpl.vertices, tmpl.triangles);
  const std::string ply = ReadBytes(Path("posed.ply"));
  EXPECT_EQ(ply.rfind("ply", 0), 0u);
  EXPECT_NE(ply.find("binary_little_endian"), std::string::npos);
  EXPECT_NE(ply.find("element vertex " + std::to_string(tmpl.num_vertices())), std::string::npos);
  EXPECT_NE(ply.find("element face " + std::to_string(tmpl.num_triangles())), std::string::npos);
  EXPECT_NE(ply.find("property uchar red"), std::string::npos);
  // OBJ: count vertex and face lines; parse back with the OBJ reader.
  const ObjMesh obj = ReadObj(Path("posed.obj"));
  ASSERT_EQ(static_cast<int>(obj.faces.size()), tmpl.num_triangles());
  ASSERT_EQ(static_cast<int>(obj.positions.size()), tmpl.num_vertices());
  double max_error = 0.0;
  for (int v = 0; v < tmpl.num_vertices(); ++v) {
    max_error = std::max(max_error, (obj.positions[v] - tmpl.vertices.row(v).transpose()).norm());
  }
  EXPECT_LT(max_error, 1e-7);
  for (int f = 0; f < tmpl.num_triangles(); ++f) {
    for (int c = 0; c < 3; ++c) EXPECT_EQ(obj.faces[f].position[c], tmpl.triangles(f, c));
  }
  const Template glb = ReadTemplateGlb(Path("posed.glb"));
  EXPECT_EQ(glb.num_vertices(), tmpl.num_vertices());
  EXPECT_EQ(glb.num_joints(), 1);
}

TEST_F(TemplateIoTest, PosedMeshExportRejectsBadInput) {
  const Template tmpl = MakeTube(2, 4);
  auto expect_error = [](const std::function<void()>& f, const std::string& fragment) {
    try {
      f();
      ADD_FAILURE() << "no error (expected '" << fragment << "')";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  };
  expect_error([&] { WritePosedMesh(Path("x.stl"), tmpl.vertices, tmpl.triangles); }, ".stl");
  Eigen::MatrixX3i bad = tmpl.triangles;
  bad(0, 0) = 9999;
  expect_error([&] { WritePosedMesh(Path("x.ply"), tmpl.vertices, bad); }, "x.ply");
  Eigen::MatrixX3d nan = tmpl.vertices;
  nan(1, 1) = std::nan("");
  expect_error([&] { WritePosedMesh(Path("y.obj"), nan, tmpl.triangles); }, "non-finite");
  expect_error(
      [&] {
        WritePosedMesh(Path("z.ply"), tmpl.vertices, tmpl.triangles, Eigen::MatrixX3d::Ones(2, 3));
      },
      "colors");
  EXPECT_FALSE(fs::exists(Path("x.ply")));
  EXPECT_FALSE(fs::exists(Path("y.obj")));
  EXPECT_FALSE(fs::exists(Path("z.ply")));
}

}  // namespace
}  // namespace artex
