#include "models/makehuman_import.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <random>
#include <set>
#include <string>

#include "models/error.h"
#include "models/skinning.h"
#include "models/template_generator.h"
#include "models/template_io.h"
#include "tests/models/small_makehuman.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------------------
// Conversion rules (no data needed).

std::vector<Joint> ChainJoints() {
  // 0 root <- 1 <- 2, and 0 <- 3 (branch).
  std::vector<Joint> joints(4);
  const int parents[4] = {-1, 0, 1, 0};
  const Eigen::Vector3d centers[4] = {{0, 0, 0}, {0, 1, 0}, {0, 2, 0}, {1, 0, 0}};
  for (int j = 0; j < 4; ++j) {
    joints[j].name = "j" + std::to_string(j);
    joints[j].parent = parents[j];
    joints[j].center = centers[j];
  }
  return joints;
}

TEST(ConvertLbsWeightsTest, ExactCasesAndTieBreaking) {
  const std::vector<Joint> joints = ChainJoints();
  const VertexJointWeights weights = {
      {{2, 1.0}},                // fully on a leaf
      {{1, 0.3}, {2, 0.7}},      // child 2 + parent 1
      {{0, 1.0}},                // fully on the root (paired with the global similarity)
      {{1, 0.5}, {0, 0.2}, {3, 0.3}},  // pair (1, 0) carries 0.7 > (3, 0) 0.5 > (0, -) 0.2
      {{1, 0.25}, {1, 0.25}, {2, 0.5}},  // repeated joint entries are summed
      {{0, 0.6}, {1, 0.2}, {3, 0.2}},  // two children tie: the lower index wins
  };
  Eigen::VectorXi k;
  Eigen::VectorXd w, tau;
  ConvertLbsWeights(joints, weights, LbsConversionOptions(), &k, &w, &tau);
  ASSERT_EQ(k.size(), 6);
  EXPECT_EQ(k[0], 2);
  EXPECT_DOUBLE_EQ(w[0], 1.0);
  EXPECT_EQ(k[1], 2);
  EXPECT_DOUBLE_EQ(w[1], 0.7);
  EXPECT_EQ(k[2], 0);
  EXPECT_DOUBLE_EQ(w[2], 1.0);
  EXPECT_EQ(k[3], 1);
  EXPECT_NEAR(w[3], 0.5 / 0.7, 1e-15);
  EXPECT_EQ(k[4], 2);
  EXPECT_DOUBLE_EQ(w[4], 0.5);
  EXPECT_EQ(k[5], 1);
  EXPECT_NEAR(w[5], 0.25, 1e-15);
  EXPECT_TRUE((tau.array() == w.array()).all());
}

TEST(ConvertLbsWeightsTest, RejectsBadInput) {
  const std::vector<Joint> joints = ChainJoints();
  Eigen::VectorXi k;
  Eigen::VectorXd w, tau;
  EXPECT_THROW(ConvertLbsWeights(joints, {{{7, 1.0}}}, LbsConversionOptions(), &k, &w, &tau),
               Error);
  EXPECT_THROW(ConvertLbsWeights(joints, {{}}, LbsConversionOptions(), &k, &w, &tau), Error);
  EXPECT_THROW(ConvertLbsWeights(joints, {{{1, -0.5}}}, LbsConversionOptions(), &k, &w, &tau),
               Error);
  LbsConversionOptions bad;
  bad.min_weight = 1.0;
  EXPECT_THROW(ConvertLbsWeights(joints, {{{1, 1.0}}}, bad, &k, &w, &tau), Error);
}

