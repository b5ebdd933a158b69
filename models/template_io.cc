// Template writing (models/template_io.h): the glTF model, the glb encoders and the writers.
#include "models/template_io.h"

#include <tbb/parallel_for.h>
#include <tiny_gltf.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <ostream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "models/error.h"
#include "models/gltf_skinning.h"
#include "models/mesh_export.h"
#include "models/normals.h"
#include "models/skinning.h"
#include "models/template_io_internal.h"

// PNG encoding of RGB8 textures: stb_image_write compiled privately into this file.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wsign-compare"
#define STB_IMAGE_WRITE_STATIC
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb/stb_image_write.h>
#pragma GCC diagnostic pop

namespace artex {

using template_io_internal::Fail;
using template_io_internal::kJointAttribute;
using template_io_internal::kLbsAttribute;
using template_io_internal::kTauAttribute;
using template_io_internal::kUvAttribute;
using template_io_internal::kVertexAttribute;
using template_io_internal::LooksLikePng;
using template_io_internal::ReadU32;

namespace {

// The version of the format written (mesh extras; docs/formats-template.md).
constexpr int kFormatVersion = 1;

tinygltf::Value NumberArray(const Eigen::Vector3d& v) {
  return tinygltf::Value(tinygltf::Value::Array{tinygltf::Value(v.x()), tinygltf::Value(v.y()),
                                                tinygltf::Value(v.z())});
}

class GltfBuilder {
 public:
  explicit GltfBuilder(tinygltf::Model* model) : model_(model) { model_->buffers.resize(1); }

  int AddBufferView(const void* data, size_t bytes, int target) {
    if (external_bytes_ > 0) throw Error("glTF builder: a buffer view after the external ones");
    std::vector<unsigned char>& buffer = model_->buffers[0].data;
    while (buffer.size() % 4 != 0) buffer.push_back(0);
    tinygltf::BufferView view;
    view.buffer = 0;
    view.byteOffset = buffer.size();
    view.byteLength = bytes;
    view.target = target;
    const auto* p = static_cast<const unsigned char*>(data);
    buffer.insert(buffer.end(), p, p + bytes);
    model_->bufferViews.push_back(view);
    return static_cast<int>(model_->bufferViews.size()) - 1;
  }

  // `values` holds count x components floats; type is a TINYGLTF_TYPE_*.
  int AddFloats(const std::vector<float>& values, int type, int target, bool min_max) {
    const int components = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(type));
    tinygltf::Accessor accessor;
    accessor.bufferView = AddBufferView(values.data(), values.size() * sizeof(float), target);
    accessor.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
    accessor.type = type;
    accessor.count = values.size() / static_cast<size_t>(components);
    if (min_max && accessor.count > 0) {
      accessor.minValues.assign(components, std::numeric_limits<double>::infinity());
      accessor.maxValues.assign(components, -std::numeric_limits<double>::infinity());
      for (size_t i = 0; i < values.size(); ++i) {
        const size_t c = i % static_cast<size_t>(components);
        accessor.minValues[c] = std::min<double>(accessor.minValues[c], values[i]);
        accessor.maxValues[c] = std::max<double>(accessor.maxValues[c], values[i]);
      }
    }
    return Push(accessor);
  }

  // A view of `bytes` (a multiple of 4) whose data the writer appends after the buffer's own
  // (WriteAnimatedGlbTo): its offset counts from the buffer's end rounded up to 4. Every
  // AddBufferView must come before the first external view.
  int AddExternalView(size_t bytes, int target) {
    const size_t base = (model_->buffers[0].data.size() + 3) / 4 * 4;
    tinygltf::BufferView view;
    view.buffer = 0;
    view.byteOffset = base + external_bytes_;
    view.byteLength = bytes;
    view.target = target;
    external_bytes_ += bytes;
    model_->bufferViews.push_back(view);
    return static_cast<int>(model_->bufferViews.size()) - 1;
  }
  size_t external_bytes() const { return external_bytes_; }

  // `count` scalar floats, all 0 but `ones`[i] (ascending), which are 1: a sparse accessor
  // (no data of its own; indices and values in two small views).
  int AddSparseOnes(size_t count, const std::vector<uint32_t>& ones) {
    tinygltf::Accessor accessor;
    accessor.bufferView = -1;
    accessor.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
    accessor.type = TINYGLTF_TYPE_SCALAR;
    accessor.count = count;
    accessor.sparse.isSparse = true;
    accessor.sparse.count = static_cast<int>(ones.size());
    accessor.sparse.indices.bufferView =
        AddBufferView(ones.data(), ones.size() * sizeof(uint32_t), 0);
    accessor.sparse.indices.byteOffset = 0;
    accessor.sparse.indices.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
    const std::vector<float> values(ones.size(), 1.0f);
    accessor.sparse.values.bufferView =
        AddBufferView(values.data(), values.size() * sizeof(float), 0);
    accessor.sparse.values.byteOffset = 0;
    return Push(accessor);
  }

