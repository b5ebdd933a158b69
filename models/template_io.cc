#include "models/template_io.h"

#include <tiny_gltf.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <unordered_map>

#include <nlohmann/json.hpp>

#include "models/error.h"
#include "models/gltf_skinning.h"
#include "models/file_context.h"
#include "models/makehuman_import.h"
#include "models/mesh_export.h"
#include "models/normals.h"
#include "models/skinning.h"

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
namespace {

// Names of the artex-specific parts of the format (docs/formats-template.md).
constexpr char kVertexAttribute[] = "_ARTEX_VERTEX";
constexpr char kUvAttribute[] = "_ARTEX_UV";
constexpr char kJointAttribute[] = "_ARTEX_JOINT";
constexpr char kLbsAttribute[] = "_ARTEX_LBS_WEIGHT";
constexpr char kTauAttribute[] = "_ARTEX_SLERP_TAU";
constexpr int kFormatVersion = 1;
constexpr uint32_t kGlbMagic = 0x46546C67;      // "glTF"
constexpr uint32_t kChunkJson = 0x4E4F534A;     // "JSON"
constexpr uint32_t kChunkBin = 0x004E4942;      // "BIN\0"

[[noreturn]] void Fail(const std::string& where, const std::string& what) {
  throw Error(where + ": " + what);
}

// ------------------------------------------------------------------------------------------
// Writing.

tinygltf::Value NumberArray(const Eigen::Vector3d& v) {
  return tinygltf::Value(tinygltf::Value::Array{tinygltf::Value(v.x()), tinygltf::Value(v.y()),
                                                tinygltf::Value(v.z())});
}

class GltfBuilder {
 public:
  explicit GltfBuilder(tinygltf::Model* model) : model_(model) {
    model_->buffers.resize(1);
  }

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

bool LooksLikePng(const std::vector<unsigned char>& bytes) {
  static const unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  return bytes.size() >= 8 && std::memcmp(bytes.data(), kSignature, 8) == 0;
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
    msg << "texture.rgb: expected width x height x 3 = " << texture.width << " x "
        << texture.height << " x 3 bytes with positive sizes, found " << texture.rgb.size();
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
tinygltf::Model BuildModel(const Template& tmpl, const std::vector<Pose>& poses,
                           double frame_rate, const GlbTexture* texture,
                           const MorphTargetLayout* morphs = nullptr) {
  std::string error;
  if (!tmpl.IsValid(&error)) throw Error("template: " + error);
  const int num_vertices = tmpl.num_vertices();
  const int num_joints = tmpl.num_joints();
  if (num_joints + 1 > 65535) throw Error("template: too many joints for JOINTS_0 (max 65534)");
  const bool has_uvs = tmpl.has_uvs();
  const std::vector<std::pair<int, int>> pairs = GltfVertexPairs(tmpl);
  const int num_gltf_vertices = static_cast<int>(pairs.size());
  auto gltf_index = [&pairs](int v, int uv) {
    return static_cast<uint32_t>(std::lower_bound(pairs.begin(), pairs.end(),
                                                  std::make_pair(v, uv)) -
                                 pairs.begin());
  };

  Eigen::MatrixX3d normals;
  ComputeVertexNormals(tmpl.vertices, tmpl.triangles, &normals);

  std::vector<float> positions, normal_values, texcoords, vertex_ids, uv_ids, joint_ids,
      lbs_values, tau_values, weights;
  std::vector<uint16_t> joints;
  positions.reserve(3 * num_gltf_vertices);
  for (const auto& [v, uv] : pairs) {
    for (int c = 0; c < 3; ++c) positions.push_back(static_cast<float>(tmpl.vertices(v, c)));
    Eigen::Vector3f n = normals.row(v).transpose().cast<float>();
    if (!(n.norm() > 0.5f)) n = Eigen::Vector3f::UnitY();  // isolated or degenerate vertex
    n.normalize();
    normal_values.insert(normal_values.end(), {n.x(), n.y(), n.z()});
    if (has_uvs) {
      const Eigen::Vector2d t = uv >= 0 ? Eigen::Vector2d(tmpl.uvs.row(uv).transpose())
                                        : Eigen::Vector2d::Zero();
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
    node.extras = tinygltf::Value(tinygltf::Value::Object{
        {"artex_center", NumberArray(joint.center)},
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
      if (!(pose.scale > 0.0)) throw Error(what + ": expected a positive scale, found " +
                                           ErrorNumber(pose.scale));
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
    add_channel(kGlobalNode, "rotation",
                rotation_track([](const Pose& p) { return p.rotation; }), TINYGLTF_TYPE_VEC4);
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

// ------------------------------------------------------------------------------------------
// Reading.

std::string ReadFileBytes(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) Fail(path, "no such file");
  std::ifstream in(path, std::ios::binary);
  if (!in) Fail(path, "cannot open for reading");
  std::ostringstream data;
  data << in.rdbuf();
  if (in.bad()) Fail(path, "read error");
  return data.str();
}

uint32_t ReadU32(const std::string& bytes, size_t offset) {
  uint32_t v = 0;
  std::memcpy(&v, bytes.data() + offset, 4);
  return v;  // little endian host (x86-64 / aarch64)
}

// Checks the GLB container (header, chunk table) before handing it to the parser, so that
// truncation is reported precisely.
void CheckGlbContainer(const std::string& bytes, const std::string& path) {
  if (bytes.size() < 12) {
    Fail(path, "truncated glTF binary: expected at least a 12-byte header, found " +
                   std::to_string(bytes.size()) + " bytes");
  }
  if (ReadU32(bytes, 0) != kGlbMagic) Fail(path, "not a glTF binary (magic 'glTF' missing)");
  const uint32_t version = ReadU32(bytes, 4);
  if (version != 2) Fail(path, "expected glTF binary version 2, found " + std::to_string(version));
  const uint32_t length = ReadU32(bytes, 8);
  if (length > bytes.size()) {
    Fail(path, "truncated glTF binary: header declares " + std::to_string(length) +
                   " bytes, file has " + std::to_string(bytes.size()));
  }
  if (length < bytes.size()) {
    Fail(path, "malformed glTF binary: header declares " + std::to_string(length) +
                   " bytes, file has " + std::to_string(bytes.size()));
  }
  size_t offset = 12;
  int chunk = 0;
  while (offset < length) {
    if (offset + 8 > length) Fail(path, "truncated glTF binary: incomplete chunk header");
    const uint32_t chunk_length = ReadU32(bytes, offset);
    const uint32_t chunk_type = ReadU32(bytes, offset + 4);
    if (offset + 8 + static_cast<size_t>(chunk_length) > length) {
      Fail(path, "truncated glTF binary: chunk " + std::to_string(chunk) + " declares " +
                     std::to_string(chunk_length) + " bytes beyond the end of the file");
    }
    if (chunk == 0 && chunk_type != kChunkJson) {
      Fail(path, "malformed glTF binary: the first chunk must be JSON");
    }
    if (chunk == 1 && chunk_type != kChunkBin) {
      Fail(path, "malformed glTF binary: the second chunk must be BIN");
    }
    offset += 8 + static_cast<size_t>(chunk_length);
    ++chunk;
  }
  if (chunk == 0) Fail(path, "malformed glTF binary: no JSON chunk");
}

// Images are not decoded: artex keeps the encoded bytes.
bool KeepImageEncoded(tinygltf::Image* image, const int, std::string*, std::string*, int, int,
                      const unsigned char*, int, void*) {
  (void)image;
  return true;
}

// Fails when the JSON text nests objects and arrays deeper than max_depth: tinygltf converts
// JSON recursively and overflowed the stack on a file nesting a million levels (issue 20).
// Linear; brackets inside strings do not count.
void CheckJsonDepth(const char* json, size_t size, int max_depth, const std::string& path) {
  int depth = 0;
  bool in_string = false, escaped = false;
  for (size_t i = 0; i < size; ++i) {
    const char c = json[i];
    if (in_string) {
      if (escaped) {
        escaped = false;
      } else if (c == '\\') {
        escaped = true;
      } else if (c == '"') {
        in_string = false;
      }
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > max_depth) {
        Fail(path, "malformed glTF: JSON nests deeper than " + std::to_string(max_depth) +
                       " levels (at byte " + std::to_string(i) + ")");
      }
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
}

tinygltf::Model LoadModel(const std::string& path, const std::string& bytes,
                          const GlbReadOptions& options) {
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(KeepImageEncoded, nullptr);
  tinygltf::Model model;
  std::string err, warn;
  bool ok = false;
  const std::string base_dir = std::filesystem::path(path).parent_path().string();
  if (bytes.size() >= 4 && ReadU32(bytes, 0) == kGlbMagic) {
    CheckGlbContainer(bytes, path);
    CheckJsonDepth(bytes.data() + 20, ReadU32(bytes, 12), options.max_json_depth, path);
    ok = loader.LoadBinaryFromMemory(&model, &err, &warn,
                                     reinterpret_cast<const unsigned char*>(bytes.data()),
                                     static_cast<unsigned int>(bytes.size()), base_dir);
  } else {
    CheckJsonDepth(bytes.data(), bytes.size(), options.max_json_depth, path);
    ok = loader.LoadASCIIFromString(&model, &err, &warn, bytes.data(),
                                    static_cast<unsigned int>(bytes.size()), base_dir);
  }
  if (!ok) {
    while (!err.empty() && (err.back() == '\n' || err.back() == ' ')) err.pop_back();
    Fail(path, "malformed glTF: " + (err.empty() ? std::string("parser failed") : err));
  }
  return model;
}

// Accessor contents as doubles (count x components), with bounds checks.
struct AccessorValues {
  size_t count = 0;
  int components = 0;
  std::vector<double> values;
  double at(size_t i, int c) const { return values[i * components + c]; }
};

AccessorValues ReadAccessor(const tinygltf::Model& model, int index, const std::string& what,
                            const std::string& path) {
  if (index < 0 || index >= static_cast<int>(model.accessors.size())) {
    Fail(path, what + ": accessor index " + std::to_string(index) + " out of range");
  }
  const tinygltf::Accessor& accessor = model.accessors[index];
  if (accessor.sparse.isSparse) Fail(path, what + ": sparse accessors are not supported");
  const int components = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(accessor.type));
  const int component_size =
      tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(accessor.componentType));
  if (components <= 0 || component_size <= 0) {
    Fail(path, what + ": unsupported accessor type/componentType");
  }
  AccessorValues out;
  out.count = accessor.count;
  out.components = components;
  if (accessor.bufferView < 0) {
    // All zeros, no data: its count is capped by the file's buffer bytes (issue 20: a 352 KB
    // file declared 2^28 elements and allocated 6 GB).
    size_t max_elements = 0;
    for (const tinygltf::Buffer& b : model.buffers) max_elements += b.data.size();
    if (accessor.count > max_elements) {
      Fail(path, what + ": accessor " + std::to_string(index) +
                     " without a buffer view: expected at most " + std::to_string(max_elements) +
                     " elements (the file's buffer bytes), found " +
                     std::to_string(accessor.count));
    }
    out.values.assign(accessor.count * components, 0.0);
    return out;
  }
  if (accessor.bufferView >= static_cast<int>(model.bufferViews.size())) {
    Fail(path, what + ": buffer view index out of range");
  }
  const tinygltf::BufferView& view = model.bufferViews[accessor.bufferView];
  if (view.buffer < 0 || view.buffer >= static_cast<int>(model.buffers.size())) {
    Fail(path, what + ": buffer index out of range");
  }
  const std::vector<unsigned char>& buffer = model.buffers[view.buffer].data;
  if (view.byteOffset > buffer.size() || view.byteLength > buffer.size() - view.byteOffset) {
    Fail(path, what + ": buffer view " + std::to_string(accessor.bufferView) +
                   " extends beyond its buffer (truncated data)");
  }
  const size_t element_size = static_cast<size_t>(components) * component_size;
  const size_t stride = view.byteStride != 0 ? view.byteStride : element_size;
  if (stride < element_size) Fail(path, what + ": byteStride smaller than the element size");
  if (accessor.count > 0) {
    if (accessor.count > view.byteLength ||
        accessor.byteOffset > view.byteLength ||
        stride * (accessor.count - 1) + element_size > view.byteLength - accessor.byteOffset) {
      Fail(path, what + ": accessor " + std::to_string(index) +
                     " extends beyond its buffer view (truncated data)");
    }
  }
  out.values.resize(accessor.count * components);
  const unsigned char* base = buffer.data() + view.byteOffset + accessor.byteOffset;
  for (size_t i = 0; i < accessor.count; ++i) {
    const unsigned char* element = base + i * stride;
    for (int c = 0; c < components; ++c) {
      const unsigned char* p = element + static_cast<size_t>(c) * component_size;
      double value = 0.0;
      switch (accessor.componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT: {
          float f;
          std::memcpy(&f, p, 4);
          value = f;
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_DOUBLE: {
          std::memcpy(&value, p, 8);
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
          value = *p;
          if (accessor.normalized) value /= 255.0;
          break;
        case TINYGLTF_COMPONENT_TYPE_BYTE:
          value = static_cast<int8_t>(*p);
          if (accessor.normalized) value = std::max(value / 127.0, -1.0);
          break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
          uint16_t s;
          std::memcpy(&s, p, 2);
          value = s;
          if (accessor.normalized) value /= 65535.0;
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_SHORT: {
          int16_t s;
          std::memcpy(&s, p, 2);
          value = s;
          if (accessor.normalized) value = std::max(value / 32767.0, -1.0);
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
          uint32_t u;
          std::memcpy(&u, p, 4);
          value = u;
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_INT: {
          int32_t s;
          std::memcpy(&s, p, 4);
          value = s;
          break;
        }
        default:
          Fail(path, what + ": unsupported componentType " +
                         std::to_string(accessor.componentType));
      }
      out.values[i * components + c] = value;
    }
  }
  return out;
}

// Reads a vertex attribute, checking count, components and finiteness.
AccessorValues ReadAttribute(const tinygltf::Model& model, const tinygltf::Primitive& primitive,
                             const std::string& name, int components, size_t count,
                             const std::string& what, const std::string& path) {
  auto it = primitive.attributes.find(name);
  if (it == primitive.attributes.end()) Fail(path, what + ": missing attribute " + name);
  AccessorValues values = ReadAccessor(model, it->second, what + " attribute " + name, path);
  if (values.components != components) {
    Fail(path, what + " attribute " + name + ": expected " + std::to_string(components) +
                   " components, found " + std::to_string(values.components));
  }
  if (values.count != count) {
    Fail(path, what + " attribute " + name + ": expected " + std::to_string(count) +
                   " entries (POSITION count), found " + std::to_string(values.count));
  }
  for (size_t i = 0; i < values.values.size(); ++i) {
    if (!std::isfinite(values.values[i])) {
      Fail(path, what + " attribute " + name + ": vertex " +
                     std::to_string(i / static_cast<size_t>(components)) +
                     " has a non-finite value");
    }
  }
  return values;
}

// Integer-valued float attribute entry in [lo, hi].
int ToIndex(double value, int lo, int hi, const std::string& what, size_t vertex,
            const std::string& path) {
  const double rounded = std::round(value);
  if (rounded != value || rounded < lo || rounded > hi) {
    Fail(path, what + ": vertex " + std::to_string(vertex) + ": expected an integer in [" +
                   std::to_string(lo) + ", " + std::to_string(hi) + "], found " +
                   ErrorNumber(value));
  }
  return static_cast<int>(rounded);
}

// Parent node of every node; throws on out-of-range children, a node with two parents or a
// cycle.
std::vector<int> NodeParents(const tinygltf::Model& model, const std::string& path) {
  const int n = static_cast<int>(model.nodes.size());
  std::vector<int> parent(n, -1);
  for (int i = 0; i < n; ++i) {
    for (int child : model.nodes[i].children) {
      if (child < 0 || child >= n) {
        Fail(path, "node " + std::to_string(i) + " has child index " + std::to_string(child) +
                       " out of range [0, " + std::to_string(n) + ")");
      }
      if (child == i) {
        Fail(path, "joint hierarchy has a cycle: node " + std::to_string(i) + " ('" +
                       model.nodes[i].name + "') is its own child");
      }
      if (parent[child] != -1) {
        Fail(path, "node " + std::to_string(child) + " ('" + model.nodes[child].name +
                       "') has two parents (" + std::to_string(parent[child]) + " and " +
                       std::to_string(i) + ")");
      }
      parent[child] = i;
    }
  }
  // Cycle check in linear time (issue 20: the per-node walk to the root was quadratic on long
  // chains): walk up from each unvisited node until a finished node or a root; meeting a node
  // of the current walk is a cycle.
  std::vector<char> state(n, 0);  // 0 unvisited, 1 on the current walk, 2 finished
  std::vector<int> walk;
  for (int i = 0; i < n; ++i) {
    walk.clear();
    int j = i;
    for (; j >= 0 && state[j] == 0; j = parent[j]) {
      state[j] = 1;
      walk.push_back(j);
    }
    if (j >= 0 && state[j] == 1) {
      Fail(path, "joint hierarchy has a cycle through node " + std::to_string(j) + " ('" +
                     model.nodes[j].name + "')");
    }
    for (int k : walk) state[k] = 2;
  }
  return parent;
}

// Every node after its parent (`parent` from NodeParents: a forest), in linear time.
std::vector<int> ParentFirstOrder(const std::vector<int>& parent) {
  const int n = static_cast<int>(parent.size());
  std::vector<char> placed(n, 0);
  std::vector<int> order, walk;
  order.reserve(n);
  for (int i = 0; i < n; ++i) {
    walk.clear();
    for (int j = i; j >= 0 && !placed[j]; j = parent[j]) walk.push_back(j);
    for (auto it = walk.rbegin(); it != walk.rend(); ++it) {
      placed[*it] = 1;
      order.push_back(*it);
    }
  }
  return order;
}

// For every node, the nearest proper ancestor that is a skin joint (its skin index), or -1.
// Linear time (a per-joint walk up is quadratic under long chains of plain nodes).
std::vector<int> NearestSkinAncestor(const std::vector<int>& parent,
                                     const std::unordered_map<int, int>& skin_index_of_node) {
  std::vector<int> nearest(parent.size(), -1);
  for (int i : ParentFirstOrder(parent)) {
    const int p = parent[i];
    if (p < 0) continue;
    auto it = skin_index_of_node.find(p);
    nearest[i] = it != skin_index_of_node.end() ? it->second : nearest[p];
  }
  return nearest;
}

Eigen::Matrix4d LocalTransform(const tinygltf::Node& node, const std::string& path, int index) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  const std::string what = "node " + std::to_string(index) + " ('" + node.name + "')";
  if (node.matrix.size() == 16) {
    for (int i = 0; i < 16; ++i) m(i % 4, i / 4) = node.matrix[i];
  } else {
    Eigen::Vector3d t = Eigen::Vector3d::Zero(), s = Eigen::Vector3d::Ones();
    Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
    if (node.translation.size() == 3) t = {node.translation[0], node.translation[1],
                                           node.translation[2]};
    if (node.scale.size() == 3) s = {node.scale[0], node.scale[1], node.scale[2]};
    if (node.rotation.size() == 4) {
      q = Eigen::Quaterniond(node.rotation[3], node.rotation[0], node.rotation[1],
                             node.rotation[2]);
      if (!(q.norm() > 0.0)) Fail(path, what + ": zero rotation quaternion");
      q.normalize();
    }
    m.block<3, 3>(0, 0) = q.toRotationMatrix() * s.asDiagonal();
    m.block<3, 1>(0, 3) = t;
  }
  if (!m.allFinite()) Fail(path, what + ": non-finite transform");
  return m;
}

std::vector<Eigen::Matrix4d> WorldTransforms(const tinygltf::Model& model,
                                             const std::vector<int>& parent,
                                             const std::string& path) {
  // Iterative, parents first: a recursion would overflow the stack on a long node chain.
  std::vector<Eigen::Matrix4d> world(model.nodes.size());
  for (int i : ParentFirstOrder(parent)) {
    const Eigen::Matrix4d local = LocalTransform(model.nodes[i], path, i);
    world[i] = parent[i] >= 0 ? Eigen::Matrix4d(world[parent[i]] * local) : local;
  }
  return world;
}

bool ReadVector3(const tinygltf::Value& extras, const std::string& key, Eigen::Vector3d* out) {
  if (!extras.IsObject() || !extras.Has(key)) return false;
  const tinygltf::Value& v = extras.Get(key);
  if (!v.IsArray() || v.ArrayLen() != 3) return false;
  for (int c = 0; c < 3; ++c) {
    if (!v.Get(c).IsNumber()) return false;
    (*out)[c] = v.Get(c).GetNumberAsDouble();
  }
  return true;
}

// An integer extra; values beyond int's range saturate (a cast would be undefined).
int ReadInt(const tinygltf::Value& extras, const std::string& key, int fallback) {
  if (!extras.IsObject() || !extras.Has(key) || !extras.Get(key).IsNumber()) return fallback;
  const double d = extras.Get(key).GetNumberAsDouble();
  if (std::isnan(d)) return fallback;
  if (d >= static_cast<double>(std::numeric_limits<int>::max()))
    return std::numeric_limits<int>::max();
  if (d <= static_cast<double>(std::numeric_limits<int>::min()))
    return std::numeric_limits<int>::min();
  return static_cast<int>(d);
}

// The first node with a mesh and a skin.
int FindSkinnedMeshNode(const tinygltf::Model& model, const std::string& path) {
  for (size_t i = 0; i < model.nodes.size(); ++i) {
    const tinygltf::Node& node = model.nodes[i];
    if (node.mesh >= 0 && node.skin >= 0) {
      if (node.mesh >= static_cast<int>(model.meshes.size())) {
        Fail(path, "node " + std::to_string(i) + ": mesh index out of range");
      }
      if (node.skin >= static_cast<int>(model.skins.size())) {
        Fail(path, "node " + std::to_string(i) + ": skin index out of range");
      }
      return static_cast<int>(i);
    }
  }
  Fail(path, "no skinned mesh (no node has both a mesh and a skin)");
}

std::vector<int> ReadIndices(const tinygltf::Model& model, const tinygltf::Primitive& primitive,
                             size_t num_vertices, const std::string& what,
                             const std::string& path) {
  if (primitive.mode != -1 && primitive.mode != TINYGLTF_MODE_TRIANGLES) {
    Fail(path, what + ": expected triangles (mode 4), found mode " +
                   std::to_string(primitive.mode));
  }
  std::vector<int> indices;
  if (primitive.indices >= 0) {
    const AccessorValues values = ReadAccessor(model, primitive.indices, what + " indices", path);
    if (values.components != 1) Fail(path, what + " indices: expected scalars");
    indices.reserve(values.count);
    for (size_t i = 0; i < values.count; ++i) {
      const double x = values.values[i];
      if (!(x >= 0.0 && x < static_cast<double>(num_vertices))) {
        Fail(path, what + " indices: entry " + std::to_string(i) + " = " + ErrorNumber(x) +
                       " outside [0, " + std::to_string(num_vertices) + ")");
      }
      indices.push_back(static_cast<int>(x));
    }
  } else {
    indices.resize(num_vertices);
    for (size_t i = 0; i < num_vertices; ++i) indices[i] = static_cast<int>(i);
  }
  if (indices.size() % 3 != 0) {
    Fail(path, what + ": index count " + std::to_string(indices.size()) +
                   " is not a multiple of 3");
  }
  return indices;
}

// Per-vertex (skin joint, weight) lists from JOINTS_n / WEIGHTS_n, checking the sums.
std::vector<std::vector<JointWeight>> ReadSkinWeights(const tinygltf::Model& model,
                                                       const tinygltf::Primitive& primitive,
                                                       size_t count, int num_skin_joints,
                                                       double tolerance, const std::string& what,
                                                       const std::string& path) {
  std::vector<std::vector<JointWeight>> out(count);
  std::vector<double> sums(count, 0.0);
  for (int set = 0; set < 8; ++set) {
    const std::string joints_name = "JOINTS_" + std::to_string(set);
    const std::string weights_name = "WEIGHTS_" + std::to_string(set);
    const bool has_joints = primitive.attributes.count(joints_name) > 0;
    const bool has_weights = primitive.attributes.count(weights_name) > 0;
    if (!has_joints && !has_weights) {
      if (set == 0) Fail(path, what + ": missing attributes JOINTS_0 and WEIGHTS_0");
      break;
    }
    const AccessorValues joints =
        ReadAttribute(model, primitive, joints_name, 4, count, what, path);
    const AccessorValues weights =
        ReadAttribute(model, primitive, weights_name, 4, count, what, path);
    for (size_t v = 0; v < count; ++v) {
      for (int c = 0; c < 4; ++c) {
        const double w = weights.at(v, c);
        if (w < 0.0) {
          Fail(path, what + " attribute " + weights_name + ": vertex " + std::to_string(v) +
                         " has a negative weight " + ErrorNumber(w));
        }
        sums[v] += w;
        if (w == 0.0) continue;
        const int joint = ToIndex(joints.at(v, c), 0, num_skin_joints - 1,
                                  what + " attribute " + joints_name, v, path);
        out[v].push_back({joint, w});
      }
    }
  }
  for (size_t v = 0; v < count; ++v) {
    if (std::abs(sums[v] - 1.0) > tolerance) {
      Fail(path, what + ": skin weights (WEIGHTS_n) of vertex " + std::to_string(v) +
                     " sum to " + ErrorNumber(sums[v]) + ", expected 1");
    }
  }
  return out;
}

void ReadTexture(const tinygltf::Model& model, const tinygltf::Primitive& primitive,
                 GlbTexture* texture) {
  *texture = GlbTexture();
  if (primitive.material < 0 || primitive.material >= static_cast<int>(model.materials.size())) {
    return;
  }
  const int t = model.materials[primitive.material].pbrMetallicRoughness.baseColorTexture.index;
  if (t < 0 || t >= static_cast<int>(model.textures.size())) return;
  const int source = model.textures[t].source;
  if (source < 0 || source >= static_cast<int>(model.images.size())) return;
  const tinygltf::Image& image = model.images[source];
  if (image.bufferView < 0 || image.bufferView >= static_cast<int>(model.bufferViews.size())) {
    return;
  }
  const tinygltf::BufferView& view = model.bufferViews[image.bufferView];
  if (view.buffer < 0 || view.buffer >= static_cast<int>(model.buffers.size())) return;
  const std::vector<unsigned char>& buffer = model.buffers[view.buffer].data;
  if (view.byteOffset + view.byteLength > buffer.size()) return;
  texture->png.assign(buffer.begin() + view.byteOffset,
                      buffer.begin() + view.byteOffset + view.byteLength);
  if (!LooksLikePng(texture->png)) texture->png.clear();  // only PNG is returned
}

Template ParseArtexTemplate(const tinygltf::Model& model, const std::string& path,
                            GlbTexture* texture, const GlbReadOptions& options) {
  const std::vector<int> node_parent = NodeParents(model, path);
  const int mesh_node = FindSkinnedMeshNode(model, path);
  const tinygltf::Mesh& mesh = model.meshes[model.nodes[mesh_node].mesh];
  const tinygltf::Skin& skin = model.skins[model.nodes[mesh_node].skin];
  if (mesh.primitives.size() != 1) {
    Fail(path, "mesh '" + mesh.name + "': expected one primitive, found " +
                   std::to_string(mesh.primitives.size()));
  }
  const tinygltf::Primitive& primitive = mesh.primitives[0];
  const std::string what = "mesh '" + mesh.name + "'";
  if (!primitive.attributes.count(kVertexAttribute)) {
    Fail(path, what + ": missing attribute " + std::string(kVertexAttribute) +
                   " (not an artex template; import other glTF skinned meshes with "
                   "`artex template import-gltf`)");
  }
  auto position_it = primitive.attributes.find("POSITION");
  if (position_it == primitive.attributes.end()) Fail(path, what + ": missing attribute POSITION");
  const size_t count = ReadAccessor(model, position_it->second, what + " POSITION", path).count;
  if (count == 0) Fail(path, what + ": no vertices");
  const AccessorValues positions = ReadAttribute(model, primitive, "POSITION", 3, count, what, path);
  const AccessorValues vertex_ids =
      ReadAttribute(model, primitive, kVertexAttribute, 1, count, what, path);
  const AccessorValues joint_ids =
      ReadAttribute(model, primitive, kJointAttribute, 1, count, what, path);
  const AccessorValues lbs = ReadAttribute(model, primitive, kLbsAttribute, 1, count, what, path);
  const AccessorValues tau = ReadAttribute(model, primitive, kTauAttribute, 1, count, what, path);

  // Joints: skin joint 0 is the global-similarity node, skin joint j + 1 is artex joint j.
  const int num_skin_joints = static_cast<int>(skin.joints.size());
  if (num_skin_joints < 2) {
    Fail(path, "skin '" + skin.name + "': expected the global node and at least one joint, found " +
                   std::to_string(num_skin_joints) + " joints");
  }
  for (int node : skin.joints) {
    if (node < 0 || node >= static_cast<int>(model.nodes.size())) {
      Fail(path, "skin '" + skin.name + "': joint node index out of range");
    }
  }
  ReadSkinWeights(model, primitive, count, num_skin_joints, options.weight_sum_tolerance, what,
                  path);
  const std::vector<Eigen::Matrix4d> world = WorldTransforms(model, node_parent, path);
  std::unordered_map<int, int> skin_index_of_node;
  for (int i = 0; i < num_skin_joints; ++i) {
    if (!skin_index_of_node.emplace(skin.joints[i], i).second) {
      Fail(path, "skin '" + skin.name + "': node " + std::to_string(skin.joints[i]) +
                     " listed twice (skin joints " +
                     std::to_string(skin_index_of_node[skin.joints[i]]) + " and " +
                     std::to_string(i) + ")");
    }
  }
  const std::vector<int> nearest_skin = NearestSkinAncestor(node_parent, skin_index_of_node);
  const int num_joints = num_skin_joints - 1;
  Template tmpl;
  tmpl.joints.resize(num_joints);
  for (int j = 0; j < num_joints; ++j) {
    const int node_index = skin.joints[j + 1];
    const tinygltf::Node& node = model.nodes[node_index];
    Joint& joint = tmpl.joints[j];
    joint.name = node.name;
    // The nearest skin-joint ancestor; the global node (skin joint 0) maps to -1.
    joint.parent = nearest_skin[node_index] >= 0 ? nearest_skin[node_index] - 1 : -1;
    if (!ReadVector3(node.extras, "artex_center", &joint.center)) {
      joint.center = world[node_index].block<3, 1>(0, 3);
    }
    if (!joint.center.allFinite()) {
      Fail(path, "joint '" + joint.name + "': non-finite centre");
    }
  }
  bool all_axes = true;
  for (int j = 0; j < num_joints; ++j) {
    Eigen::Vector3d axis;
    const tinygltf::Value& extras = model.nodes[skin.joints[j + 1]].extras;
    if (ReadVector3(extras, "artex_twist_axis", &axis)) {
      if (!axis.allFinite() || !(axis.norm() > 0.0)) {
        Fail(path, "joint '" + tmpl.joints[j].name + "': artex_twist_axis must be a finite "
                                                     "non-zero vector");
      }
      tmpl.joints[j].twist_axis = axis.normalized();
      if (std::abs(axis.norm() - 1.0) < 1e-12) tmpl.joints[j].twist_axis = axis;
    } else {
      all_axes = false;
    }
  }
  if (!all_axes) AssignDefaultTwistAxes(&tmpl.joints);

  // Vertices: merge the UV-seam copies back.
  int num_vertices = ReadInt(mesh.extras, "artex_num_vertices", -1);
  // Every template vertex has a glTF vertex: more than `count` cannot be (and would allocate
  // whatever the file declares).
  if (num_vertices > static_cast<long long>(count)) {
    Fail(path, what + ": extras.artex_num_vertices: expected at most " + std::to_string(count) +
                   " (the glTF vertex count), found " + std::to_string(num_vertices));
  }
  if (num_vertices < 0) {
    num_vertices = 0;
    for (size_t i = 0; i < count; ++i) {
      const int v = ToIndex(vertex_ids.values[i], 0, static_cast<int>(count) - 1,
                            what + " attribute " + kVertexAttribute, i, path);
      num_vertices = std::max(num_vertices, v + 1);
    }
  }
  std::vector<int> template_vertex(count);
  std::vector<int> first_copy(num_vertices, -1);
  tmpl.vertices.resize(num_vertices, 3);
  tmpl.vertex_joint.resize(num_vertices);
  tmpl.lbs_weight.resize(num_vertices);
  tmpl.slerp_tau.resize(num_vertices);
  const double tol = options.unit_interval_tolerance;
  for (size_t i = 0; i < count; ++i) {
    const int v = ToIndex(vertex_ids.values[i], 0, num_vertices - 1,
                          what + " attribute " + kVertexAttribute, i, path);
    template_vertex[i] = v;
    const Eigen::Vector3d p(positions.at(i, 0), positions.at(i, 1), positions.at(i, 2));
    const int k = ToIndex(joint_ids.values[i], 0, num_joints - 1,
                          what + " attribute " + kJointAttribute, i, path);
    if (first_copy[v] >= 0) {
      if ((tmpl.vertices.row(v).transpose() - p).squaredNorm() != 0.0 ||
          tmpl.vertex_joint[v] != k) {
        Fail(path, what + ": glTF vertices " + std::to_string(first_copy[v]) + " and " +
                       std::to_string(i) + " are copies of template vertex " + std::to_string(v) +
                       " but differ in position or joint");
      }
      continue;
    }
    first_copy[v] = static_cast<int>(i);
    tmpl.vertices.row(v) = p.transpose();
    tmpl.vertex_joint[v] = k;
    const double w = lbs.values[i], t = tau.values[i];
    if (w < -tol || w > 1.0 + tol) {
      Fail(path, what + " attribute " + kLbsAttribute + ": vertex " + std::to_string(i) +
                     ": expected a weight in [0, 1], found " + ErrorNumber(w));
    }
    if (t < -tol || t > 1.0 + tol) {
      Fail(path, what + " attribute " + kTauAttribute + ": vertex " + std::to_string(i) +
                     ": expected a value in [0, 1], found " + ErrorNumber(t));
    }
    tmpl.lbs_weight[v] = std::clamp(w, 0.0, 1.0);
    tmpl.slerp_tau[v] = std::clamp(t, 0.0, 1.0);
  }
  for (int v = 0; v < num_vertices; ++v) {
    if (first_copy[v] < 0) {
      Fail(path, what + ": template vertex " + std::to_string(v) + " has no glTF vertex (" +
                     std::string(kVertexAttribute) + ")");
    }
  }

  const std::vector<int> indices = ReadIndices(model, primitive, count, what, path);
  const int num_triangles = static_cast<int>(indices.size() / 3);
  tmpl.triangles.resize(num_triangles, 3);
  for (int f = 0; f < num_triangles; ++f) {
    for (int c = 0; c < 3; ++c) tmpl.triangles(f, c) = template_vertex[indices[3 * f + c]];
  }

  const bool has_uvs = primitive.attributes.count("TEXCOORD_0") > 0 &&
                       primitive.attributes.count(kUvAttribute) > 0;
  if (has_uvs) {
    const AccessorValues texcoords =
        ReadAttribute(model, primitive, "TEXCOORD_0", 2, count, what, path);
    const AccessorValues uv_ids = ReadAttribute(model, primitive, kUvAttribute, 1, count, what, path);
    int num_uvs = ReadInt(mesh.extras, "artex_num_uvs", -1);
    if (num_uvs > static_cast<long long>(count)) {
      Fail(path, what + ": extras.artex_num_uvs: expected at most " + std::to_string(count) +
                     " (the glTF vertex count), found " + std::to_string(num_uvs));
    }
    if (num_uvs <= 0) {
      num_uvs = 0;
      for (size_t i = 0; i < count; ++i) {
        const int uv = ToIndex(uv_ids.values[i], -1, static_cast<int>(count) - 1,
                               what + " attribute " + kUvAttribute, i, path);
        num_uvs = std::max(num_uvs, uv + 1);
      }
    }
    tmpl.uvs = Eigen::MatrixX2d::Zero(num_uvs, 2);
    std::vector<int> uv_of_vertex(count);
    for (size_t i = 0; i < count; ++i) {
      const int uv = ToIndex(uv_ids.values[i], -1, num_uvs - 1,
                             what + " attribute " + kUvAttribute, i, path);
      uv_of_vertex[i] = uv;
      if (uv >= 0) tmpl.uvs.row(uv) << texcoords.at(i, 0), texcoords.at(i, 1);
    }
    tmpl.uv_triangles.resize(num_triangles, 3);
    for (int f = 0; f < num_triangles; ++f) {
      for (int c = 0; c < 3; ++c) {
        const int uv = uv_of_vertex[indices[3 * f + c]];
        if (uv < 0) {
          Fail(path, what + ": triangle " + std::to_string(f) + " uses a vertex without UV (" +
                         std::string(kUvAttribute) + " = -1)");
        }
        tmpl.uv_triangles(f, c) = uv;
      }
    }
  }

  const int chart_accessor = ReadInt(mesh.extras, "artex_triangle_chart_accessor", -1);
  if (chart_accessor >= 0) {
    const AccessorValues charts = ReadAccessor(model, chart_accessor, what + " triangle charts",
                                               path);
    if (charts.count != static_cast<size_t>(num_triangles) || charts.components != 1) {
      Fail(path, what + ": triangle chart accessor: expected " + std::to_string(num_triangles) +
                     " scalars, found " + std::to_string(charts.count));
    }
    tmpl.triangle_chart.resize(num_triangles);
    for (int f = 0; f < num_triangles; ++f) {
      tmpl.triangle_chart[f] = ToIndex(charts.values[f], -1, std::numeric_limits<int>::max(),
                                       what + " triangle charts", f, path);
    }
  }

  if (texture != nullptr) ReadTexture(model, primitive, texture);
  std::string error;
  if (!tmpl.IsValid(&error)) Fail(path, error);
  return tmpl;
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

bool AnimatedGlbOptions::IsValid(std::string* error) const {
  return corrective.IsValid(error);
}

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
  std::vector<float> displacement(3 * pairs.size());
  double lbs_sum = 0.0, exact_sum = 0.0;
  long long count = 0;
  for (std::size_t f = 0; f < poses.size(); ++f) {
    if (poses[f].num_joints() != tmpl.num_joints() || !poses[f].AllFinite()) {
      break;  // BuildModel reports the bad pose
    }
    Eigen::MatrixX3d artex_positions, lbs_positions;
    skinning.Apply(poses[f], &artex_positions);
    GltfSkinnedPositions(tmpl, poses[f], nullptr, &lbs_positions);
    const Eigen::VectorXd lbs_error = (lbs_positions - artex_positions).rowwise().norm();
    s.lbs_max_residual_mm = std::max(s.lbs_max_residual_mm, 1e3 * lbs_error.maxCoeff());
    lbs_sum += lbs_error.sum();
    count += lbs_error.size();
    if (!options.exact) continue;
    Eigen::MatrixX3d offsets;
    GltfCorrectiveStats stats;
    GltfCorrectiveOffsets(tmpl, poses[f], artex_positions, options.corrective, &offsets, &stats);
    s.singular_vertices += stats.singular_vertices;
    // The residual of what the file holds: offsets rounded to float as written.
    const Eigen::MatrixX3f stored = offsets.cast<float>();
    Eigen::MatrixX3d exact_positions;
    const Eigen::MatrixX3d stored_d = stored.cast<double>();
    GltfSkinnedPositions(tmpl, poses[f], &stored_d, &exact_positions);
    const Eigen::VectorXd exact_error = (exact_positions - artex_positions).rowwise().norm();
    s.exact_max_residual_mm = std::max(s.exact_max_residual_mm, 1e3 * exact_error.maxCoeff());
    exact_sum += exact_error.sum();
    Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::infinity());
    Eigen::Vector3f hi = -lo;
    for (std::size_t i = 0; i < pairs.size(); ++i) {
      const Eigen::Vector3f d = stored.row(pairs[i].first).transpose();
      lo = lo.cwiseMin(d);
      hi = hi.cwiseMax(d);
      for (int c = 0; c < 3; ++c) displacement[3 * i + c] = d[c];
    }
    layout.min.push_back(lo);
    layout.max.push_back(hi);
    if (std::fwrite(displacement.data(), sizeof(float), displacement.size(), spill.get()) !=
        displacement.size()) {
      throw Error("cannot write the morph targets to a temporary file (disk full?)");
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

void WriteAnimatedGlb(const std::string& path, const Template& tmpl,
                      const std::vector<Pose>& poses, double frame_rate, const GlbTexture* texture,
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

void WriteAnimatedGlb(const std::string& path, const Template& tmpl,
                      const std::vector<Pose>& poses, double frame_rate,
                      const GlbTexture* texture) {
  std::string bytes;
  try {
    bytes = EncodeAnimatedGlb(tmpl, poses, frame_rate, texture);
  } catch (const Error& e) {
    Fail(path, e.what());
  }
  WriteFileAtomically(path, bytes);
}

Template ReadTemplateGlb(const std::string& path, GlbTexture* texture,
                         const GlbReadOptions& options) {
  return WithFileContext(path, [&] {
    const std::string bytes = ReadFileBytes(path);
    if (bytes.size() < 4 || ReadU32(bytes, 0) != kGlbMagic) {
      Fail(path, "not a glTF binary (.glb): magic 'glTF' missing");
    }
    const tinygltf::Model model = LoadModel(path, bytes, options);
    return ParseArtexTemplate(model, path, texture, options);
  });
}

Template ImportGltfSkinnedMesh(const std::string& path, const GltfImportOptions& options,
                               VertexJointWeights* lbs_weights) {
  const std::string bytes = ReadFileBytes(path);
  const tinygltf::Model model = LoadModel(path, bytes, options.read);
  const std::vector<int> node_parent = NodeParents(model, path);
  const int mesh_node = FindSkinnedMeshNode(model, path);
  const tinygltf::Mesh& mesh = model.meshes[model.nodes[mesh_node].mesh];
  const tinygltf::Skin& skin = model.skins[model.nodes[mesh_node].skin];
  const int num_skin_joints = static_cast<int>(skin.joints.size());
  if (num_skin_joints == 0) Fail(path, "skin '" + skin.name + "' has no joints");
  std::unordered_map<int, int> skin_index_of_node;
  for (int i = 0; i < num_skin_joints; ++i) {
    const int node = skin.joints[i];
    if (node < 0 || node >= static_cast<int>(model.nodes.size())) {
      Fail(path, "skin '" + skin.name + "': joint node index out of range");
    }
    if (!skin_index_of_node.emplace(node, i).second) {
      Fail(path, "skin '" + skin.name + "': node " + std::to_string(node) + " listed twice");
    }
  }
  const std::vector<Eigen::Matrix4d> world = WorldTransforms(model, node_parent, path);

  // Joint tree over the skin joints (nearest skin-joint ancestor), one root, pre-order.
  std::vector<int> skin_parent(num_skin_joints, -1);
  std::vector<int> roots;
  const std::vector<int> nearest_skin = NearestSkinAncestor(node_parent, skin_index_of_node);
  for (int i = 0; i < num_skin_joints; ++i) {
    skin_parent[i] = nearest_skin[skin.joints[i]];
    if (skin_parent[i] < 0) roots.push_back(i);
  }
  if (roots.size() != 1) {
    std::string names;
    for (int r : roots) names += (names.empty() ? "" : ", ") + model.nodes[skin.joints[r]].name;
    Fail(path, "skin '" + skin.name + "': expected one root joint, found " +
                   std::to_string(roots.size()) + " (" + names + ")");
  }
  std::vector<std::vector<int>> skin_children(num_skin_joints);
  for (int i = 0; i < num_skin_joints; ++i) {
    if (skin_parent[i] >= 0) skin_children[skin_parent[i]].push_back(i);
  }
  std::vector<int> order;  // artex joint -> skin joint
  std::vector<int> stack = {roots[0]};
  while (!stack.empty()) {
    const int i = stack.back();
    stack.pop_back();
    order.push_back(i);
    for (auto it = skin_children[i].rbegin(); it != skin_children[i].rend(); ++it) {
      stack.push_back(*it);
    }
  }
  std::vector<int> artex_of_skin(num_skin_joints, -1);
  for (size_t j = 0; j < order.size(); ++j) artex_of_skin[order[j]] = static_cast<int>(j);
  Template tmpl;
  tmpl.joints.resize(num_skin_joints);
  for (int j = 0; j < num_skin_joints; ++j) {
    const int s = order[j];
    const int node = skin.joints[s];
    Joint& joint = tmpl.joints[j];
    joint.name = model.nodes[node].name.empty() ? "joint_" + std::to_string(s)
                                                : model.nodes[node].name;
    joint.parent = skin_parent[s] >= 0 ? artex_of_skin[skin_parent[s]] : -1;
    joint.center = world[node].block<3, 1>(0, 3);
  }
  AssignDefaultTwistAxes(&tmpl.joints);

  // Skinning matrices of the rest (default scene) pose.
  std::vector<Eigen::Matrix4d> skin_matrix(num_skin_joints);
  std::vector<Eigen::Matrix4d> inverse_bind(num_skin_joints, Eigen::Matrix4d::Identity());
  if (skin.inverseBindMatrices >= 0) {
    const AccessorValues ibm =
        ReadAccessor(model, skin.inverseBindMatrices, "skin inverseBindMatrices", path);
    if (ibm.components != 16 || ibm.count != static_cast<size_t>(num_skin_joints)) {
      Fail(path, "skin inverseBindMatrices: expected " + std::to_string(num_skin_joints) +
                     " MAT4 entries");
    }
    for (int i = 0; i < num_skin_joints; ++i) {
      for (int k = 0; k < 16; ++k) inverse_bind[i](k % 4, k / 4) = ibm.at(i, k);
      if (!inverse_bind[i].allFinite()) Fail(path, "skin inverseBindMatrices: non-finite entry");
    }
  }
  for (int i = 0; i < num_skin_joints; ++i) skin_matrix[i] = world[skin.joints[i]] * inverse_bind[i];

  // Gather all triangle primitives.
  std::vector<Eigen::Vector3d> positions;
  std::vector<Eigen::Vector2d> texcoords;
  std::vector<std::vector<JointWeight>> weights;
  std::vector<int> corners;
  bool all_uvs = true;
  for (size_t p = 0; p < mesh.primitives.size(); ++p) {
    const tinygltf::Primitive& primitive = mesh.primitives[p];
    const std::string what = "mesh '" + mesh.name + "' primitive " + std::to_string(p);
    if (primitive.mode != -1 && primitive.mode != TINYGLTF_MODE_TRIANGLES) continue;
    auto position_it = primitive.attributes.find("POSITION");
    if (position_it == primitive.attributes.end()) Fail(path, what + ": missing attribute POSITION");
    const size_t count = ReadAccessor(model, position_it->second, what + " POSITION", path).count;
    const AccessorValues pos = ReadAttribute(model, primitive, "POSITION", 3, count, what, path);
    const std::vector<std::vector<JointWeight>> w = ReadSkinWeights(
        model, primitive, count, num_skin_joints, options.read.weight_sum_tolerance, what, path);
    const bool has_uv = primitive.attributes.count("TEXCOORD_0") > 0;
    AccessorValues uv;
    if (has_uv) uv = ReadAttribute(model, primitive, "TEXCOORD_0", 2, count, what, path);
    all_uvs = all_uvs && has_uv;
    const std::vector<int> indices = ReadIndices(model, primitive, count, what, path);
    const int base = static_cast<int>(positions.size());
    for (size_t v = 0; v < count; ++v) {
      const Eigen::Vector4d x(pos.at(v, 0), pos.at(v, 1), pos.at(v, 2), 1.0);
      Eigen::Vector4d rest = Eigen::Vector4d::Zero();
      double total = 0.0;
      for (const JointWeight& jw : w[v]) total += jw.weight;
      std::vector<JointWeight> merged;
      for (const JointWeight& jw : w[v]) {
        rest += (jw.weight / total) * (skin_matrix[jw.joint] * x);
        const int artex_joint = artex_of_skin[jw.joint];
        auto it = std::find_if(merged.begin(), merged.end(),
                               [artex_joint](const JointWeight& m) { return m.joint == artex_joint; });
        if (it != merged.end()) {
          it->weight += jw.weight;
        } else {
          merged.push_back({artex_joint, jw.weight});
        }
      }
      positions.push_back(rest.head<3>());
      texcoords.push_back(has_uv ? Eigen::Vector2d(uv.at(v, 0), uv.at(v, 1))
                                 : Eigen::Vector2d::Zero());
      weights.push_back(merged);
    }
    for (int index : indices) corners.push_back(base + index);
  }
  if (corners.empty()) Fail(path, "mesh '" + mesh.name + "': no triangles");

  // Weld seam copies (identical rest positions) into template vertices.
  const int num_gltf_vertices = static_cast<int>(positions.size());
  std::vector<int> template_vertex(num_gltf_vertices);
  std::vector<int> representative;
  if (options.weld_identical_positions) {
    std::map<std::tuple<double, double, double>, int> seen;
    for (int i = 0; i < num_gltf_vertices; ++i) {
      const auto key = std::make_tuple(positions[i].x(), positions[i].y(), positions[i].z());
      auto [it, inserted] = seen.emplace(key, static_cast<int>(representative.size()));
      if (inserted) representative.push_back(i);
      template_vertex[i] = it->second;
    }
  } else {
    for (int i = 0; i < num_gltf_vertices; ++i) {
      template_vertex[i] = i;
      representative.push_back(i);
    }
  }
  const int num_vertices = static_cast<int>(representative.size());
  tmpl.vertices.resize(num_vertices, 3);
  VertexJointWeights vertex_weights(num_vertices);
  for (int v = 0; v < num_vertices; ++v) {
    tmpl.vertices.row(v) = positions[representative[v]].transpose();
    double total = 0.0;
    for (const JointWeight& jw : weights[representative[v]]) {
      if (jw.weight >= options.min_joint_weight) {
        vertex_weights[v].push_back(jw);
        total += jw.weight;
      }
    }
    if (!(total > 0.0)) {
      Fail(path, "vertex " + std::to_string(representative[v]) +
                     ": no skin weight above min_joint_weight");
    }
    for (JointWeight& jw : vertex_weights[v]) jw.weight /= total;
  }
  std::vector<int> kept;
  for (size_t f = 0; f + 2 < corners.size(); f += 3) {
    const int a = template_vertex[corners[f]], b = template_vertex[corners[f + 1]],
              c = template_vertex[corners[f + 2]];
    if (a != b && b != c && a != c) kept.push_back(static_cast<int>(f));
  }
  if (kept.empty()) Fail(path, "mesh '" + mesh.name + "': only degenerate triangles");
  tmpl.triangles.resize(static_cast<int>(kept.size()), 3);
  if (all_uvs) {
    tmpl.uvs.resize(num_gltf_vertices, 2);
    for (int i = 0; i < num_gltf_vertices; ++i) tmpl.uvs.row(i) = texcoords[i].transpose();
    tmpl.uv_triangles.resize(static_cast<int>(kept.size()), 3);
  }
  for (size_t t = 0; t < kept.size(); ++t) {
    for (int c = 0; c < 3; ++c) {
      tmpl.triangles(static_cast<int>(t), c) = template_vertex[corners[kept[t] + c]];
      if (all_uvs) tmpl.uv_triangles(static_cast<int>(t), c) = corners[kept[t] + c];
    }
  }
  if (all_uvs) tmpl.triangle_chart = UvIslands(tmpl.triangles, tmpl.uv_triangles);

  LbsConversionOptions conversion;
  conversion.min_weight = options.min_joint_weight;
  try {
    ConvertLbsWeights(tmpl.joints, vertex_weights, conversion, &tmpl.vertex_joint,
                      &tmpl.lbs_weight, &tmpl.slerp_tau);
  } catch (const Error& e) {
    Fail(path, e.what());
  }
  std::string error;
  if (!tmpl.IsValid(&error)) Fail(path, error);
  if (lbs_weights != nullptr) *lbs_weights = std::move(vertex_weights);
  return tmpl;
}

}  // namespace artex

namespace artex {

TemplateSummary SummarizeTemplate(const Template& tmpl, const TemplateSummaryOptions& options) {
  std::string error;
  if (!tmpl.IsValid(&error)) throw Error("template: " + error);
  if (options.uv_grid < 16) {
    throw Error("TemplateSummaryOptions.uv_grid: expected at least 16, found " +
                std::to_string(options.uv_grid));
  }
  TemplateSummary s;
  s.num_vertices = tmpl.num_vertices();
  s.num_triangles = tmpl.num_triangles();
  s.num_joints = tmpl.num_joints();
  s.num_pose_parameters = tmpl.num_pose_parameters();
  s.vertices_per_joint.assign(s.num_joints, 0);
  for (int v = 0; v < s.num_vertices; ++v) ++s.vertices_per_joint[tmpl.vertex_joint[v]];
  s.bbox_min = tmpl.vertices.colwise().minCoeff().transpose();
  s.bbox_max = tmpl.vertices.colwise().maxCoeff().transpose();

  // Edges: undirected incidence counts and directed duplicates.
  std::vector<std::pair<int, int>> directed;
  directed.reserve(static_cast<size_t>(s.num_triangles) * 3);
  for (int f = 0; f < s.num_triangles; ++f) {
    for (int c = 0; c < 3; ++c) directed.emplace_back(tmpl.triangles(f, c), tmpl.triangles(f, (c + 1) % 3));
  }
  std::vector<std::pair<int, int>> undirected(directed.size());
  for (size_t i = 0; i < directed.size(); ++i) {
    undirected[i] = {std::min(directed[i].first, directed[i].second),
                     std::max(directed[i].first, directed[i].second)};
  }
  std::sort(directed.begin(), directed.end());
  std::sort(undirected.begin(), undirected.end());
  int num_edges = 0;
  for (size_t i = 0; i < undirected.size();) {
    size_t j = i;
    while (j < undirected.size() && undirected[j] == undirected[i]) ++j;
    const size_t count = j - i;
    ++num_edges;
    if (count == 1) ++s.boundary_edges;
    if (count > 2) ++s.non_manifold_edges;
    i = j;
  }
  for (size_t i = 1; i < directed.size(); ++i) {
    if (directed[i] == directed[i - 1]) ++s.misoriented_edges;
  }

  // Components over referenced vertices (union-find).
  std::vector<int> parent(s.num_vertices);
  for (int v = 0; v < s.num_vertices; ++v) parent[v] = v;
  auto find = [&parent](int x) {
    while (parent[x] != x) {
      parent[x] = parent[parent[x]];
      x = parent[x];
    }
    return x;
  };
  std::vector<char> referenced(s.num_vertices, 0);
  for (int f = 0; f < s.num_triangles; ++f) {
    for (int c = 0; c < 3; ++c) {
      referenced[tmpl.triangles(f, c)] = 1;
      const int a = find(tmpl.triangles(f, c)), b = find(tmpl.triangles(f, (c + 1) % 3));
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
  }
  int num_referenced = 0;
  for (int v = 0; v < s.num_vertices; ++v) {
    if (!referenced[v]) {
      ++s.unreferenced_vertices;
      continue;
    }
    ++num_referenced;
    if (find(v) == v) ++s.components;
  }
  s.euler_characteristic = num_referenced - num_edges + s.num_triangles;

  if (tmpl.has_uvs()) {
    s.num_uvs = static_cast<int>(tmpl.uvs.rows());
    // Rasterise UV triangles: cell centres inside a triangle (inclusive edges) are covered.
    const int n = options.uv_grid;
    std::vector<unsigned char> count(static_cast<size_t>(n) * n, 0);
    for (int f = 0; f < s.num_triangles; ++f) {
      Eigen::Vector2d p[3];
      for (int c = 0; c < 3; ++c) p[c] = tmpl.uvs.row(tmpl.uv_triangles(f, c)).transpose() * n;
      const double area = (p[1] - p[0]).x() * (p[2] - p[0]).y() - (p[1] - p[0]).y() * (p[2] - p[0]).x();
      if (area == 0.0) continue;
      const int x0 = std::max(0, static_cast<int>(std::floor(std::min({p[0].x(), p[1].x(), p[2].x()}))));
      const int x1 = std::min(n - 1, static_cast<int>(std::ceil(std::max({p[0].x(), p[1].x(), p[2].x()}))));
      const int y0 = std::max(0, static_cast<int>(std::floor(std::min({p[0].y(), p[1].y(), p[2].y()}))));
      const int y1 = std::min(n - 1, static_cast<int>(std::ceil(std::max({p[0].y(), p[1].y(), p[2].y()}))));
      const double sign = area > 0.0 ? 1.0 : -1.0;
      for (int y = y0; y <= y1; ++y) {
        for (int x = x0; x <= x1; ++x) {
          const Eigen::Vector2d q(x + 0.5, y + 0.5);
          bool inside = true;
          for (int c = 0; c < 3 && inside; ++c) {
            const Eigen::Vector2d e = p[(c + 1) % 3] - p[c], d = q - p[c];
            inside = sign * (e.x() * d.y() - e.y() * d.x()) >= 0.0;
          }
          if (inside) {
            unsigned char& cell = count[static_cast<size_t>(y) * n + x];
            if (cell < 255) ++cell;
          }
        }
      }
    }
    size_t covered = 0, multiple = 0;
    for (unsigned char c : count) {
      covered += c > 0;
      multiple += c > 1;
    }
    s.uv_coverage = static_cast<double>(covered) / (static_cast<double>(n) * n);
    s.uv_overlap = covered > 0 ? static_cast<double>(multiple) / covered : 0.0;
  }
  if (tmpl.triangle_chart.size() == s.num_triangles && s.num_triangles > 0) {
    std::vector<int> charts(tmpl.triangle_chart.data(),
                            tmpl.triangle_chart.data() + tmpl.triangle_chart.size());
    std::sort(charts.begin(), charts.end());
    s.num_charts = static_cast<int>(std::unique(charts.begin(), charts.end()) - charts.begin());
  }
  return s;
}

}  // namespace artex