TEST(ConvertLbsWeightsTest, LinearBlendOfOneBoneIsReproducedExactlyWithoutTwist) {
  // A vertex weighted between joint 2 and its parent 1 poses identically under both models
  // when the rotations have no twist about the joints' axes.
  Template tmpl;
  tmpl.joints = ChainJoints();
  AssignDefaultTwistAxes(&tmpl.joints);
  tmpl.vertices.resize(3, 3);
  tmpl.vertices << 0.1, 1.6, 0.0, -0.1, 1.9, 0.05, 0.05, 2.3, -0.1;
  tmpl.triangles.resize(1, 3);
  tmpl.triangles << 0, 1, 2;
  const VertexJointWeights weights = {{{1, 0.6}, {2, 0.4}}, {{1, 0.2}, {2, 0.8}}, {{2, 1.0}}};
  ConvertLbsWeights(tmpl.joints, weights, LbsConversionOptions(), &tmpl.vertex_joint,
                    &tmpl.lbs_weight, &tmpl.slerp_tau);
  Pose pose = Pose::Identity(4);
  pose.joint_rotations[1] = Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitX()).toRotationMatrix();
  pose.joint_rotations[2] = Eigen::AngleAxisd(-0.5, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  pose.rotation = Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix();
  pose.translation = Eigen::Vector3d(0.2, -0.1, 0.4);
  pose.scale = 1.1;
  Eigen::MatrixX3d artex;
  Skinning(tmpl).Apply(pose, &artex);
  EXPECT_LT((artex - PoseLinearBlend(tmpl, weights, pose)).cwiseAbs().maxCoeff(), 1e-12);
  // With twist about the bone axis the models differ (SLERP vs linear blend of the twist).
  pose.joint_rotations[2] = Eigen::AngleAxisd(1.2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  Skinning(tmpl).Apply(pose, &artex);
  EXPECT_GT((artex - PoseLinearBlend(tmpl, weights, pose)).cwiseAbs().maxCoeff(), 1e-3);
}

TEST(AssignDefaultTwistAxesTest, FollowsTheJointTree) {
  std::vector<Joint> joints = ChainJoints();
  joints.push_back(joints[0]);  // 4: second child of 1, pointing sideways
  joints[4].name = "j4";
  joints[4].parent = 1;
  joints[4].center = Eigen::Vector3d(0.5, 1.0, 0.0);
  AssignDefaultTwistAxes(&joints);
  // Root: two children (1 with subtree 3, 3 with subtree 1): towards 1.
  EXPECT_LT((joints[0].twist_axis - Eigen::Vector3d::UnitY()).norm(), 1e-12);
  // Joint 1: children 2 (straight on) and 4 (sideways): towards 2.
  EXPECT_LT((joints[1].twist_axis - Eigen::Vector3d::UnitY()).norm(), 1e-12);
  // Leaves continue their bone.
  EXPECT_LT((joints[2].twist_axis - Eigen::Vector3d::UnitY()).norm(), 1e-12);
  EXPECT_LT((joints[3].twist_axis - Eigen::Vector3d::UnitX()).norm(), 1e-12);
  EXPECT_LT((joints[4].twist_axis - Eigen::Vector3d::UnitX()).norm(), 1e-12);
}

TEST(UvIslandsTest, SharedUvEdgesJoinTriangles) {
  Eigen::MatrixX3i triangles(3, 3), uv(3, 3);
  triangles << 0, 1, 2, 2, 1, 3, 3, 1, 4;
  uv << 0, 1, 2, 2, 1, 3, 5, 6, 7;  // third triangle: its edge 1-3 uses other UV indices
  const Eigen::VectorXi charts = UvIslands(triangles, uv);
  EXPECT_EQ(charts[0], 0);
  EXPECT_EQ(charts[1], 0);
  EXPECT_EQ(charts[2], 1);
}

// ---------------------------------------------------------------------------------------------
// OBJ reader errors (temporary files).

class ObjReaderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("artex_obj_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Write(const std::string& name, const std::string& text) {
    const std::string path = (dir_ / name).string();
    std::ofstream(path) << text;
    return path;
  }
  void ExpectError(const std::string& text, const std::string& fragment) {
    const std::string path = Write("bad.obj", text);
    try {
      ReadObj(path);
      ADD_FAILURE() << "accepted: " << text;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(path + ":"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  }
  fs::path dir_;
};

TEST_F(ObjReaderTest, ReadsGroupsCornersAndNegativeIndices) {
  const ObjMesh mesh = ReadObj(Write("ok.obj",
                                     "# comment\r\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                     "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                                     "g body\nf 1/1 2/2 3/3 4/4\ng other\nf -4//1 -3//1 -2//1\n"
                                     "s off\nusemtl skin\n"));
  ASSERT_EQ(mesh.positions.size(), 4u);
  ASSERT_EQ(mesh.faces.size(), 2u);
  EXPECT_EQ(mesh.faces[0].group, "body");
  EXPECT_EQ(mesh.faces[0].position, (std::vector<int>{0, 1, 2, 3}));
  EXPECT_EQ(mesh.faces[0].texcoord, (std::vector<int>{0, 1, 2, 3}));
  EXPECT_EQ(mesh.faces[1].group, "other");
  EXPECT_EQ(mesh.faces[1].position, (std::vector<int>{0, 1, 2}));
  EXPECT_TRUE(mesh.faces[1].texcoord.empty());
  EXPECT_EQ(mesh.faces[1].line, 13);
}

TEST_F(ObjReaderTest, ReportsFileAndLine) {
  ExpectError("v 0 0 0\nv 1 x 0\n", ":2: expected a finite number, found 'x'");
  ExpectError("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", ":4: vertex index 4 out of range");
  ExpectError("v 0 0 0\nv 1 0 0\nf 1 2\n", ":3: face: expected at least 3 corners");
  ExpectError("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "start at 1");
  ExpectError("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3\n", "some corners only");
  ExpectError("v 0 0\n", "3 coordinates");
  EXPECT_THROW(ReadObj((dir_ / "missing.obj").string()), Error);
}

// ---------------------------------------------------------------------------------------------
// MakeHuman base mesh (needs ../shared/data/makehuman).

std::string MakeHumanFolder() { return std::string(ARTEX_SHARED_DATA) + "/makehuman"; }

struct Imported {
  Template tmpl;
  VertexJointWeights weights;
  MakeHumanImportReport report;
};

const Imported* ImportOnce() {
  static const std::unique_ptr<Imported> imported = [] {
    auto result = std::make_unique<Imported>();
    result->tmpl = ImportMakeHuman(MakeHumanFolder(), MakeHumanImportOptions(), &result->weights,
                                   &result->report);
    return result;
  }();
  return imported.get();
}

class MakeHumanTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!fs::exists(MakeHumanFolder() + "/base.obj")) {
      GTEST_SKIP() << "MakeHuman data not found in " << MakeHumanFolder();
    }
  }
};