  int AddUnsignedShorts(const std::vector<uint16_t>& values, int type, int target) {
    const int components = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(type));
    tinygltf::Accessor accessor;
    accessor.bufferView = AddBufferView(values.data(), values.size() * sizeof(uint16_t), target);
    accessor.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT;
    accessor.type = type;
    accessor.count = values.size() / static_cast<size_t>(components);
    return Push(accessor);
  }

  int AddUnsignedInts(const std::vector<uint32_t>& values, int target) {
    tinygltf::Accessor accessor;
    accessor.bufferView = AddBufferView(values.data(), values.size() * sizeof(uint32_t), target);
    accessor.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
    accessor.type = TINYGLTF_TYPE_SCALAR;
    accessor.count = values.size();
    return Push(accessor);
  }

 private:
  int Push(const tinygltf::Accessor& accessor) {
    model_->accessors.push_back(accessor);
    return static_cast<int>(model_->accessors.size()) - 1;
  }

  tinygltf::Model* model_;
  size_t external_bytes_ = 0;
};

void AppendToVector(void* context, void* data, int size) {
  auto* out = static_cast<std::vector<unsigned char>*>(context);
  const auto* p = static_cast<const unsigned char*>(data);
  out->insert(out->end(), p, p + size);
}

std::vector<unsigned char> EncodeTexturePng(const GlbTexture& texture) {
  if (!texture.png.empty()) {
    if (!LooksLikePng(texture.png)) {
      throw Error("texture.png: expected encoded PNG bytes (PNG signature), found other data");
    }
    return texture.png;
  }
  if (texture.width <= 0 || texture.height <= 0 ||
      texture.rgb.size() != static_cast<size_t>(texture.width) * texture.height * 3) {
    std::ostringstream msg;
    msg << "texture.rgb: expected width x height x 3 = " << texture.width << " x " << texture.height
        << " x 3 bytes with positive sizes, found " << texture.rgb.size();
    throw Error(msg.str());
  }
  std::vector<unsigned char> png;
  if (!stbi_write_png_to_func(AppendToVector, &png, texture.width, texture.height, 3,
                              texture.rgb.data(), texture.width * 3)) {
    throw Error("texture.rgb: PNG encoding failed");
  }
  return png;
}

Eigen::Quaterniond ToQuaternion(const Eigen::Matrix3d& r) {
  Eigen::Quaterniond q(r);
  q.normalize();
  return q;
}

void AppendQuaternion(const Eigen::Quaterniond& q, std::vector<float>* out) {
  out->push_back(static_cast<float>(q.x()));
  out->push_back(static_cast<float>(q.y()));
  out->push_back(static_cast<float>(q.z()));
  out->push_back(static_cast<float>(q.w()));
}

