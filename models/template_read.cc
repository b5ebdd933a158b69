// ReadTemplateGlb (models/template_io.h) and the checked glTF reading it shares with the importer.
#include <tiny_gltf.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "models/error.h"
#include "models/file_context.h"
#include "models/makehuman_import.h"
#include "models/template_io.h"
#include "models/template_io_internal.h"

namespace artex {
namespace template_io_internal {
namespace {

constexpr uint32_t kGlbMagic = 0x46546C67;   // "glTF"
constexpr uint32_t kChunkJson = 0x4E4F534A;  // "JSON"
constexpr uint32_t kChunkBin = 0x004E4942;   // "BIN\0"

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

Eigen::Matrix4d LocalTransform(const tinygltf::Node& node, const std::string& path, int index) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  const std::string what = "node " + std::to_string(index) + " ('" + node.name + "')";
  if (node.matrix.size() == 16) {
    for (int i = 0; i < 16; ++i) m(i % 4, i / 4) = node.matrix[i];
  } else {
    Eigen::Vector3d t = Eigen::Vector3d::Zero(), s = Eigen::Vector3d::Ones();
    Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
    if (node.translation.size() == 3)
      t = {node.translation[0], node.translation[1], node.translation[2]};
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

}  // namespace

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
    if (accessor.count > view.byteLength || accessor.byteOffset > view.byteLength ||
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
          Fail(path,
               what + ": unsupported componentType " + std::to_string(accessor.componentType));
      }
      out.values[i * components + c] = value;
    }
  }
  return out;
}

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
    Fail(path,
         what + ": expected triangles (mode 4), found mode " + std::to_string(primitive.mode));
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
    Fail(path,
         what + ": index count " + std::to_string(indices.size()) + " is not a multiple of 3");
  }
  return indices;
}

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
      Fail(path, what + ": skin weights (WEIGHTS_n) of vertex " + std::to_string(v) + " sum to " +
                     ErrorNumber(sums[v]) + ", expected 1");
    }
  }
  return out;
}

namespace {

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
  const AccessorValues positions =
      ReadAttribute(model, primitive, "POSITION", 3, count, what, path);
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
        Fail(path, "joint '" + tmpl.joints[j].name +
                       "': artex_twist_axis must be a finite "
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

  const bool has_uvs =
      primitive.attributes.count("TEXCOORD_0") > 0 && primitive.attributes.count(kUvAttribute) > 0;
  if (has_uvs) {
    const AccessorValues texcoords =
        ReadAttribute(model, primitive, "TEXCOORD_0", 2, count, what, path);
    const AccessorValues uv_ids =
        ReadAttribute(model, primitive, kUvAttribute, 1, count, what, path);
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
      const int uv =
          ToIndex(uv_ids.values[i], -1, num_uvs - 1, what + " attribute " + kUvAttribute, i, path);
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
    const AccessorValues charts =
        ReadAccessor(model, chart_accessor, what + " triangle charts", path);
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
}  // namespace template_io_internal

using template_io_internal::Fail;
using template_io_internal::kGlbMagic;
using template_io_internal::LoadModel;
using template_io_internal::ParseArtexTemplate;
using template_io_internal::ReadFileBytes;
using template_io_internal::ReadU32;

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

}  // namespace artex