TEST_F(MakeHumanTest, ImportsTheBodyAsAClosed17JointTemplate) {
  const Imported& m = *ImportOnce();
  const Template& t = m.tmpl;
  std::string error;
  ASSERT_TRUE(t.IsValid(&error)) << error;
  EXPECT_EQ(t.num_vertices(), 13380);
  EXPECT_EQ(t.num_triangles(), 2 * 13378);
  EXPECT_EQ(m.report.group_quads, 13378);
  EXPECT_EQ(m.report.obj_vertices, 19158);
  std::printf("MakeHuman body: %d vertices, %d triangles, height %.3f m, boundary edges %d, "
              "non-manifold edges %d, max dropped weight %.3f, %d UV charts\n",
              t.num_vertices(), t.num_triangles(), m.report.height_m, m.report.boundary_edges,
              m.report.non_manifold_edges, m.report.max_joint_weight_loss,
              t.triangle_chart.maxCoeff() + 1);
  EXPECT_EQ(m.report.boundary_edges, 0);  // the body group is closed
  EXPECT_EQ(m.report.non_manifold_edges, 0);
  EXPECT_NEAR(m.report.height_m, 1.67, 0.05);
  EXPECT_DOUBLE_EQ(t.vertices.col(1).minCoeff(), 0.0);
  ASSERT_EQ(t.num_joints(), kDefaultNumJoints);
  for (int j = 0; j < kDefaultNumJoints; ++j) EXPECT_EQ(t.joints[j].name, DefaultJointNames()[j]);
  // Orientation: counter-clockwise from outside (positive enclosed volume, ~55 litres).
  double volume = 0.0;
  for (int f = 0; f < t.num_triangles(); ++f) {
    const Eigen::Vector3d a = t.vertices.row(t.triangles(f, 0)),
                          b = t.vertices.row(t.triangles(f, 1)),
                          c = t.vertices.row(t.triangles(f, 2));
    volume += a.dot(b.cross(c)) / 6.0;
  }
  EXPECT_GT(volume, 0.04);
  EXPECT_LT(volume, 0.08);
  // UVs in the unit square, several charts.
  EXPECT_GE(t.uvs.minCoeff(), 0.0);
  EXPECT_LE(t.uvs.maxCoeff(), 1.0);
  EXPECT_GT(t.triangle_chart.maxCoeff(), 1);
}

