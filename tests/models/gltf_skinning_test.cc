// Exact animated glb export (issue 17): a glTF viewer's skinning of tracked.glb against artex's
// LBS+SLERP skinning. The glb is evaluated here independently of artex's writer, as a viewer
// does (glTF 2.0 sec. 3.7.3 skinning, 3.7.2.2 morph targets): node TRS from the animation
// at each keyframe, world matrices through the hierarchy, joint matrices times inverse bind
// matrices, morph targets applied before skinning.
#include "models/gltf_skinning.h"

#include <gtest/gtest.h>
#include <tiny_gltf.h>

#include <Eigen/Geometry>
#include <cstdio>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include "models/error.h"
#include "models/skinning.h"
#include "models/template_generator.h"
#include "models/template_io.h"
#include "sensors/motion.h"

namespace artex {
namespace {

// Accessor contents as floats (count x components), as a glTF viewer reads them: the view's
// data (zeros without one), then a sparse accessor's values at its indices (artex writes the
// morph weights sparse: one 1 per keyframe).
std::vector<float> Floats(const tinygltf::Model& m, int index) {
  const tinygltf::Accessor& a = m.accessors[index];
  const int components = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(a.type));
  std::vector<float> out(a.count * components, 0.0f);
  EXPECT_EQ(a.componentType, TINYGLTF_COMPONENT_TYPE_FLOAT);
  if (a.bufferView >= 0) {
    const tinygltf::BufferView& view = m.bufferViews[a.bufferView];
    const unsigned char* src =
        m.buffers[view.buffer].data.data() + view.byteOffset + a.byteOffset;
    const size_t stride = view.byteStride ? view.byteStride : components * sizeof(float);
    for (size_t i = 0; i < a.count; ++i)
      std::memcpy(&out[i * components], src + i * stride, components * sizeof(float));
  }
  if (a.sparse.isSparse) {
    EXPECT_EQ(a.sparse.indices.componentType, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT);
    const tinygltf::BufferView& iv = m.bufferViews[a.sparse.indices.bufferView];
    const tinygltf::BufferView& vv = m.bufferViews[a.sparse.values.bufferView];
    const unsigned char* indices =
        m.buffers[iv.buffer].data.data() + iv.byteOffset + a.sparse.indices.byteOffset;
    const unsigned char* values =
        m.buffers[vv.buffer].data.data() + vv.byteOffset + a.sparse.values.byteOffset;
    for (int k = 0; k < a.sparse.count; ++k) {
      uint32_t i = 0;
      std::memcpy(&i, indices + 4 * k, 4);
      EXPECT_LT(i, a.count);
      if (i >= a.count) continue;
      std::memcpy(&out[i * components], values + k * components * sizeof(float),
                  components * sizeof(float));
    }
  }
  return out;
}

std::vector<int> UnsignedShorts(const tinygltf::Model& m, int index) {
  const tinygltf::Accessor& a = m.accessors[index];
  const tinygltf::BufferView& view = m.bufferViews[a.bufferView];
  const int components = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(a.type));
  const auto* src = reinterpret_cast<const uint16_t*>(m.buffers[view.buffer].data.data() +
                                                      view.byteOffset + a.byteOffset);
  return std::vector<int>(src, src + a.count * components);
}