// glTF vertices: one per (template vertex, uv index) pair (uv -1: none), sorted by template
// vertex.
std::vector<std::pair<int, int>> GltfVertexPairs(const Template& tmpl) {
  const int num_vertices = tmpl.num_vertices();
  const bool has_uvs = tmpl.has_uvs();
  std::vector<std::pair<int, int>> pairs;
  pairs.reserve(static_cast<size_t>(tmpl.num_triangles()) * 3 + num_vertices);
  for (int f = 0; f < tmpl.num_triangles(); ++f) {
    for (int c = 0; c < 3; ++c) {
      pairs.emplace_back(tmpl.triangles(f, c), has_uvs ? tmpl.uv_triangles(f, c) : -1);
    }
  }
  std::vector<char> referenced(num_vertices, 0);
  for (const auto& p : pairs) referenced[p.first] = 1;
  for (int v = 0; v < num_vertices; ++v) {
    if (!referenced[v]) pairs.emplace_back(v, -1);
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  return pairs;
}

// The morph targets of an animated glb (one per pose, weighted 1 at its own keyframe,
// models/gltf_skinning.h): their count and each one's POSITION bounds (glTF requires min/max).
// Their displacements are not in the model: their views follow the buffer's own data, and
// WriteAnimatedGlbTo appends them (`external` views, GltfBuilder::AddExternalView).
struct MorphTargetLayout {
  std::vector<Eigen::Vector3f> min, max;  // per target
  int count() const { return static_cast<int>(min.size()); }
};

// Builds the glTF model of a template; poses non-empty adds the animation; `morphs` (or null)
// adds the morph targets' accessors and views, without their data.
tinygltf::Model BuildModel(const Template& tmpl, const std::vector<Pose>& poses, double frame_rate,
                           const GlbTexture* texture, const MorphTargetLayout* morphs = nullptr) {
  std::string error;
  if (!tmpl.IsValid(&error)) throw Error("template: " + error);
  const int num_vertices = tmpl.num_vertices();
  const int num_joints = tmpl.num_joints();
  if (num_joints + 1 > 65535) throw Error("template: too many joints for JOINTS_0 (max 65534)");
  const bool has_uvs = tmpl.has_uvs();
  const std::vector<std::pair<int, int>> pairs = GltfVertexPairs(tmpl);
  const int num_gltf_vertices = static_cast<int>(pairs.size());
  auto gltf_index = [&pairs](int v, int uv) {
    return static_cast<uint32_t>(
        std::lower_bound(pairs.begin(), pairs.end(), std::make_pair(v, uv)) - pairs.begin());
  };

  Eigen::MatrixX3d normals;
  ComputeVertexNormals(tmpl.vertices, tmpl.triangles, &normals);

  std::vector<float> positions, normal_values, texcoords, vertex_ids, uv_ids, joint_ids, lbs_values,
      tau_values, weights;
  std::vector<uint16_t> joints;
  positions.reserve(3 * num_gltf_vertices);
  for (const auto& [v, uv] : pairs) {
    for (int c = 0; c < 3; ++c) positions.push_back(static_cast<float>(tmpl.vertices(v, c)));
    Eigen::Vector3f n = normals.row(v).transpose().cast<float>();
    if (!(n.norm() > 0.5f)) n = Eigen::Vector3f::UnitY();  // isolated or degenerate vertex
    n.normalize();
    normal_values.insert(normal_values.end(), {n.x(), n.y(), n.z()});
    if (has_uvs) {
      const Eigen::Vector2d t =
          uv >= 0 ? Eigen::Vector2d(tmpl.uvs.row(uv).transpose()) : Eigen::Vector2d::Zero();
      texcoords.push_back(static_cast<float>(t.x()));
      texcoords.push_back(static_cast<float>(t.y()));
      uv_ids.push_back(static_cast<float>(uv));
    }
    vertex_ids.push_back(static_cast<float>(v));
    const int k = tmpl.vertex_joint[v];
    joint_ids.push_back(static_cast<float>(k));
    const float w = static_cast<float>(tmpl.lbs_weight[v]);
    lbs_values.push_back(w);
    tau_values.push_back(static_cast<float>(tmpl.slerp_tau[v]));
    // Skin joint 0 is the global-similarity node; artex joint j is skin joint j + 1.
    const uint16_t own = static_cast<uint16_t>(k + 1);
    const uint16_t parent = static_cast<uint16_t>(tmpl.joints[k].parent + 1);
    if (w >= 1.0f) {
      joints.insert(joints.end(), {own, 0, 0, 0});
      weights.insert(weights.end(), {1.0f, 0.0f, 0.0f, 0.0f});
    } else if (w <= 0.0f) {
      joints.insert(joints.end(), {parent, 0, 0, 0});
      weights.insert(weights.end(), {1.0f, 0.0f, 0.0f, 0.0f});
    } else {
      joints.insert(joints.end(), {own, parent, 0, 0});
      weights.insert(weights.end(), {w, 1.0f - w, 0.0f, 0.0f});
    }
  }
  std::vector<uint32_t> indices;
  indices.reserve(static_cast<size_t>(tmpl.num_triangles()) * 3);
  for (int f = 0; f < tmpl.num_triangles(); ++f) {
    for (int c = 0; c < 3; ++c) {
      indices.push_back(gltf_index(tmpl.triangles(f, c), has_uvs ? tmpl.uv_triangles(f, c) : -1));
    }
  }

  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = "artex";
  GltfBuilder builder(&model);

  tinygltf::Primitive primitive;
  primitive.mode = TINYGLTF_MODE_TRIANGLES;
  primitive.indices = builder.AddUnsignedInts(indices, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
  primitive.attributes["POSITION"] =
      builder.AddFloats(positions, TINYGLTF_TYPE_VEC3, TINYGLTF_TARGET_ARRAY_BUFFER, true);
  primitive.attributes["NORMAL"] =
      builder.AddFloats(normal_values, TINYGLTF_TYPE_VEC3, TINYGLTF_TARGET_ARRAY_BUFFER, false);
  if (has_uvs) {
    primitive.attributes["TEXCOORD_0"] =
        builder.AddFloats(texcoords, TINYGLTF_TYPE_VEC2, TINYGLTF_TARGET_ARRAY_BUFFER, false);
    primitive.attributes[kUvAttribute] =
        builder.AddFloats(uv_ids, TINYGLTF_TYPE_SCALAR, TINYGLTF_TARGET_ARRAY_BUFFER, false);
  }
  primitive.attributes["JOINTS_0"] =
      builder.AddUnsignedShorts(joints, TINYGLTF_TYPE_VEC4, TINYGLTF_TARGET_ARRAY_BUFFER);
  primitive.attributes["WEIGHTS_0"] =
      builder.AddFloats(weights, TINYGLTF_TYPE_VEC4, TINYGLTF_TARGET_ARRAY_BUFFER, false);
  primitive.attributes[kVertexAttribute] =
      builder.AddFloats(vertex_ids, TINYGLTF_TYPE_SCALAR, TINYGLTF_TARGET_ARRAY_BUFFER, false);
  primitive.attributes[kJointAttribute] =
      builder.AddFloats(joint_ids, TINYGLTF_TYPE_SCALAR, TINYGLTF_TARGET_ARRAY_BUFFER, false);
  primitive.attributes[kLbsAttribute] =
      builder.AddFloats(lbs_values, TINYGLTF_TYPE_SCALAR, TINYGLTF_TARGET_ARRAY_BUFFER, false);
  primitive.attributes[kTauAttribute] =
      builder.AddFloats(tau_values, TINYGLTF_TYPE_SCALAR, TINYGLTF_TARGET_ARRAY_BUFFER, false);
  const int num_targets = morphs ? morphs->count() : 0;

  // Material (and the optional embedded base-colour texture).
  tinygltf::Material material;
  material.name = "artex_material";
  material.pbrMetallicRoughness.metallicFactor = 0.0;
  material.pbrMetallicRoughness.roughnessFactor = 1.0;
  if (texture != nullptr && !texture->empty()) {
    if (!has_uvs) throw Error("texture: the template has no UV atlas to map it with");
    const std::vector<unsigned char> png = EncodeTexturePng(*texture);
    tinygltf::Image image;
    image.name = "artex_texture";
    image.mimeType = "image/png";
    image.bufferView = builder.AddBufferView(png.data(), png.size(), 0);
    model.images.push_back(image);
    tinygltf::Sampler sampler;
    sampler.magFilter = TINYGLTF_TEXTURE_FILTER_LINEAR;
    sampler.minFilter = TINYGLTF_TEXTURE_FILTER_LINEAR;
    sampler.wrapS = TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE;
    sampler.wrapT = TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE;
    model.samplers.push_back(sampler);
    tinygltf::Texture gltf_texture;
    gltf_texture.sampler = 0;
    gltf_texture.source = 0;
    model.textures.push_back(gltf_texture);
    material.pbrMetallicRoughness.baseColorTexture.index = 0;
  } else {
    material.pbrMetallicRoughness.baseColorFactor = {0.8, 0.8, 0.8, 1.0};
  }
  model.materials.push_back(material);
  primitive.material = 0;

  tinygltf::Mesh mesh;
  mesh.name = "artex_template";
  mesh.primitives.push_back(primitive);
  tinygltf::Value::Object mesh_extras;
  mesh_extras["artex_format_version"] = tinygltf::Value(kFormatVersion);
  mesh_extras["artex_num_vertices"] = tinygltf::Value(num_vertices);
  mesh_extras["artex_num_uvs"] = tinygltf::Value(static_cast<int>(has_uvs ? tmpl.uvs.rows() : 0));
  if (tmpl.triangle_chart.size() == tmpl.num_triangles()) {
    std::vector<uint32_t> charts(tmpl.triangle_chart.size());
    for (int f = 0; f < tmpl.num_triangles(); ++f) {
      if (tmpl.triangle_chart[f] < 0) {
        throw Error("template: triangle_chart[" + std::to_string(f) +
                    "]: expected a non-negative chart index, found " +
                    std::to_string(tmpl.triangle_chart[f]));
      }
      charts[f] = static_cast<uint32_t>(tmpl.triangle_chart[f]);
    }
    mesh_extras["artex_triangle_chart_accessor"] =
        tinygltf::Value(builder.AddUnsignedInts(charts, 0));
  }
  mesh.extras = tinygltf::Value(std::move(mesh_extras));
  if (num_targets > 0) {
    model.meshes.push_back(mesh);
    model.meshes.back().weights.assign(num_targets, 0.0);
    tinygltf::Value::Array names;
    for (int t = 0; t < num_targets; ++t) {
      names.push_back(tinygltf::Value("artex_frame_" + std::to_string(t)));
    }
    tinygltf::Value::Object extras = model.meshes.back().extras.Get<tinygltf::Value::Object>();
    extras["targetNames"] = tinygltf::Value(names);  // shape-key names in Blender
    model.meshes.back().extras = tinygltf::Value(extras);
  } else {
    model.meshes.push_back(mesh);
  }

  // Nodes: 0 = skinned mesh, 1 = global similarity, 2 + j = joint j.
  constexpr int kMeshNode = 0;
  constexpr int kGlobalNode = 1;
  auto joint_node = [](int j) { return 2 + j; };
  model.nodes.resize(2 + num_joints);
  model.nodes[kMeshNode].name = "artex_mesh";
  model.nodes[kMeshNode].mesh = 0;
  model.nodes[kMeshNode].skin = 0;
  tinygltf::Node& global = model.nodes[kGlobalNode];
  global.name = "artex_global";
  global.extras = tinygltf::Value(
      tinygltf::Value::Object{{"artex_role", tinygltf::Value(std::string("global_similarity"))}});
  for (int j = 0; j < num_joints; ++j) {
    const Joint& joint = tmpl.joints[j];
    tinygltf::Node& node = model.nodes[joint_node(j)];
    node.name = joint.name;
    const Eigen::Vector3d parent_center =
        joint.parent >= 0 ? tmpl.joints[joint.parent].center : Eigen::Vector3d::Zero();
    const Eigen::Vector3d offset = joint.center - parent_center;
    node.translation = {offset.x(), offset.y(), offset.z()};
    node.extras = tinygltf::Value(
        tinygltf::Value::Object{{"artex_center", NumberArray(joint.center)},
                                {"artex_twist_axis", NumberArray(joint.twist_axis)}});
    const int parent_node = joint.parent >= 0 ? joint_node(joint.parent) : kGlobalNode;
    model.nodes[parent_node].children.push_back(joint_node(j));
  }

  // Skin: joints [global, joint 0 .. J-1]; inverse bind matrices translate by -t_j.
  tinygltf::Skin skin;
  skin.name = "artex_skeleton";
  skin.skeleton = kGlobalNode;
  skin.joints.push_back(kGlobalNode);
  std::vector<float> inverse_bind;
  auto append_translation_matrix = [&inverse_bind](const Eigen::Vector3d& t) {
    Eigen::Matrix4f m = Eigen::Matrix4f::Identity();
    m.block<3, 1>(0, 3) = t.cast<float>();
    inverse_bind.insert(inverse_bind.end(), m.data(), m.data() + 16);  // column-major
  };
  append_translation_matrix(Eigen::Vector3d::Zero());
  for (int j = 0; j < num_joints; ++j) {
    skin.joints.push_back(joint_node(j));
    append_translation_matrix(-tmpl.joints[j].center);
  }
  skin.inverseBindMatrices = builder.AddFloats(inverse_bind, TINYGLTF_TYPE_MAT4, 0, false);
  model.skins.push_back(skin);

  tinygltf::Scene scene;
  scene.name = "artex";
  scene.nodes = {kMeshNode, kGlobalNode};
  model.scenes.push_back(scene);
  model.defaultScene = 0;

  if (!poses.empty()) {
    if (!(frame_rate > 0.0) || !std::isfinite(frame_rate)) {
      throw Error("frame_rate: expected a positive finite rate (Hz), found " +
                  ErrorNumber(frame_rate));
    }
    const int num_frames = static_cast<int>(poses.size());
    for (int f = 0; f < num_frames; ++f) {
      const Pose& pose = poses[f];
      const std::string what = "poses[" + std::to_string(f) + "]";
      if (pose.num_joints() != num_joints) {
        throw Error(what + ": expected " + std::to_string(num_joints) + " joint rotations, found " +
                    std::to_string(pose.num_joints()));
      }
      if (!pose.AllFinite()) throw Error(what + ": found a non-finite entry");
      if (!(pose.scale > 0.0))
        throw Error(what + ": expected a positive scale, found " + ErrorNumber(pose.scale));
    }
    std::vector<float> times(num_frames);
    for (int f = 0; f < num_frames; ++f) times[f] = static_cast<float>(f / frame_rate);
    const int input = builder.AddFloats(times, TINYGLTF_TYPE_SCALAR, 0, true);
    tinygltf::Animation animation;
    animation.name = "artex_motion";
    // A linear channel animating `path` of `node` with the keyframe values of accessor `output`.
    auto add_channel_output = [&](int node, const std::string& path, int output) {
      tinygltf::AnimationSampler sampler;
      sampler.input = input;
      sampler.output = output;
      sampler.interpolation = "LINEAR";
      animation.samplers.push_back(sampler);
      tinygltf::AnimationChannel channel;
      channel.sampler = static_cast<int>(animation.samplers.size()) - 1;
      channel.target_node = node;
      channel.target_path = path;
      animation.channels.push_back(channel);
    };
    auto add_channel = [&](int node, const std::string& path, const std::vector<float>& values,
                           int type) {
      add_channel_output(node, path, builder.AddFloats(values, type, 0, false));
    };
    // Quaternion tracks keep the sign closest to the previous key (shortest interpolation).
    auto rotation_track = [&](const std::function<Eigen::Matrix3d(const Pose&)>& get) {
      std::vector<float> values;
      Eigen::Quaterniond previous = Eigen::Quaterniond::Identity();
      for (int f = 0; f < num_frames; ++f) {
        Eigen::Quaterniond q = ToQuaternion(get(poses[f]));
        if (f > 0 && q.dot(previous) < 0.0) q.coeffs() = -q.coeffs();
        AppendQuaternion(q, &values);
        previous = q;
      }
      return values;
    };
    std::vector<float> translation, scale;
    for (const Pose& pose : poses) {
      for (int c = 0; c < 3; ++c) translation.push_back(static_cast<float>(pose.translation[c]));
      for (int c = 0; c < 3; ++c) scale.push_back(static_cast<float>(pose.scale));
    }
    add_channel(kGlobalNode, "translation", translation, TINYGLTF_TYPE_VEC3);
    add_channel(kGlobalNode, "rotation", rotation_track([](const Pose& p) { return p.rotation; }),
                TINYGLTF_TYPE_VEC4);
    add_channel(kGlobalNode, "scale", scale, TINYGLTF_TYPE_VEC3);
    for (int j = 0; j < num_joints; ++j) {
      add_channel(joint_node(j), "rotation",
                  rotation_track([j](const Pose& p) { return p.joint_rotations[j]; }),
                  TINYGLTF_TYPE_VEC4);
    }
    if (num_targets > 0) {
      // Keyframe f: weight 1 on frame f's corrective, 0 on the others (blended in between):
      // a sparse accessor of num_frames^2 weights with num_frames ones (the dense one grew
      // with the square of the frame count: 324 MB for 5 minutes at 30 Hz).
      if (num_targets != num_frames) throw Error("morph targets: expected one per pose");
      if (static_cast<uint64_t>(num_frames) * num_frames > 0xffffffffull) {
        throw Error("poses: at most 65535 frames in an animated glb with morph targets, found " +
                    std::to_string(num_frames));
      }
      std::vector<uint32_t> ones(num_frames);
      for (int f = 0; f < num_frames; ++f) {
        ones[f] = static_cast<uint32_t>(f) * static_cast<uint32_t>(num_frames + 1);
      }
      add_channel_output(kMeshNode, "weights",
                         builder.AddSparseOnes(static_cast<size_t>(num_frames) * num_frames, ones));
    }
    model.animations.push_back(animation);
  }
  // The morph targets' displacements, last in the buffer (appended by WriteAnimatedGlbTo).
  for (int t = 0; t < num_targets; ++t) {
    tinygltf::Accessor accessor;
    accessor.bufferView = builder.AddExternalView(
        static_cast<size_t>(num_gltf_vertices) * 3 * sizeof(float), TINYGLTF_TARGET_ARRAY_BUFFER);
    accessor.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
    accessor.type = TINYGLTF_TYPE_VEC3;
    accessor.count = num_gltf_vertices;
    for (int c = 0; c < 3; ++c) {
      accessor.minValues.push_back(morphs->min[t][c]);
      accessor.maxValues.push_back(morphs->max[t][c]);
    }
    model.accessors.push_back(accessor);
    model.meshes[0].primitives[0].targets.push_back(
        {{"POSITION", static_cast<int>(model.accessors.size()) - 1}});
  }
  return model;
}

std::string Serialize(const tinygltf::Model& model) {
  std::ostringstream out(std::ios::binary);
  tinygltf::TinyGLTF writer;
  if (!writer.WriteGltfSceneToStream(&model, out, false, true)) {
    throw Error("glTF serialisation failed");
  }
  return out.str();
}

}  // namespace

// ------------------------------------------------------------------------------------------

std::string EncodeTemplateGlb(const Template& tmpl, const GlbTexture* texture) {
  return Serialize(BuildModel(tmpl, {}, 0.0, texture));
}

std::string EncodeAnimatedGlb(const Template& tmpl, const std::vector<Pose>& poses,
                              double frame_rate, const GlbTexture* texture) {
  if (poses.empty()) throw Error("poses: expected at least one pose for an animation, found none");
  return Serialize(BuildModel(tmpl, poses, frame_rate, texture));
}

bool AnimatedGlbOptions::IsValid(std::string* error) const { return corrective.IsValid(error); }

namespace {

struct FileCloser {
  void operator()(std::FILE* f) const { std::fclose(f); }
};

void PutU32(std::ostream& out, uint32_t v) {
  const unsigned char b[4] = {static_cast<unsigned char>(v), static_cast<unsigned char>(v >> 8),
                              static_cast<unsigned char>(v >> 16),
                              static_cast<unsigned char>(v >> 24)};
  out.write(reinterpret_cast<const char*>(b), 4);
}

// The animated glb, written to `out` with the morph targets' displacements passing through an
// anonymous temporary file: memory stays the template's, whatever the number of frames (each
// target is 12 bytes per glTF vertex; 300 frames of the default template held ~200 MB in
// copies before).
void WriteAnimatedGlbTo(std::ostream& out, const Template& tmpl, const std::vector<Pose>& poses,
                        double frame_rate, const GlbTexture* texture,
                        const AnimatedGlbOptions& options, AnimatedGlbSummary* summary) {
  if (poses.empty()) throw Error("poses: expected at least one pose for an animation, found none");
  std::string why;
  if (!options.IsValid(&why)) throw Error("animated glb options: " + why);
  std::string error;
  if (!tmpl.IsValid(&error)) throw Error("template: " + error);
  AnimatedGlbSummary s;
  s.frames = static_cast<int>(poses.size());
  const Skinning skinning(tmpl);
  const std::vector<std::pair<int, int>> pairs = GltfVertexPairs(tmpl);
  std::unique_ptr<std::FILE, FileCloser> spill;
  if (options.exact) {
    spill.reset(std::tmpfile());
    if (!spill) throw Error("cannot create a temporary file for the morph targets");
  }
  MorphTargetLayout layout;
  double lbs_sum = 0.0, exact_sum = 0.0;
  long long count = 0;
  // Frames up to the first bad pose (BuildModel reports it), in batches: a batch's frames are
  // evaluated concurrently, then summed and written in frame order (the same sums and file as
  // one frame after another).
  std::size_t frames = 0;
  while (frames < poses.size() && poses[frames].num_joints() == tmpl.num_joints() &&
         poses[frames].AllFinite()) {
    ++frames;
  }
  struct FrameTargets {
    double lbs_sum = 0.0, lbs_max = 0.0, exact_sum = 0.0, exact_max = 0.0;
    long long count = 0;
    int singular_vertices = 0;
    Eigen::Vector3f lo, hi;
    std::vector<float> displacement;  // 3 per glTF vertex
  };
  constexpr std::size_t kBatch = 16;  // frames in memory at once (~0.6 MB each, default template)
  std::vector<FrameTargets> batch(kBatch);
  for (std::size_t first = 0; first < frames; first += kBatch) {
    const std::size_t n = std::min(kBatch, frames - first);
    tbb::parallel_for(std::size_t{0}, n, [&](std::size_t k) {
      const Pose& pose = poses[first + k];
      FrameTargets& t = batch[k];
      Eigen::MatrixX3d artex_positions, lbs_positions;
      skinning.Apply(pose, &artex_positions);
      GltfSkinnedPositions(tmpl, pose, nullptr, &lbs_positions);
      const Eigen::VectorXd lbs_error = (lbs_positions - artex_positions).rowwise().norm();
      t.lbs_max = lbs_error.maxCoeff();
      t.lbs_sum = lbs_error.sum();
      t.count = lbs_error.size();
      if (!options.exact) return;
      Eigen::MatrixX3d offsets;
      GltfCorrectiveStats stats;
      GltfCorrectiveOffsets(tmpl, pose, artex_positions, options.corrective, &offsets, &stats);
      t.singular_vertices = stats.singular_vertices;
      // The residual of what the file holds: offsets rounded to float as written.
      const Eigen::MatrixX3f stored = offsets.cast<float>();
      Eigen::MatrixX3d exact_positions;
      const Eigen::MatrixX3d stored_d = stored.cast<double>();
      GltfSkinnedPositions(tmpl, pose, &stored_d, &exact_positions);
      const Eigen::VectorXd exact_error = (exact_positions - artex_positions).rowwise().norm();
      t.exact_max = exact_error.maxCoeff();
      t.exact_sum = exact_error.sum();
      t.lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::infinity());
      t.hi = -t.lo;
      t.displacement.resize(3 * pairs.size());
      for (std::size_t i = 0; i < pairs.size(); ++i) {
        const Eigen::Vector3f d = stored.row(pairs[i].first).transpose();
        t.lo = t.lo.cwiseMin(d);
        t.hi = t.hi.cwiseMax(d);
        for (int c = 0; c < 3; ++c) t.displacement[3 * i + c] = d[c];
      }
    });
    for (std::size_t k = 0; k < n; ++k) {
      const FrameTargets& t = batch[k];
      s.lbs_max_residual_mm = std::max(s.lbs_max_residual_mm, 1e3 * t.lbs_max);
      lbs_sum += t.lbs_sum;
      count += t.count;
      if (!options.exact) continue;
      s.singular_vertices += t.singular_vertices;
      s.exact_max_residual_mm = std::max(s.exact_max_residual_mm, 1e3 * t.exact_max);
      exact_sum += t.exact_sum;
      layout.min.push_back(t.lo);
      layout.max.push_back(t.hi);
      if (std::fwrite(t.displacement.data(), sizeof(float), t.displacement.size(), spill.get()) !=
          t.displacement.size()) {
        throw Error("cannot write the morph targets to a temporary file (disk full?)");
      }
    }
  }
  if (count > 0) s.lbs_mean_residual_mm = 1e3 * lbs_sum / static_cast<double>(count);
  if (options.exact && count > 0) {
    s.exact_mean_residual_mm = 1e3 * exact_sum / static_cast<double>(count);
  } else {
    s.exact_max_residual_mm = s.lbs_max_residual_mm;
    s.exact_mean_residual_mm = s.lbs_mean_residual_mm;
  }
  s.morph_targets = layout.count();
  const tinygltf::Model model =
      BuildModel(tmpl, poses, frame_rate, texture, options.exact ? &layout : nullptr);
  const std::string glb = Serialize(model);  // the buffer's own data, without the targets
  const uint64_t external = static_cast<uint64_t>(layout.count()) * pairs.size() * 12;
  if (external == 0) {
    out.write(glb.data(), static_cast<std::streamsize>(glb.size()));
    s.bytes = glb.size();
    if (summary) *summary = s;
    return;
  }
  // Re-frame tinygltf's GLB: the JSON with the buffer's whole length, the BIN chunk with the
  // targets appended (their views start at the own data's length rounded up to 4).
  const uint32_t json_length = ReadU32(glb, 12);
  const uint32_t bin_length = ReadU32(glb, 20 + json_length);
  const uint64_t own = (model.buffers[0].data.size() + 3) / 4 * 4;
  if (bin_length != own) throw Error("glTF serialisation: unexpected BIN chunk length");
  nlohmann::json json = nlohmann::json::parse(glb.substr(20, json_length));
  json["buffers"][0]["byteLength"] = own + external;
  std::string text = json.dump();
  while (text.size() % 4 != 0) text.push_back(' ');
  const uint64_t total = 12 + 8 + text.size() + 8 + own + external;
  if (total > 0xffffffffull) {
    throw Error("animated glb: " + std::to_string(total) + " bytes, beyond GLB's 4 GiB (" +
                std::to_string(poses.size()) + " frames of " + std::to_string(pairs.size()) +
                " vertices); write fewer frames or without `exact`");
  }
  out.write("glTF", 4);
  PutU32(out, 2);
  PutU32(out, static_cast<uint32_t>(total));
  PutU32(out, static_cast<uint32_t>(text.size()));
  out.write("JSON", 4);
  out.write(text.data(), static_cast<std::streamsize>(text.size()));
  PutU32(out, static_cast<uint32_t>(own + external));
  out.write("BIN\0", 4);
  out.write(glb.data() + 28 + json_length, static_cast<std::streamsize>(own));
  std::rewind(spill.get());
  std::vector<char> block(1 << 20);
  uint64_t copied = 0;
  while (copied < external) {
    const std::size_t n = std::fread(block.data(), 1, block.size(), spill.get());
    if (n == 0) throw Error("cannot read the morph targets back from their temporary file");
    out.write(block.data(), static_cast<std::streamsize>(n));
    copied += n;
  }
  if (copied != external) throw Error("morph targets: temporary file of the wrong length");
  s.bytes = total;
  if (summary) *summary = s;
}

}  // namespace

