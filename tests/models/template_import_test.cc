// Template files beyond artex's own: a plain skinned glTF imported (models/template_io.h), the
// Khronos validator on artex's files, the template summary, and posed mesh export.
#include "tests/models/template_io_test_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using testing_util::AttributeAccessor;
using testing_util::BuildGlb;
using testing_util::Glb;
using testing_util::MakeTube;
using testing_util::ParseGlb;
using testing_util::RandomSwingPose;
using testing_util::ReadFloat;
using testing_util::StripArtexAttributes;
using testing_util::TemplateIoTest;
using testing_util::WriteFloat;
using testing_util::WriteU16;

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