// A viewer's skinned positions (glTF vertices x 3) at keyframe `key` of animation 0.
Eigen::MatrixX3d ViewerPositions(const tinygltf::Model& m, int key) {
  const int num_nodes = static_cast<int>(m.nodes.size());
  std::vector<Eigen::Vector3d> t(num_nodes), s(num_nodes);
  std::vector<Eigen::Quaterniond> r(num_nodes);
  for (int n = 0; n < num_nodes; ++n) {
    const auto& node = m.nodes[n];
    t[n] = node.translation.size() == 3
               ? Eigen::Vector3d(node.translation[0], node.translation[1], node.translation[2])
               : Eigen::Vector3d::Zero();
    s[n] = node.scale.size() == 3 ? Eigen::Vector3d(node.scale[0], node.scale[1], node.scale[2])
                                  : Eigen::Vector3d::Ones();
    r[n] = node.rotation.size() == 4 ? Eigen::Quaterniond(node.rotation[3], node.rotation[0],
                                                          node.rotation[1], node.rotation[2])
                                     : Eigen::Quaterniond::Identity();
  }
  const tinygltf::Mesh& mesh = m.meshes[0];
  std::vector<double> morph = mesh.weights;
  const tinygltf::Animation& anim = m.animations[0];
  for (const auto& channel : anim.channels) {
    const auto& sampler = anim.samplers[channel.sampler];
    const std::vector<float> out = Floats(m, sampler.output);
    const int n = channel.target_node;
    if (channel.target_path == "translation") {
      t[n] = Eigen::Vector3d(out[3 * key], out[3 * key + 1], out[3 * key + 2]);
    } else if (channel.target_path == "scale") {
      s[n] = Eigen::Vector3d(out[3 * key], out[3 * key + 1], out[3 * key + 2]);
    } else if (channel.target_path == "rotation") {
      r[n] = Eigen::Quaterniond(out[4 * key + 3], out[4 * key], out[4 * key + 1], out[4 * key + 2])
                 .normalized();
    } else if (channel.target_path == "weights") {
      for (size_t i = 0; i < morph.size(); ++i) morph[i] = out[key * morph.size() + i];
    }
  }
  std::vector<int> parent(num_nodes, -1);
  for (int n = 0; n < num_nodes; ++n) {
    for (int c : m.nodes[n].children) parent[c] = n;
  }
  std::vector<Eigen::Matrix4d> world(num_nodes);
  std::vector<char> done(num_nodes, 0);
  std::function<const Eigen::Matrix4d&(int)> world_of = [&](int n) -> const Eigen::Matrix4d& {
    if (!done[n]) {
      Eigen::Matrix4d local = Eigen::Matrix4d::Identity();
      local.topLeftCorner<3, 3>() = r[n].toRotationMatrix() * s[n].asDiagonal();
      local.topRightCorner<3, 1>() = t[n];
      world[n] = parent[n] >= 0 ? Eigen::Matrix4d(world_of(parent[n]) * local) : local;
      done[n] = 1;
    }
    return world[n];
  };
  const tinygltf::Skin& skin = m.skins[0];
  const std::vector<float> ibm = Floats(m, skin.inverseBindMatrices);
  std::vector<Eigen::Matrix4d> joint_matrix(skin.joints.size());
  for (size_t j = 0; j < skin.joints.size(); ++j) {
    joint_matrix[j] =
        world_of(skin.joints[j]) * Eigen::Map<const Eigen::Matrix4f>(&ibm[16 * j]).cast<double>();
  }
  const tinygltf::Primitive& prim = mesh.primitives[0];
  const std::vector<float> pos = Floats(m, prim.attributes.at("POSITION"));
  const std::vector<int> joints = UnsignedShorts(m, prim.attributes.at("JOINTS_0"));
  const std::vector<float> weights = Floats(m, prim.attributes.at("WEIGHTS_0"));
  const size_t count = pos.size() / 3;
  std::vector<double> p(pos.begin(), pos.end());
  for (size_t target = 0; target < prim.targets.size(); ++target) {
    if (morph[target] == 0.0) continue;
    const std::vector<float> d = Floats(m, prim.targets[target].at("POSITION"));
    for (size_t i = 0; i < p.size(); ++i) p[i] += morph[target] * d[i];
  }
  Eigen::MatrixX3d result(count, 3);
  for (size_t v = 0; v < count; ++v) {
    Eigen::Matrix4d skin_matrix = Eigen::Matrix4d::Zero();
    for (int i = 0; i < 4; ++i) skin_matrix += weights[4 * v + i] * joint_matrix[joints[4 * v + i]];
    result.row(v) = (skin_matrix * Eigen::Vector4d(p[3 * v], p[3 * v + 1], p[3 * v + 2], 1.0))
                        .head<3>()
                        .transpose();
  }
  return result;
}

struct Residual {
  double max_mm = 0.0;
  double mean_mm = 0.0;
};

// Viewer positions of every keyframe against Skinning::Apply of the same pose.
Residual ViewerResidual(const std::string& glb, const Template& tmpl,
                        const std::vector<Pose>& poses) {
  tinygltf::Model model;
  tinygltf::TinyGLTF loader;
  std::string err, warn;
  EXPECT_TRUE(loader.LoadBinaryFromMemory(&model, &err, &warn,
                                          reinterpret_cast<const unsigned char*>(glb.data()),
                                          static_cast<unsigned int>(glb.size())))
      << err;
  const std::vector<float> ids =
      Floats(model, model.meshes[0].primitives[0].attributes.at("_ARTEX_VERTEX"));
  const Skinning skinning(tmpl);
  Residual r;
  double sum = 0.0;
  long long n = 0;
  for (size_t f = 0; f < poses.size(); ++f) {
    Eigen::MatrixX3d expected;
    skinning.Apply(poses[f], &expected);
    const Eigen::MatrixX3d viewer = ViewerPositions(model, static_cast<int>(f));
    for (Eigen::Index v = 0; v < viewer.rows(); ++v) {
      const double e = 1e3 * (viewer.row(v) - expected.row(static_cast<int>(ids[v]))).norm();
      r.max_mm = std::max(r.max_mm, e);
      sum += e;
      ++n;
    }
  }
  r.mean_mm = sum / static_cast<double>(n);
  return r;
}

class ExactGlbTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    tmpl_ = new Template(GenerateTemplate());  // the default tracking template
    MotionOptions motion;                      // walk, 60 frames at 30 Hz
    poses_ = new std::vector<Pose>(GenerateMotion(*tmpl_, motion));
  }
  static void TearDownTestSuite() {
    delete tmpl_;
    delete poses_;
  }
  static Template* tmpl_;
  static std::vector<Pose>* poses_;
};
Template* ExactGlbTest::tmpl_ = nullptr;
std::vector<Pose>* ExactGlbTest::poses_ = nullptr;

TEST_F(ExactGlbTest, ViewerReproducesArtexSkinningOnA60FrameWalk) {
  ASSERT_EQ(poses_->size(), 60u);
  AnimatedGlbOptions exact;
  AnimatedGlbSummary summary;
  const std::string glb = EncodeAnimatedGlb(*tmpl_, *poses_, 30.0, nullptr, exact, &summary);
  EXPECT_EQ(summary.morph_targets, 60);
  EXPECT_EQ(summary.singular_vertices, 0);
  const Residual r = ViewerResidual(glb, *tmpl_, *poses_);
  std::printf(
      "exact glb: viewer residual max %.4f mm, mean %.5f mm (writer's estimate max %.4f mm); "
      "plain LBS max %.2f mm, mean %.3f mm; %zu bytes\n",
      r.max_mm, r.mean_mm, summary.exact_max_residual_mm, summary.lbs_max_residual_mm,
      summary.lbs_mean_residual_mm, glb.size());
  EXPECT_LE(r.max_mm, 0.5);
  EXPECT_LE(summary.exact_max_residual_mm, 0.5);
  EXPECT_GT(summary.lbs_max_residual_mm, 2.0);  // what the correctives remove (5.1 mm)
}

TEST_F(ExactGlbTest, PlainLbsExportDiffersAndMatchesTheWritersModel) {
  AnimatedGlbOptions plain;
  plain.exact = false;
  AnimatedGlbSummary summary;
  const std::vector<Pose>& poses = *poses_;
  const std::string glb = EncodeAnimatedGlb(*tmpl_, poses, 30.0, nullptr, plain, &summary);
  EXPECT_EQ(summary.morph_targets, 0);
  const Residual r = ViewerResidual(glb, *tmpl_, poses);
  std::printf("plain glb: viewer residual max %.2f mm, mean %.3f mm; %zu bytes\n", r.max_mm,
              r.mean_mm, glb.size());
  // The viewer's plain LBS is what GltfSkinnedPositions models (to float storage).
  EXPECT_NEAR(r.max_mm, summary.lbs_max_residual_mm, 0.05);
  EXPECT_GT(r.max_mm, 2.0);
}

TEST_F(ExactGlbTest, CorrectivesInvertTheGltfSkinning) {
  const Pose& pose = (*poses_)[40];
  Eigen::MatrixX3d target, offsets, back;
  Skinning(*tmpl_).Apply(pose, &target);
  GltfCorrectiveOptions options;
  GltfCorrectiveStats stats;
  GltfCorrectiveOffsets(*tmpl_, pose, target, options, &offsets, &stats);
  GltfSkinnedPositions(*tmpl_, pose, &offsets, &back);
  EXPECT_LT((back - target).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_GT(stats.max_offset, 0.001);
  // At the rest pose both skinnings agree: no correction.
  GltfCorrectiveOffsets(*tmpl_, Pose::Identity(tmpl_->num_joints()), tmpl_->vertices, options,
                        &offsets, &stats);
  EXPECT_LT(offsets.cwiseAbs().maxCoeff(), 1e-12);
  options.min_relative_determinant = -1.0;
  EXPECT_THROW(GltfCorrectiveOffsets(*tmpl_, pose, target, options, &offsets), Error);
}

}  // namespace
}  // namespace artex