std::string EncodeAnimatedGlb(const Template& tmpl, const std::vector<Pose>& poses,
                              double frame_rate, const GlbTexture* texture,
                              const AnimatedGlbOptions& options, AnimatedGlbSummary* summary) {
  std::ostringstream out(std::ios::binary);
  WriteAnimatedGlbTo(out, tmpl, poses, frame_rate, texture, options, summary);
  return out.str();
}

void WriteAnimatedGlb(const std::string& path, const Template& tmpl, const std::vector<Pose>& poses,
                      double frame_rate, const GlbTexture* texture,
                      const AnimatedGlbOptions& options, AnimatedGlbSummary* summary) {
  // WriteFileAtomically's own errors name `path` already; the encoder's get it here.
  WriteFileAtomically(path, [&](std::ostream& out) {
    try {
      WriteAnimatedGlbTo(out, tmpl, poses, frame_rate, texture, options, summary);
    } catch (const Error& e) {
      Fail(path, e.what());
    }
  });
}

void WriteTemplateGlb(const std::string& path, const Template& tmpl, const GlbTexture* texture) {
  std::string bytes;
  try {
    bytes = EncodeTemplateGlb(tmpl, texture);
  } catch (const Error& e) {
    Fail(path, e.what());
  }
  WriteFileAtomically(path, bytes);
}

void WriteAnimatedGlb(const std::string& path, const Template& tmpl, const std::vector<Pose>& poses,
                      double frame_rate, const GlbTexture* texture) {
  std::string bytes;
  try {
    bytes = EncodeAnimatedGlb(tmpl, poses, frame_rate, texture);
  } catch (const Error& e) {
    Fail(path, e.what());
  }
  WriteFileAtomically(path, bytes);
}

}  // namespace artex
