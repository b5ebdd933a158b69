// ImportGltfSkinnedMesh (models/template_io.h): any skinned glTF 2.0 mesh as an artex template.
#include <tiny_gltf.h>

#include <Eigen/Core>
#include <algorithm>
#include <map>
#include <string>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

#include "models/error.h"
#include "models/makehuman_import.h"
#include "models/template_io.h"
#include "models/template_io_internal.h"

namespace artex {

using template_io_internal::AccessorValues;
using template_io_internal::Fail;
using template_io_internal::FindSkinnedMeshNode;
using template_io_internal::LoadModel;
using template_io_internal::NearestSkinAncestor;
using template_io_internal::NodeParents;
using template_io_internal::ReadAccessor;
using template_io_internal::ReadAttribute;
using template_io_internal::ReadFileBytes;
using template_io_internal::ReadIndices;
using template_io_internal::ReadSkinWeights;
using template_io_internal::WorldTransforms;

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
    joint.name =
        model.nodes[node].name.empty() ? "joint_" + std::to_string(s) : model.nodes[node].name;
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
  for (int i = 0; i < num_skin_joints; ++i)
    skin_matrix[i] = world[skin.joints[i]] * inverse_bind[i];

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
    if (position_it == primitive.attributes.end())
      Fail(path, what + ": missing attribute POSITION");
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
        auto it = std::find_if(merged.begin(), merged.end(), [artex_joint](const JointWeight& m) {
          return m.joint == artex_joint;
        });
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
    ConvertLbsWeights(tmpl.joints, vertex_weights, conversion, &tmpl.vertex_joint, &tmpl.lbs_weight,
                      &tmpl.slerp_tau);
  } catch (const Error& e) {
    Fail(path, e.what());
  }
  std::string error;
  if (!tmpl.IsValid(&error)) Fail(path, error);
  if (lbs_weights != nullptr) *lbs_weights = std::move(vertex_weights);
  return tmpl;
}

}  // namespace artex