TEST_F(MakeHumanTest, FramesAndJointsAreAnatomicallyPlaced) {
  const Template& t = ImportOnce()->tmpl;
  auto center = [&t](const char* name) { return t.joints[t.FindJoint(name)].center; };
  // Y up, feet at 0, facing +Z (toes in front of the ankles), the subject's left at +X.
  EXPECT_NEAR(center("pelvis").y(), 0.9, 0.12);
  EXPECT_NEAR(center("head").y(), 1.5, 0.1);
  EXPECT_NEAR(center("l_knee").y(), 0.48, 0.08);
  EXPECT_NEAR(center("l_ankle").y(), 0.08, 0.05);
  EXPECT_GT(center("l_shoulder").x(), 0.1);
  EXPECT_LT(center("r_shoulder").x(), -0.1);
  EXPECT_GT(center("l_elbow").x(), center("l_shoulder").x());
  EXPECT_LT(center("l_elbow").y(), center("l_shoulder").y());  // A-pose: arms down-out
  double toe_z = -1.0;
  for (int v = 0; v < t.num_vertices(); ++v) {
    if (t.vertices(v, 1) < 0.03) toe_z = std::max(toe_z, t.vertices(v, 2));
  }
  EXPECT_GT(toe_z, center("l_ankle").z() + 0.1);
  // Left/right symmetry of the joints.
  EXPECT_NEAR(center("l_wrist").x(), -center("r_wrist").x(), 1e-6);
  // Twist axes: along the bones (upper arm towards the elbow, shank downwards).
  const Eigen::Vector3d arm = (center("l_elbow") - center("l_shoulder")).normalized();
  EXPECT_GT(t.joints[t.FindJoint("l_shoulder")].twist_axis.dot(arm), 0.99);
  EXPECT_LT(t.joints[t.FindJoint("l_knee")].twist_axis.y(), -0.95);
  // Every joint but the pelvis owns vertices. The rig weights every pelvis vertex together
  // with a hip or the spine, so the conversion (largest retained pair weight) assigns those
  // vertices to the child joint with a small w_l (docs/formats-template.md).
  std::vector<int> owned(t.num_joints(), 0);
  for (int v = 0; v < t.num_vertices(); ++v) ++owned[t.vertex_joint[v]];
  for (int j = 1; j < t.num_joints(); ++j) EXPECT_GT(owned[j], 50) << t.joints[j].name;
  EXPECT_EQ(t.joints[0].name, "pelvis");
  // The hands belong to the wrists: the lowest arm vertices (fingertips) are wrist vertices.
  int fingertip = 0;
  for (int v = 0; v < t.num_vertices(); ++v) {
    if (t.vertices(v, 0) > t.vertices(fingertip, 0)) fingertip = v;
  }
  EXPECT_EQ(t.joints[t.vertex_joint[fingertip]].name, "l_wrist");
}

