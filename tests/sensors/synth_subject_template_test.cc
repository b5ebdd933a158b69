// The virtual Kinect's subject read from a template file (SynthOptions::subject_template,
// `artex synth --subject-template`): bad files, a file of the generated body, and the
// MakeHuman CC0 base mesh (needs ../shared/data/makehuman; skipped when absent).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "models/error.h"
#include "models/makehuman_import.h"
#include "models/skinning.h"
#include "models/template_generator.h"
#include "models/template_io.h"
#include "sensors/sequence.h"
#include "sensors/virtual_kinect.h"
#include "tests/sensors/small_synth.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

fs::path TempDir(const std::string& name) {
  return testing_util::FreshTempDir("subject_tmpl_" + name);
}

SynthOptions SmallOptions() { return testing_util::SmallSynthOptions(3, 0); }

// The message of the artex::Error thrown by PrepareSynthSubject with subject_template = path.
std::string PrepareError(const std::string& path) {
  SynthOptions o = SmallOptions();
  o.subject_template = path;
  try {
    PrepareSynthSubject(o);
  } catch (const Error& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(SubjectTemplateTest, BadTemplateFilesFailNamingTheFileAndTheProblem) {
  const fs::path dir = TempDir("bad");
  const std::string missing = (dir / "missing.glb").string();
  std::string e = PrepareError(missing);
  EXPECT_NE(e.find("subject template '" + missing + "'"), std::string::npos) << e;

  const std::string garbage = (dir / "garbage.glb").string();
  std::ofstream(garbage) << "not a glb file";
  e = PrepareError(garbage);
  EXPECT_NE(e.find("subject template '" + garbage + "'"), std::string::npos) << e;

  BodyShapeOptions shape;
  shape.resolution = 0;
  Template no_uvs = GenerateTemplate(shape);
  no_uvs.uvs.resize(0, 2);
  no_uvs.uv_triangles.resize(0, 3);
  no_uvs.triangle_chart.resize(0);
  const std::string no_uvs_path = (dir / "no_uvs.glb").string();
  WriteTemplateGlb(no_uvs_path, no_uvs);
  e = PrepareError(no_uvs_path);
  EXPECT_NE(e.find("subject template '" + no_uvs_path + "'"), std::string::npos) << e;
  EXPECT_NE(e.find("expected a UV atlas"), std::string::npos) << e;

  Template renamed = GenerateTemplate(shape);
  renamed.joints[renamed.FindJoint("l_knee")].name = "LeftLeg";
  const std::string renamed_path = (dir / "renamed.glb").string();
  WriteTemplateGlb(renamed_path, renamed);
  e = PrepareError(renamed_path);
  EXPECT_NE(e.find("subject template '" + renamed_path + "'"), std::string::npos) << e;
  EXPECT_NE(e.find("missing l_knee; found"), std::string::npos) << e;
  EXPECT_NE(e.find("LeftLeg"), std::string::npos) << e;
  fs::remove_all(dir);
}

TEST(SubjectTemplateTest, AFileOfTheGeneratedBodyGivesTheGeneratedSubject) {
  const fs::path dir = TempDir("generated");
  const SynthOptions o = SmallOptions();
  const SynthSubject generated = PrepareSynthSubject(o);
  SynthOptions from_file = o;
  from_file.subject_template = (dir / "subject.glb").string();
  WriteTemplateGlb(from_file.subject_template, generated.subject);
  const SynthSubject loaded = PrepareSynthSubject(from_file);
  ASSERT_EQ(loaded.subject.num_vertices(), generated.subject.num_vertices());
  ASSERT_EQ(loaded.poses.size(), generated.poses.size());
  // The GLB stores single-precision positions.
  EXPECT_LT((loaded.subject.vertices - generated.subject.vertices).cwiseAbs().maxCoeff(), 1e-6);
  for (size_t f = 0; f < generated.poses.size(); ++f) {
    EXPECT_LT((loaded.poses[f].translation - generated.poses[f].translation).norm(), 1e-5);
  }
  ASSERT_EQ(loaded.texture_bgr.size(), generated.texture_bgr.size());
  EXPECT_LT(cv::norm(loaded.texture_bgr, generated.texture_bgr, cv::NORM_L1) /
                (loaded.texture_bgr.total() * 3.0),
            0.5);
  fs::remove_all(dir);
}

// ---------------------------------------------------------------------------------------------
// The MakeHuman body as the subject.

std::string MakeHumanFolder() { return std::string(ARTEX_SHARED_DATA) + "/makehuman"; }

TEST(SubjectTemplateTest, MakeHumanSubjectGroundTruthLiesOnTheRenderedSubject) {
  if (!fs::exists(MakeHumanFolder() + "/base.obj")) {
    GTEST_SKIP() << "MakeHuman data not found in " << MakeHumanFolder();
  }
  const fs::path dir = TempDir("makehuman");
  const Template body = ImportMakeHuman(MakeHumanFolder());
  const std::string glb = (dir / "makehuman.glb").string();
  WriteTemplateGlb(glb, body);
  SynthOptions o = SmallOptions();
  o.subject_template = glb;
  o.kinect.SetNoiseLevel(NoiseLevel::kOff);
  const fs::path seq = dir / "seq";
  SynthesizeSequence(o, seq.string());

  SequenceReader reader(seq.string());
  ASSERT_TRUE(reader.has_ground_truth());
  ASSERT_EQ(reader.num_frames(), 3);
  const Template subject = ReadTemplateGlb(reader.GroundTruthSubjectPath());
  ASSERT_EQ(subject.num_vertices(), body.num_vertices());
  EXPECT_NE(reader.GroundTruthTexturePath(), "");
  const Skinning skinning(subject);
  const PinholeCamera& camera = reader.calibration().depth;
  for (int f = 0; f < reader.num_frames(); ++f) {
    const GroundTruthFrame truth = reader.ReadGroundTruth(f);
    ASSERT_EQ(truth.vertices.rows(), body.num_vertices());
    Eigen::MatrixX3d posed;
    skinning.Apply(truth.pose, &posed);
    EXPECT_LT((posed - truth.vertices).cwiseAbs().maxCoeff(), 1e-4) << "frame " << f;
    // The walk keeps this body's feet on the floor (y = 0 in the scene frame).
    EXPECT_NEAR(truth.vertices.col(1).minCoeff(), 0.0, 0.02) << "frame " << f;
    Frame frame;
    std::string warning;
    ASSERT_TRUE(reader.ReadFrame(f, &frame, &warning)) << warning;
    // Every vertex projects onto the rendered subject: the depth there is its own (visible:
    // within 1 cm) or nearer (the body's own front hides it), never farther or missing (a
    // pixel's neighbours count: along the silhouette the vertex's own pixel may miss it).
    int visible = 0, behind_or_missing = 0;
    for (int v = 0; v < truth.vertices.rows(); ++v) {
      double z = 0.0;
      const Eigen::Vector2d px = camera.Project(truth.vertices.row(v).transpose(), &z);
      const int u = static_cast<int>(std::lround(px.x())), w = static_cast<int>(std::lround(px.y()));
      ASSERT_TRUE(u >= 0 && w >= 0 && u < frame.depth.cols && w < frame.depth.rows)
          << "vertex " << v << " outside the image at frame " << f;
      const double scale = reader.calibration().depth_scale;
      const double d = frame.depth.at<uint16_t>(w, u) / scale;
      // Nearest depth of the 3 x 3 pixels around (a finger is 2-3 pixels wide).
      double nearest = 0.0;
      for (int y = std::max(0, w - 1); y <= std::min(frame.depth.rows - 1, w + 1); ++y) {
        for (int x = std::max(0, u - 1); x <= std::min(frame.depth.cols - 1, u + 1); ++x) {
          const double e = frame.depth.at<uint16_t>(y, x) / scale;
          if (e > 0.0 && (nearest == 0.0 || e < nearest)) nearest = e;
        }
      }
      if (nearest == 0.0 || nearest > z + 0.03) {
        ++behind_or_missing;
      } else if (std::abs(d - z) < 0.01) {
        ++visible;
      }
    }
    const double n = static_cast<double>(truth.vertices.rows());
    std::printf("frame %d: %.4f of the vertices visible, %.4f off the subject\n", f, visible / n,
                behind_or_missing / n);
    EXPECT_LT(behind_or_missing / n, 0.02) << "frame " << f;
    EXPECT_GT(visible / n, 0.3) << "frame " << f;
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace artex
