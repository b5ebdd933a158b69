// Runs the built `artex` binary (ARTEX_BINARY): artex template make | info | pose | animate |
// import-gltf | import-makehuman, and its error handling (non-zero exit, message names the file).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "models/error.h"
#include "models/template_io.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
using testing_util::ReadFileBytes;

using Result = testing_util::CommandResult;

class TemplateCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(testing_util::FreshTempDir("template_cli_test"));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
    delete make_result_;
    dir_ = nullptr;
    make_result_ = nullptr;
  }
  void SetUp() override {
    ASSERT_TRUE(fs::exists(ARTEX_BINARY)) << "build the artex target first: " << ARTEX_BINARY;
  }

  static std::string Path(const std::string& name) { return (*dir_ / name).string(); }

  static Result Run(const std::string& args) { return testing_util::RunArtex(args, *dir_); }

  // The coarse template, made on first use (once per test process).
  static std::string Template() {
    if (make_result_ == nullptr) {
      make_result_ = new Result(Run("template make --resolution 0 --height 1.7 -o '" +
                                    Path("coarse.glb") + "'"));
    }
    EXPECT_EQ(make_result_->status, 0) << make_result_->err;
    return Path("coarse.glb");
  }

  static fs::path* dir_;
  static Result* make_result_;
};

fs::path* TemplateCliTest::dir_ = nullptr;
Result* TemplateCliTest::make_result_ = nullptr;

TEST_F(TemplateCliTest, MakeWritesAValidTemplate) {
  const std::string path = Template();
  ASSERT_TRUE(fs::exists(path));
  ASSERT_NE(make_result_, nullptr);
  EXPECT_NE(make_result_->out.find("17 joints"), std::string::npos) << make_result_->out;
  const artex::Template tmpl = ReadTemplateGlb(path);
  EXPECT_EQ(tmpl.num_joints(), 17);
  EXPECT_NEAR(tmpl.vertices.col(1).maxCoeff() - tmpl.vertices.col(1).minCoeff(), 1.7, 0.05);
}

TEST_F(TemplateCliTest, InfoPrintsJointsUvsAndTopology) {
  const Result r = Run("template info '" + Template() + "'");
  ASSERT_EQ(r.status, 0) << r.err;
  for (const std::string expected :
       {"vertices: ", "triangles: ", "joints: 17", "pelvis", "l_ankle", "parent (root)",
        "pose parameters: 58", "uv atlas:", "coverage", "manifold: closed", "texture: none"}) {
    EXPECT_NE(r.out.find(expected), std::string::npos) << "missing '" << expected << "' in\n"
                                                       << r.out;
  }
}

TEST_F(TemplateCliTest, PoseWritesPlyObjAndGlb) {
  const std::string tmpl = Template();
  Result r = Run("template pose '" + tmpl + "' --joint l_elbow=0,0,60 --joint r_knee=45,0,0 "
                 "--color-joints -o '" + Path("posed.ply") + "'");
  ASSERT_EQ(r.status, 0) << r.err;
  const std::string ply = ReadFileBytes(Path("posed.ply"));
  EXPECT_EQ(ply.rfind("ply", 0), 0u);
  EXPECT_NE(ply.find("property uchar red"), std::string::npos);
  r = Run("template pose '" + tmpl + "' --joint head=0,30,0 -o '" + Path("posed.obj") + "'");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(ReadFileBytes(Path("posed.obj")).find("\nf "), std::string::npos);
  // A full pose vector: 58 numbers; global translation of 1 m along x moves every vertex.
  std::string vector = "1 1 0 0 0 0 0";
  for (int i = 0; i < 51; ++i) vector += " 0";
  r = Run("template pose '" + tmpl + "' --pose '" + vector + "' -o '" + Path("moved.glb") + "'");
  ASSERT_EQ(r.status, 0) << r.err;
  const artex::Template rest = ReadTemplateGlb(tmpl);
  const artex::Template moved = ReadTemplateGlb(Path("moved.glb"));
  ASSERT_EQ(moved.num_vertices(), rest.num_vertices());
  EXPECT_NEAR((moved.vertices.col(0) - rest.vertices.col(0)).mean(), 1.0, 1e-5);
  EXPECT_NEAR((moved.joints[0].center - rest.joints[0].center).x(), 1.0, 1e-9);
}