TEST_F(MakeHumanTest, UvsAreFlippedToTheGltfConvention) {
  const Template& t = ImportOnce()->tmpl;
  const ObjMesh obj = ReadObj(MakeHumanFolder() + "/base.obj");
  // The first body face: its first corner's UV is (u, 1 - v) of the OBJ's.
  const ObjMesh::Face* first = nullptr;
  for (const ObjMesh::Face& f : obj.faces) {
    if (f.group == "body") {
      first = &f;
      break;
    }
  }
  ASSERT_NE(first, nullptr);
  const Eigen::Vector2d obj_uv = obj.texcoords[first->texcoord[0]];
  const Eigen::Vector2d uv = t.uvs.row(t.uv_triangles(0, 0)).transpose();
  EXPECT_DOUBLE_EQ(uv.x(), obj_uv.x());
  EXPECT_DOUBLE_EQ(uv.y(), 1.0 - obj_uv.y());
}

TEST_F(MakeHumanTest, ConversionApproximationErrorAtRandomPoses) {
  const Imported& m = *ImportOnce();
  const Skinning skinning(m.tmpl);
  std::mt19937_64 rng(2024);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  for (double max_angle : {0.35, 0.7}) {
    double sum = 0.0, max_error = 0.0;
    long count = 0;
    for (int trial = 0; trial < 10; ++trial) {
      Pose pose = Pose::Identity(m.tmpl.num_joints());
      for (auto& r : pose.joint_rotations) {
        const Eigen::Vector3d axis =
            Eigen::Vector3d(uniform(rng), uniform(rng), uniform(rng)).normalized();
        r = Eigen::AngleAxisd(max_angle * uniform(rng), axis).toRotationMatrix();
      }
      Eigen::MatrixX3d artex;
      skinning.Apply(pose, &artex);
      const Eigen::VectorXd d =
          (artex - PoseLinearBlend(m.tmpl, m.weights, pose)).rowwise().norm();
      sum += d.sum();
      count += d.size();
      max_error = std::max(max_error, d.maxCoeff());
    }
    const double mean = sum / static_cast<double>(count);
    std::printf("MakeHuman LBS (merged to 17 joints) vs artex model, joint rotations up to "
                "%.0f deg: mean %.2f mm, max %.1f mm\n",
                max_angle * 180.0 / M_PI, 1e3 * mean, 1e3 * max_error);
    EXPECT_LT(mean, max_angle * 0.003);       // 1 mm at 20 deg, 2 mm at 40 deg
    EXPECT_LT(max_error, max_angle * 0.085);  // 3 cm at 20 deg, 6 cm at 40 deg
  }
}

TEST_F(MakeHumanTest, ImportedTemplateRoundTripsThroughGlb) {
  const Template& t = ImportOnce()->tmpl;
  const std::string path =
      (fs::temp_directory_path() / ("artex_mh_" + std::to_string(::getpid()) + ".glb")).string();
  WriteTemplateGlb(path, t);
  const Template back = ReadTemplateGlb(path);
  fs::remove(path);
  EXPECT_EQ(back.num_vertices(), t.num_vertices());
  EXPECT_TRUE((back.triangles.array() == t.triangles.array()).all());
  EXPECT_TRUE((back.uv_triangles.array() == t.uv_triangles.array()).all());
  EXPECT_TRUE((back.vertex_joint.array() == t.vertex_joint.array()).all());
  EXPECT_LT((back.vertices - t.vertices).cwiseAbs().maxCoeff(), 1e-6);
}

// A folder of test_data::MakeSmallMakeHuman's files, one of them replaced.
class SmallMakeHumanTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("artex_small_mh_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
    files_ = test_data::MakeSmallMakeHuman();
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Folder() {
    const MakeHumanImportOptions o;
    std::ofstream(dir_ / o.obj_file) << files_.obj;
    std::ofstream(dir_ / o.rig_file) << files_.rig;
    std::ofstream(dir_ / o.weights_file) << files_.weights;
    return dir_.string();
  }
  // Imports with `rig` in place of the rig file's text `from`; expects an artex::Error naming
  // the rig file and `fragment`.
  void ExpectRigError(const std::string& from, const std::string& to, const std::string& fragment,
                      RigPositionSource source = RigPositionSource::kJointCubes) {
    const std::string rig = files_.rig;
    const size_t at = files_.rig.find(from);
    ASSERT_NE(at, std::string::npos) << from;
    files_.rig.replace(at, from.size(), to);
    MakeHumanImportOptions options;
    options.joint_positions = source;
    try {
      ImportMakeHuman(Folder(), options);
      ADD_FAILURE() << "accepted: " << to;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("mpfb_rig.cmu_mb.json: "), std::string::npos)
          << e.what();
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
    files_.rig = rig;
  }
  fs::path dir_;
  test_data::SmallMakeHuman files_;
};

