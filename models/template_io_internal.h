// Internal to models/template_io.cc, template_read.cc and gltf_import.cc: what they share; not API.
#pragma once

#include <tiny_gltf.h>

#include <Eigen/Core>
#include <cstdint>
#include <cstring>
#include <string>
#include <unordered_map>
#include <vector>

#include "models/error.h"
#include "models/template_io.h"

namespace artex {
namespace template_io_internal {

// Names of the artex-specific parts of the format (docs/formats-template.md).
constexpr char kVertexAttribute[] = "_ARTEX_VERTEX";
constexpr char kUvAttribute[] = "_ARTEX_UV";
constexpr char kJointAttribute[] = "_ARTEX_JOINT";
constexpr char kLbsAttribute[] = "_ARTEX_LBS_WEIGHT";
constexpr char kTauAttribute[] = "_ARTEX_SLERP_TAU";

[[noreturn]] inline void Fail(const std::string& where, const std::string& what) {
  throw Error(where + ": " + what);
}

inline uint32_t ReadU32(const std::string& bytes, size_t offset) {
  uint32_t v = 0;
  std::memcpy(&v, bytes.data() + offset, 4);
  return v;  // little endian host (x86-64 / aarch64)
}

inline bool LooksLikePng(const std::vector<unsigned char>& bytes) {
  static const unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  return bytes.size() >= 8 && std::memcmp(bytes.data(), kSignature, 8) == 0;
}

// The bytes of the file at `path`; throws (naming `path`) when it is missing or unreadable.
std::string ReadFileBytes(const std::string& path);

// Parses `bytes` (GLB, or glTF JSON with embedded buffers) read from `path`, after checking the
// GLB container and the JSON nesting depth; images are kept encoded.
tinygltf::Model LoadModel(const std::string& path, const std::string& bytes,
                          const GlbReadOptions& options);

// Accessor contents as doubles (count x components), with bounds checks.
struct AccessorValues {
  size_t count = 0;
  int components = 0;
  std::vector<double> values;
  double at(size_t i, int c) const { return values[i * components + c]; }
};

AccessorValues ReadAccessor(const tinygltf::Model& model, int index, const std::string& what,
                            const std::string& path);

// Reads a vertex attribute, checking count, components and finiteness.
AccessorValues ReadAttribute(const tinygltf::Model& model, const tinygltf::Primitive& primitive,
                             const std::string& name, int components, size_t count,
                             const std::string& what, const std::string& path);

// Parent node of every node; throws on out-of-range children, a node with two parents or a
// cycle.
std::vector<int> NodeParents(const tinygltf::Model& model, const std::string& path);

// For every node, the nearest proper ancestor that is a skin joint (its skin index), or -1.
std::vector<int> NearestSkinAncestor(const std::vector<int>& parent,
                                     const std::unordered_map<int, int>& skin_index_of_node);

// Every node's world transform: its matrix or TRS composed with its ancestors' (`parent` from
// NodeParents).
std::vector<Eigen::Matrix4d> WorldTransforms(const tinygltf::Model& model,
                                             const std::vector<int>& parent,
                                             const std::string& path);

// The first node with a mesh and a skin.
int FindSkinnedMeshNode(const tinygltf::Model& model, const std::string& path);

// A triangle primitive's vertex indices (0 .. num_vertices - 1, three per triangle).
std::vector<int> ReadIndices(const tinygltf::Model& model, const tinygltf::Primitive& primitive,
                             size_t num_vertices, const std::string& what, const std::string& path);

// Per-vertex (skin joint, weight) lists from JOINTS_n / WEIGHTS_n, checking the sums.
std::vector<std::vector<JointWeight>> ReadSkinWeights(const tinygltf::Model& model,
                                                      const tinygltf::Primitive& primitive,
                                                      size_t count, int num_skin_joints,
                                                      double tolerance, const std::string& what,
                                                      const std::string& path);

}  // namespace template_io_internal
}  // namespace artex