TEST_F(TemplateCliTest, PoseFileAndAnimate) {
  const std::string tmpl = Template();
  std::ofstream csv(Path("poses.csv"));
  csv << "frame,s,tx,ty,tz,r0x,r0y,r0z";
  for (int j = 1; j <= 17; ++j) csv << ",r" << j << "x,r" << j << "y,r" << j << "z";
  csv << "\n";
  for (int f = 0; f < 5; ++f) {
    csv << f << ",1,0,0,0,0," << 0.2 * f << ",0";
    for (int k = 0; k < 51; ++k) csv << "," << (k == 3 * 6 + 2 ? 0.3 * f : 0.0);
    csv << "\n";
  }
  csv.close();
  Result r = Run("template pose '" + tmpl + "' --pose-file '" + Path("poses.csv") +
                 "' --frame 4 -o '" + Path("frame4.ply") + "'");
  ASSERT_EQ(r.status, 0) << r.err;
  r = Run("template animate '" + tmpl + "' --pose-file '" + Path("poses.csv") + "' --fps 10 -o '" +
          Path("anim.glb") + "'");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("5 frames"), std::string::npos) << r.out;
  EXPECT_EQ(ReadTemplateGlb(Path("anim.glb")).num_vertices(), ReadTemplateGlb(tmpl).num_vertices());
  r = Run("template pose '" + tmpl + "' --pose-file '" + Path("poses.csv") + "' --frame 9 -o '" +
          Path("frame9.ply") + "'");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.err.find("poses.csv"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(Path("frame9.ply")));
}

TEST_F(TemplateCliTest, ImportGltfOfATemplate) {
  const Result r = Run("template import-gltf '" + Template() + "' -o '" + Path("imported.glb") + "'");
  ASSERT_EQ(r.status, 0) << r.err;
  const artex::Template imported = ReadTemplateGlb(Path("imported.glb"));
  EXPECT_EQ(imported.num_joints(), 18);  // + the global-similarity node as root joint
}

TEST_F(TemplateCliTest, ErrorsExitNonZeroAndNameTheFile) {
  const std::string missing = Path("missing.glb");
  Result r = Run("template info '" + missing + "'");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.err.find(missing), std::string::npos) << r.err;

  const std::string garbage = Path("garbage.glb");
  std::ofstream(garbage) << "this is not a glTF file";
  r = Run("template info '" + garbage + "'");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.err.find(garbage), std::string::npos) << r.err;

  const std::string truncated = Path("truncated.glb");
  const std::string bytes = ReadFileBytes(Template());
  std::ofstream(truncated, std::ios::binary) << bytes.substr(0, bytes.size() / 3);
  r = Run("template pose '" + truncated + "' -o '" + Path("never.ply") + "'");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.err.find(truncated), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("truncated"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(Path("never.ply")));

  r = Run("template pose '" + Template() + "' --pose '1 2 3' -o '" + Path("never.ply") + "'");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.err.find("58"), std::string::npos) << r.err;
  r = Run("template pose '" + Template() + "' --joint nose=1,2,3 -o '" + Path("never.ply") + "'");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.err.find("nose"), std::string::npos) << r.err;
  r = Run("template make -o '" + Path("template.stl") + "'");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.err.find("template.stl"), std::string::npos) << r.err;
  r = Run("template make --height 5 -o '" + Path("tall.glb") + "'");
  EXPECT_NE(r.status, 0);
  EXPECT_FALSE(fs::exists(Path("tall.glb")));
  r = Run("template import-makehuman '" + Path("no_such_folder") + "' -o '" + Path("mh.glb") + "'");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.err.find("no_such_folder"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(Path("never.ply")));
}

TEST_F(TemplateCliTest, ImportMakeHuman) {
  const std::string folder = std::string(ARTEX_SHARED_DATA) + "/makehuman";
  if (!fs::exists(folder + "/base.obj")) GTEST_SKIP() << "MakeHuman data not found in " << folder;
  Result r = Run("template import-makehuman '" + folder + "' -o '" + Path("mh.glb") + "'");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("13380 vertices"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("0 boundary edges"), std::string::npos) << r.out;
  r = Run("template info '" + Path("mh.glb") + "'");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("manifold: closed"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace artex
