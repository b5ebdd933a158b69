// Template files (models/template_io.h): round trips, the embedded texture, the animated GLB,
// and the reader rejecting missing, truncated, malformed and hostile files with clear errors.
#include "tests/models/template_io_test_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using testing_util::AppendU32;
using testing_util::AttributeAccessor;
using testing_util::BuildGlb;
using testing_util::ExpectSameTemplate;
using testing_util::Glb;
using testing_util::MakeTube;
using testing_util::ParseGlb;
using testing_util::RandomSwingPose;
using testing_util::ReadFloat;
using testing_util::ReadU16;
using testing_util::StripArtexAttributes;
using testing_util::TemplateIoTest;
using testing_util::U32;
using testing_util::WriteFloat;

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


}  // namespace
}  // namespace artex