TEST_F(SmallMakeHumanTest, ImportsAValidTemplate) {
  MakeHumanImportReport report;
  const Template tmpl = ImportMakeHuman(Folder(), MakeHumanImportOptions(), nullptr, &report);
  std::string why;
  EXPECT_TRUE(tmpl.IsValid(&why)) << why;
  EXPECT_EQ(tmpl.num_vertices(), 8);
  EXPECT_EQ(tmpl.num_joints(), 17);
  EXPECT_EQ(report.boundary_edges, 0);
  // The hips' centre is its joint cube's vertex mean (y = 9.0333 decimetres above the box's
  // floor), not the rig's default position (0.9 m).
  EXPECT_NEAR(tmpl.joints[0].center.y(), 0.90333333, 1e-6);
}

// Fields of the wrong JSON type (found by the makehuman fuzzer's kind of input) are errors
// naming the file and field, not nlohmann::json exceptions.
TEST_F(SmallMakeHumanTest, RigFieldsOfTheWrongTypeNameTheFileAndField) {
  ExpectRigError("\"parent\": \"Hips\"", "\"parent\": 5", "parent: expected text");
  ExpectRigError("\"strategy\": \"CUBE\"", "\"strategy\": [1]", "Hips.head.strategy");
  ExpectRigError("\"cube_name\": \"joint-hips\"", "\"cube_name\": {}",
                 "Hips.head.cube_name: expected text");
  ExpectRigError("\"vertex_indices\": [2, 7]", "\"vertex_indices\": 2",
                 "Neck.head.vertex_indices: expected a list");
  ExpectRigError("\"vertex_indices\": [2, 7]", "\"vertex_indices\": [2, \"7\"]",
                 "Neck.head: expected a vertex index, found \"7\"");
  ExpectRigError("\"vertex_indices\": [2, 7]", "\"vertex_indices\": [2, 1e300]",
                 "expected a vertex index");
  ExpectRigError("\"vertex_indices\": [2, 7]", "\"vertex_indices\": [2, -1]",
                 "expected a vertex index, found -1");
  ExpectRigError("\"vertex_indices\": [2, 7]", "\"vertex_indices\": [2, 99]",
                 "vertex index 99 outside");
}

TEST_F(MakeHumanTest, ReportsMissingAndBrokenFiles) {
  EXPECT_THROW(ImportMakeHuman(MakeHumanFolder() + "/no_such_folder"), Error);
  const fs::path dir = fs::temp_directory_path() / ("artex_mh_bad_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  fs::create_symlink(MakeHumanFolder() + "/base.obj", dir / "base.obj");
  fs::create_symlink(MakeHumanFolder() + "/mpfb_rig.cmu_mb.json", dir / "mpfb_rig.cmu_mb.json");
  std::ofstream(dir / "mpfb_weights.cmu_mb.json") << "{\"weights\": {\"Hips\": [[0, 1.0]],";
  try {
    ImportMakeHuman(dir.string());
    ADD_FAILURE() << "broken weights accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("mpfb_weights.cmu_mb.json"), std::string::npos)
        << e.what();
  }
  MakeHumanImportOptions options;
  options.bone_of_joint["head"] = "NoSuchBone";
  try {
    ImportMakeHuman(MakeHumanFolder(), options);
    ADD_FAILURE() << "unknown bone accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("NoSuchBone"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace artex
