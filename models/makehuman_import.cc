#include "models/makehuman_import.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>
#include <tuple>
#include <unordered_map>

#include <nlohmann/json.hpp>

#include "models/error.h"

namespace artex {
namespace {

// ------------------------------------------------------------------------------------------
// OBJ parsing helpers.

[[noreturn]] void ObjFail(const std::string& path, int line, const std::string& what) {
  throw Error(path + ":" + std::to_string(line) + ": " + what);
}

double ParseDouble(const std::string& token, const std::string& path, int line) {
  const char* begin = token.c_str();
  char* end = nullptr;
  errno = 0;
  const double value = std::strtod(begin, &end);
  if (end == begin || *end != '\0' || errno == ERANGE || !std::isfinite(value)) {
    ObjFail(path, line, "expected a finite number, found '" + token + "'");
  }
  return value;
}

long ParseIndex(const std::string& token, const std::string& path, int line) {
  const char* begin = token.c_str();
  char* end = nullptr;
  errno = 0;
  const long value = std::strtol(begin, &end, 10);
  if (end == begin || *end != '\0' || errno == ERANGE) {
    ObjFail(path, line, "expected an integer index, found '" + token + "'");
  }
  if (value == 0) ObjFail(path, line, "OBJ indices start at 1, found 0");
  return value;
}

// Resolves a 1-based (or negative, relative) OBJ index against `count` elements seen so far.
int ResolveIndex(long index, size_t count, const char* kind, const std::string& path, int line) {
  const long resolved = index > 0 ? index - 1 : static_cast<long>(count) + index;
  if (resolved < 0 || resolved >= static_cast<long>(count)) {
    ObjFail(path, line, std::string(kind) + " index " + std::to_string(index) +
                            " out of range (" + std::to_string(count) + " defined so far)");
  }
  return static_cast<int>(resolved);
}

// ------------------------------------------------------------------------------------------
// JSON helpers.

nlohmann::json ReadJson(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw Error(path + ": cannot open (no such file or not readable)");
  try {
    return nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw Error(path + ": malformed JSON: " + e.what());
  }
}

Eigen::Vector3d JsonVector3(const nlohmann::json& value, const std::string& path,
                            const std::string& field) {
  if (!value.is_array() || value.size() != 3) {
    throw Error(path + ": " + field + ": expected an array of 3 numbers");
  }
  Eigen::Vector3d v;
  for (int c = 0; c < 3; ++c) {
    if (!value[c].is_number()) throw Error(path + ": " + field + ": expected numbers");
    v[c] = value[c].get<double>();
  }
  if (!v.allFinite()) throw Error(path + ": " + field + ": non-finite value");
  return v;
}

// object[key] as text ("" when absent); an error naming the file and field when not text.
std::string JsonString(const nlohmann::json& object, const char* key, const std::string& path,
                       const std::string& field) {
  if (!object.contains(key)) return std::string();
  const nlohmann::json& value = object[key];
  if (!value.is_string()) {
    throw Error(path + ": " + field + "." + key + ": expected text, found " +
                std::string(value.type_name()));
  }
  return value.get<std::string>();
}

// A vertex index (an integer that fits an int; the caller checks the range).
int JsonIndex(const nlohmann::json& value, const std::string& path, const std::string& field) {
  if (!value.is_number_integer() || value.get<long long>() < 0 ||
      value.get<long long>() > std::numeric_limits<int>::max()) {
    throw Error(path + ": " + field + ": expected a vertex index, found " + value.dump());
  }
  return static_cast<int>(value.get<long long>());
}

}  // namespace

// ------------------------------------------------------------------------------------------

void ConvertLbsWeights(const std::vector<Joint>& joints, const VertexJointWeights& weights,
                       const LbsConversionOptions& options, Eigen::VectorXi* vertex_joint,
                       Eigen::VectorXd* lbs_weight, Eigen::VectorXd* slerp_tau) {
  if (!(options.min_weight >= 0.0 && options.min_weight < 1.0)) {
    throw Error("LbsConversionOptions.min_weight: expected a value in [0, 1), found " +
                ErrorNumber(options.min_weight));
  }
  const int num_joints = static_cast<int>(joints.size());
  const int n = static_cast<int>(weights.size());
  vertex_joint->resize(n);
  lbs_weight->resize(n);
  slerp_tau->resize(n);
  std::vector<double> w(num_joints, 0.0);
  for (int v = 0; v < n; ++v) {
    std::vector<int> used;
    for (const JointWeight& jw : weights[v]) {
      if (jw.joint < 0 || jw.joint >= num_joints) {
        throw Error("skin weights of vertex " + std::to_string(v) + ": joint index " +
                    std::to_string(jw.joint) + " outside [0, " + std::to_string(num_joints) +
                    ")");
      }
      if (!std::isfinite(jw.weight) || jw.weight < 0.0) {
        throw Error("skin weights of vertex " + std::to_string(v) +
                    ": expected finite non-negative weights, found " + ErrorNumber(jw.weight));
      }
      if (w[jw.joint] == 0.0 && jw.weight > 0.0) used.push_back(jw.joint);
      w[jw.joint] += jw.weight;
    }
    double total = 0.0;
    for (int j : used) total += w[j];
    int best = -1;
    double best_score = -1.0, best_own = -1.0;
    for (int c : used) {
      if (w[c] < options.min_weight * total) continue;
      const int p = joints[c].parent;
      const double own = w[c];
      const double parent = p >= 0 && w[p] >= options.min_weight * total ? w[p] : 0.0;
      const double score = own + parent;
      if (score > best_score || (score == best_score && own > best_own) ||
          (score == best_score && own == best_own && c < best)) {
        best = c;
        best_score = score;
        best_own = own;
      }
    }
    for (int j : used) w[j] = 0.0;
    if (best < 0 || !(best_score > 0.0)) {
      throw Error("skin weights of vertex " + std::to_string(v) +
                  ": expected at least one positive weight, found none");
    }
    (*vertex_joint)[v] = best;
    (*lbs_weight)[v] = std::clamp(best_own / best_score, 0.0, 1.0);
    (*slerp_tau)[v] = (*lbs_weight)[v];
  }
}

void AssignDefaultTwistAxes(std::vector<Joint>* joints_ptr) {
  std::vector<Joint>& joints = *joints_ptr;
  const int n = static_cast<int>(joints.size());
  std::vector<std::vector<int>> children(n);
  for (int j = 0; j < n; ++j) {
    if (joints[j].parent >= 0 && joints[j].parent < n) children[joints[j].parent].push_back(j);
  }
  // Subtree sizes (children after parents is not assumed: iterate to a fixed point).
  std::vector<int> subtree(n, 1);
  for (int pass = 0; pass < n; ++pass) {
    bool changed = false;
    for (int j = 0; j < n; ++j) {
      int size = 1;
      for (int c : children[j]) size += subtree[c];
      if (size != subtree[j]) {
        subtree[j] = size;
        changed = true;
      }
    }
    if (!changed) break;
  }
  for (int j = 0; j < n; ++j) {
    Joint& joint = joints[j];
    const bool has_parent = joint.parent >= 0 && joint.parent < n;
    const Eigen::Vector3d incoming =
        has_parent ? Eigen::Vector3d(joint.center - joints[joint.parent].center)
                   : Eigen::Vector3d::Zero();
    Eigen::Vector3d axis = Eigen::Vector3d::Zero();
    if (children[j].size() == 1) {
      axis = joints[children[j][0]].center - joint.center;
    } else if (children[j].size() > 1) {
      int chosen = children[j][0];
      double best = -std::numeric_limits<double>::infinity();
      for (int c : children[j]) {
        const Eigen::Vector3d d = joints[c].center - joint.center;
        double score;
        if (has_parent && incoming.norm() > 0.0 && d.norm() > 0.0) {
          score = incoming.normalized().dot(d.normalized());
        } else {
          score = subtree[c];
        }
        if (score > best) {
          best = score;
          chosen = c;
        }
      }
      axis = joints[chosen].center - joint.center;
    } else {
      axis = incoming;
    }
    joint.twist_axis = axis.norm() > 0.0 && axis.allFinite() ? Eigen::Vector3d(axis.normalized())
                                                             : Eigen::Vector3d::UnitY();
  }
}

Eigen::MatrixX3d PoseLinearBlend(const Template& tmpl, const VertexJointWeights& weights,
                                 const Pose& pose) {
  const int num_joints = tmpl.num_joints();
  if (pose.num_joints() != num_joints) {
    throw Error("pose: expected " + std::to_string(num_joints) + " joint rotations, found " +
                std::to_string(pose.num_joints()));
  }
  if (static_cast<int>(weights.size()) != tmpl.num_vertices()) {
    throw Error("skin weights: expected " + std::to_string(tmpl.num_vertices()) +
                " vertices, found " + std::to_string(weights.size()));
  }
  // Chain transforms x -> m_j x + b_j of T_root o ... o T_j, then the global similarity.
  std::vector<Eigen::Matrix3d> m(num_joints);
  std::vector<Eigen::Vector3d> b(num_joints);
  for (int j = 0; j < num_joints; ++j) {
    const Joint& joint = tmpl.joints[j];
    const Eigen::Matrix3d& r = pose.joint_rotations[j];
    const Eigen::Vector3d local_b = joint.center - r * joint.center;
    if (joint.parent >= 0) {
      m[j] = m[joint.parent] * r;
      b[j] = m[joint.parent] * local_b + b[joint.parent];
    } else {
      m[j] = r;
      b[j] = local_b;
    }
  }
  const Eigen::Matrix3d global = pose.scale * pose.rotation;
  for (int j = 0; j < num_joints; ++j) {
    m[j] = global * m[j];
    b[j] = global * b[j] + pose.translation;
  }
  Eigen::MatrixX3d posed(tmpl.num_vertices(), 3);
  for (int v = 0; v < tmpl.num_vertices(); ++v) {
    const Eigen::Vector3d x = tmpl.vertices.row(v).transpose();
    Eigen::Vector3d y = Eigen::Vector3d::Zero();
    double total = 0.0;
    for (const JointWeight& jw : weights[v]) {
      if (jw.joint < 0 || jw.joint >= num_joints) {
        throw Error("skin weights of vertex " + std::to_string(v) + ": joint index out of range");
      }
      y += jw.weight * (m[jw.joint] * x + b[jw.joint]);
      total += jw.weight;
    }
    if (!(total > 0.0)) {
      throw Error("skin weights of vertex " + std::to_string(v) + ": no positive weight");
    }
    posed.row(v) = (y / total).transpose();
  }
  return posed;
}

Eigen::VectorXi UvIslands(const Eigen::MatrixX3i& triangles,
                          const Eigen::MatrixX3i& uv_triangles) {
  const int f = static_cast<int>(triangles.rows());
  // Union-find over triangles.
  std::vector<int> parent(f);
  for (int i = 0; i < f; ++i) parent[i] = i;
  auto find = [&parent](int x) {
    while (parent[x] != x) {
      parent[x] = parent[parent[x]];
      x = parent[x];
    }
    return x;
  };
  // Edge key: (lower vertex, higher vertex, uv at lower, uv at higher).
  std::vector<std::pair<std::array<int, 4>, int>> edges;
  edges.reserve(static_cast<size_t>(f) * 3);
  for (int t = 0; t < f; ++t) {
    for (int c = 0; c < 3; ++c) {
      int a = triangles(t, c), b = triangles(t, (c + 1) % 3);
      int ua = uv_triangles(t, c), ub = uv_triangles(t, (c + 1) % 3);
      if (a > b) {
        std::swap(a, b);
        std::swap(ua, ub);
      }
      edges.push_back({{a, b, ua, ub}, t});
    }
  }
  std::sort(edges.begin(), edges.end());
  for (size_t i = 1; i < edges.size(); ++i) {
    if (edges[i].first == edges[i - 1].first) {
      const int x = find(edges[i].second), y = find(edges[i - 1].second);
      if (x != y) parent[std::max(x, y)] = std::min(x, y);
    }
  }
  Eigen::VectorXi chart(f);
  std::unordered_map<int, int> label;
  for (int t = 0; t < f; ++t) {
    const int root = find(t);
    auto it = label.emplace(root, static_cast<int>(label.size())).first;
    chart[t] = it->second;
  }
  return chart;
}

ObjMesh ReadObj(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw Error(path + ": cannot open (no such file or not readable)");
  ObjMesh mesh;
  std::string line_text, group = "default";
  int line = 0;
  std::vector<std::string> tokens;
  while (std::getline(in, line_text)) {
    ++line;
    if (!line_text.empty() && line_text.back() == '\r') line_text.pop_back();
    const size_t comment = line_text.find('#');
    if (comment != std::string::npos) line_text.resize(comment);
    std::istringstream stream(line_text);
    tokens.clear();
    for (std::string token; stream >> token;) tokens.push_back(token);
    if (tokens.empty()) continue;
    const std::string& key = tokens[0];
    if (key == "v") {
      if (tokens.size() < 4) ObjFail(path, line, "vertex: expected 3 coordinates");
      mesh.positions.emplace_back(ParseDouble(tokens[1], path, line),
                                  ParseDouble(tokens[2], path, line),
                                  ParseDouble(tokens[3], path, line));
    } else if (key == "vt") {
      if (tokens.size() < 3) ObjFail(path, line, "texture coordinate: expected u and v");
      mesh.texcoords.emplace_back(ParseDouble(tokens[1], path, line),
                                  ParseDouble(tokens[2], path, line));
    } else if (key == "f") {
      if (tokens.size() < 4) {
        ObjFail(path, line, "face: expected at least 3 corners, found " +
                                std::to_string(tokens.size() - 1));
      }
      ObjMesh::Face face;
      face.group = group;
      face.line = line;
      for (size_t i = 1; i < tokens.size(); ++i) {
        const std::string& corner = tokens[i];
        const size_t slash1 = corner.find('/');
        const std::string v_text = corner.substr(0, slash1);
        face.position.push_back(ResolveIndex(ParseIndex(v_text, path, line),
                                             mesh.positions.size(), "vertex", path, line));
        std::string vt_text;
        if (slash1 != std::string::npos) {
          const size_t slash2 = corner.find('/', slash1 + 1);
          vt_text = corner.substr(slash1 + 1, slash2 == std::string::npos
                                                  ? std::string::npos
                                                  : slash2 - slash1 - 1);
        }
        if (!vt_text.empty()) {
          face.texcoord.push_back(ResolveIndex(ParseIndex(vt_text, path, line),
                                               mesh.texcoords.size(), "texture coordinate", path,
                                               line));
        }
      }
      if (!face.texcoord.empty() && face.texcoord.size() != face.position.size()) {
        ObjFail(path, line, "face: texture coordinates given for some corners only");
      }
      mesh.faces.push_back(std::move(face));
    } else if (key == "g" || key == "o") {
      group = tokens.size() > 1 ? tokens[1] : "default";
      for (size_t i = 2; i < tokens.size(); ++i) group += " " + tokens[i];
    }
    // vn, s, usemtl, mtllib, l, p: not needed by artex.
  }
  if (in.bad()) throw Error(path + ": read error");
  return mesh;
}

namespace {

struct RigBone {
  std::string name;
  std::string parent;
  nlohmann::json head;
  nlohmann::json tail;
};

// Position (OBJ frame, OBJ units) of a rig head/tail entry.
Eigen::Vector3d RigPoint(const nlohmann::json& point, const std::string& field,
                         RigPositionSource source, const ObjMesh& obj,
                         const std::map<std::string, std::vector<int>>& group_vertices,
                         double unit_to_metres, const std::string& rig_path) {
  if (!point.is_object()) throw Error(rig_path + ": " + field + ": expected an object");
  const std::string strategy = JsonString(point, "strategy", rig_path, field);
  if (source == RigPositionSource::kJointCubes) {
    std::vector<int> indices;
    if (strategy == "CUBE" && point.contains("cube_name")) {
      const std::string cube = JsonString(point, "cube_name", rig_path, field);
      auto it = group_vertices.find(cube);
      if (it == group_vertices.end()) {
        throw Error(rig_path + ": " + field + ": joint cube '" + cube +
                    "' is not a group of the OBJ file");
      }
      indices = it->second;
    } else if ((strategy == "MEAN" || strategy == "VERTEX") && point.contains("vertex_indices")) {
      const nlohmann::json& list = point["vertex_indices"];
      if (!list.is_array()) {
        throw Error(rig_path + ": " + field + ".vertex_indices: expected a list of vertex indices");
      }
      for (const nlohmann::json& i : list) indices.push_back(JsonIndex(i, rig_path, field));
    } else if (strategy == "VERTEX" && point.contains("vertex_index")) {
      indices = {JsonIndex(point["vertex_index"], rig_path, field)};
    }
    if (!indices.empty()) {
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (int i : indices) {
        if (i < 0 || i >= static_cast<int>(obj.positions.size())) {
          throw Error(rig_path + ": " + field + ": vertex index " + std::to_string(i) +
                      " outside the OBJ's " + std::to_string(obj.positions.size()) + " vertices");
        }
        sum += obj.positions[i];
      }
      return sum / static_cast<double>(indices.size());
    }
  }
  if (!point.contains("default_position")) {
    throw Error(rig_path + ": " + field + ": no usable position (strategy '" + strategy +
                "' without data and no default_position)");
  }
  // Blender frame (Z up, metres) -> OBJ frame (Y up) in OBJ units.
  const Eigen::Vector3d b = JsonVector3(point["default_position"], rig_path,
                                        field + ".default_position");
  return Eigen::Vector3d(b.x(), b.z(), -b.y()) / unit_to_metres;
}

}  // namespace

Template ImportMakeHuman(const std::string& folder, const MakeHumanImportOptions& options,
                         VertexJointWeights* lbs_weights, MakeHumanImportReport* report) {
  namespace fs = std::filesystem;
  if (!(options.unit_to_metres > 0.0) || !std::isfinite(options.unit_to_metres)) {
    throw Error("MakeHumanImportOptions.unit_to_metres: expected a positive number, found " +
                ErrorNumber(options.unit_to_metres));
  }
  if (!fs::is_directory(folder)) throw Error(folder + ": no such folder");
  const std::string obj_path = (fs::path(folder) / options.obj_file).string();
  const std::string rig_path = (fs::path(folder) / options.rig_file).string();
  const std::string weights_path = (fs::path(folder) / options.weights_file).string();
  const ObjMesh obj = ReadObj(obj_path);

  // Faces of the kept group; template vertices in OBJ order.
  std::vector<const ObjMesh::Face*> faces;
  std::map<std::string, std::vector<int>> group_vertices;  // for the joint cubes
  for (const ObjMesh::Face& face : obj.faces) {
    if (face.group == options.group) faces.push_back(&face);
    std::vector<int>& g = group_vertices[face.group];
    g.insert(g.end(), face.position.begin(), face.position.end());
  }
  for (auto& [name, indices] : group_vertices) {
    std::sort(indices.begin(), indices.end());
    indices.erase(std::unique(indices.begin(), indices.end()), indices.end());
  }
  if (faces.empty()) throw Error(obj_path + ": no faces in group '" + options.group + "'");
  std::vector<int> template_of_obj(obj.positions.size(), -1);
  const std::vector<int>& used = group_vertices[options.group];
  for (size_t i = 0; i < used.size(); ++i) template_of_obj[used[i]] = static_cast<int>(i);
  const int num_vertices = static_cast<int>(used.size());

  Template tmpl;
  tmpl.vertices.resize(num_vertices, 3);
  for (int v = 0; v < num_vertices; ++v) {
    tmpl.vertices.row(v) = (obj.positions[used[v]] * options.unit_to_metres).transpose();
  }
  const double floor_y = tmpl.vertices.col(1).minCoeff();
  const Eigen::RowVector3d shift(0.0, options.feet_on_floor ? -floor_y : 0.0, 0.0);
  tmpl.vertices.rowwise() += shift;

  // Triangulate; UVs per corner (v flipped to the glTF convention).
  bool all_uvs = true;
  int quads = 0, triangles = 0;
  std::vector<std::array<int, 3>> tris, uv_tris;
  for (const ObjMesh::Face* face : faces) {
    const int n = static_cast<int>(face->position.size());
    if (n == 4) ++quads;
    if (n == 3) ++triangles;
    all_uvs = all_uvs && !face->texcoord.empty();
    std::vector<std::array<int, 3>> corners;  // corner indices within the face
    if (n == 4 && options.split_quads_shorter_diagonal) {
      const auto& p = obj.positions;
      const double d02 = (p[face->position[0]] - p[face->position[2]]).squaredNorm();
      const double d13 = (p[face->position[1]] - p[face->position[3]]).squaredNorm();
      if (d13 < d02) {
        corners = {{0, 1, 3}, {1, 2, 3}};
      } else {
        corners = {{0, 1, 2}, {0, 2, 3}};
      }
    } else {
      for (int i = 1; i + 1 < n; ++i) corners.push_back({0, i, i + 1});
    }
    for (const auto& c : corners) {
      tris.push_back({template_of_obj[face->position[c[0]]], template_of_obj[face->position[c[1]]],
                      template_of_obj[face->position[c[2]]]});
      if (!face->texcoord.empty()) {
        uv_tris.push_back({face->texcoord[c[0]], face->texcoord[c[1]], face->texcoord[c[2]]});
      } else {
        uv_tris.push_back({0, 0, 0});
      }
    }
  }
  tmpl.triangles.resize(static_cast<int>(tris.size()), 3);
  for (size_t t = 0; t < tris.size(); ++t) {
    for (int c = 0; c < 3; ++c) tmpl.triangles(static_cast<int>(t), c) = tris[t][c];
  }
  if (all_uvs) {
    // Compact the used texture coordinates.
    std::vector<int> uv_map(obj.texcoords.size(), -1);
    std::vector<int> uv_used;
    tmpl.uv_triangles.resize(static_cast<int>(uv_tris.size()), 3);
    for (size_t t = 0; t < uv_tris.size(); ++t) {
      for (int c = 0; c < 3; ++c) {
        int& m = uv_map[uv_tris[t][c]];
        if (m < 0) {
          m = static_cast<int>(uv_used.size());
          uv_used.push_back(uv_tris[t][c]);
        }
        tmpl.uv_triangles(static_cast<int>(t), c) = m;
      }
    }
    tmpl.uvs.resize(static_cast<int>(uv_used.size()), 2);
    for (size_t i = 0; i < uv_used.size(); ++i) {
      const Eigen::Vector2d& t = obj.texcoords[uv_used[i]];
      tmpl.uvs.row(static_cast<int>(i)) << t.x(), 1.0 - t.y();
    }
    tmpl.triangle_chart = UvIslands(tmpl.triangles, tmpl.uv_triangles);
  }

  // Rig: bones, parents, kept joints.
  const nlohmann::json rig = ReadJson(rig_path);
  if (!rig.is_object()) throw Error(rig_path + ": expected a JSON object of bones");
  std::map<std::string, RigBone> bones;
  for (auto it = rig.begin(); it != rig.end(); ++it) {
    const nlohmann::json& b = it.value();
    if (!b.is_object() || !b.contains("head") || !b.contains("tail")) {
      throw Error(rig_path + ": bone '" + it.key() + "': expected an object with head and tail");
    }
    RigBone bone;
    bone.name = it.key();
    bone.parent = JsonString(b, "parent", rig_path, it.key());
    bone.head = b["head"];
    bone.tail = b["tail"];
    bones[bone.name] = bone;
  }
  for (const auto& [name, bone] : bones) {
    if (!bone.parent.empty() && !bones.count(bone.parent)) {
      throw Error(rig_path + ": bone '" + name + "': parent '" + bone.parent + "' not in the rig");
    }
  }
  static const char* const kJointOrder[] = {
      "pelvis",     "spine",   "chest",   "neck",       "head",    "l_shoulder",
      "l_elbow",    "l_wrist", "r_shoulder", "r_elbow", "r_wrist", "l_hip",
      "l_knee",     "l_ankle", "r_hip",   "r_knee",     "r_ankle"};
  std::vector<std::string> order = options.joint_order;
  if (order.empty()) order.assign(std::begin(kJointOrder), std::end(kJointOrder));
  std::map<std::string, int> joint_of_bone;
  for (size_t j = 0; j < order.size(); ++j) {
    auto it = options.bone_of_joint.find(order[j]);
    if (it == options.bone_of_joint.end()) {
      throw Error("MakeHumanImportOptions.bone_of_joint: no rig bone for joint '" + order[j] + "'");
    }
    if (!bones.count(it->second)) {
      throw Error(rig_path + ": bone '" + it->second + "' (for joint '" + order[j] +
                  "') not in the rig");
    }
    if (!joint_of_bone.emplace(it->second, static_cast<int>(j)).second) {
      throw Error("MakeHumanImportOptions.bone_of_joint: bone '" + it->second +
                  "' used for two joints");
    }
  }
  // Nearest kept ancestor-or-self of every bone (-1: above the root joint).
  auto kept_ancestor = [&](const std::string& start, bool include_self) {
    std::string name = include_self ? start : bones.at(start).parent;
    for (size_t steps = 0; !name.empty() && steps <= bones.size(); ++steps) {
      auto it = joint_of_bone.find(name);
      if (it != joint_of_bone.end()) return it->second;
      name = bones.at(name).parent;
    }
    return -1;
  };
  const double unit = options.unit_to_metres;
  tmpl.joints.resize(order.size());
  for (size_t j = 0; j < order.size(); ++j) {
    const std::string& bone_name = options.bone_of_joint.at(order[j]);
    const RigBone& bone = bones.at(bone_name);
    Joint& joint = tmpl.joints[j];
    joint.name = order[j];
    joint.parent = kept_ancestor(bone_name, false);
    const Eigen::Vector3d head = RigPoint(bone.head, bone_name + ".head", options.joint_positions,
                                          obj, group_vertices, unit, rig_path);
    const Eigen::Vector3d tail = RigPoint(bone.tail, bone_name + ".tail", options.joint_positions,
                                          obj, group_vertices, unit, rig_path);
    joint.center = head * unit + shift.transpose();
    const Eigen::Vector3d axis = tail - head;
    joint.twist_axis = axis.norm() > 0.0 ? Eigen::Vector3d(axis.normalized())
                                         : Eigen::Vector3d::UnitY();
    if (joint.parent >= static_cast<int>(j)) {
      throw Error("MakeHumanImportOptions.joint_order: joint '" + order[j] +
                  "' comes before its parent '" + order[joint.parent] + "'");
    }
  }

  // Weights: every bone's weights go to its nearest kept ancestor (or itself).
  const nlohmann::json weights_json = ReadJson(weights_path);
  if (!weights_json.is_object() || !weights_json.contains("weights") ||
      !weights_json["weights"].is_object()) {
    throw Error(weights_path + ": expected an object with a \"weights\" object");
  }
  std::vector<std::vector<double>> dense(num_vertices,
                                         std::vector<double>(tmpl.joints.size(), 0.0));
  const nlohmann::json& per_bone = weights_json["weights"];
  for (auto it = per_bone.begin(); it != per_bone.end(); ++it) {
    if (!bones.count(it.key())) {
      throw Error(weights_path + ": weights for bone '" + it.key() + "' not in the rig");
    }
    const int joint = kept_ancestor(it.key(), true);
    if (!it.value().is_array()) {
      throw Error(weights_path + ": weights." + it.key() + ": expected a list of [vertex, weight]");
    }
    for (const nlohmann::json& entry : it.value()) {
      if (!entry.is_array() || entry.size() != 2 || !entry[0].is_number_integer() ||
          !entry[1].is_number()) {
        throw Error(weights_path + ": weights." + it.key() +
                    ": expected [vertex index, weight] pairs");
      }
      const long index = entry[0].get<long>();
      const double w = entry[1].get<double>();
      if (index < 0 || index >= static_cast<long>(obj.positions.size())) {
        throw Error(weights_path + ": weights." + it.key() + ": vertex index " +
                    std::to_string(index) + " outside the OBJ's " +
                    std::to_string(obj.positions.size()) + " vertices");
      }
      if (!std::isfinite(w) || w < 0.0) {
        throw Error(weights_path + ": weights." + it.key() + ": invalid weight " + ErrorNumber(w));
      }
      const int v = template_of_obj[index];
      if (v < 0 || w == 0.0) continue;  // helper geometry
      if (joint < 0) {
        throw Error(weights_path + ": bone '" + it.key() +
                    "' weights body vertices but has no kept ancestor joint");
      }
      dense[v][joint] += w;
    }
  }
  VertexJointWeights vertex_weights(num_vertices);
  for (int v = 0; v < num_vertices; ++v) {
    double total = 0.0;
    for (double w : dense[v]) total += w;
    if (!(total > 0.0)) {
      throw Error(weights_path + ": OBJ vertex " + std::to_string(used[v] + 1) + " (group '" +
                  options.group + "') has no skin weight");
    }
    for (size_t j = 0; j < dense[v].size(); ++j) {
      if (dense[v][j] > 0.0) vertex_weights[v].push_back({static_cast<int>(j), dense[v][j] / total});
    }
  }
  ConvertLbsWeights(tmpl.joints, vertex_weights, options.conversion, &tmpl.vertex_joint,
                    &tmpl.lbs_weight, &tmpl.slerp_tau);

  std::string error;
  if (!tmpl.IsValid(&error)) throw Error(folder + ": imported template is invalid: " + error);

  if (report != nullptr) {
    *report = MakeHumanImportReport();
    report->obj_vertices = static_cast<int>(obj.positions.size());
    report->group_quads = quads;
    report->group_triangles = triangles;
    std::map<std::pair<int, int>, int> edge_count;
    for (const auto& t : tris) {
      for (int c = 0; c < 3; ++c) {
        const int a = t[c], b = t[(c + 1) % 3];
        ++edge_count[{std::min(a, b), std::max(a, b)}];
      }
    }
    for (const auto& [edge, count] : edge_count) {
      if (count == 1) ++report->boundary_edges;
      if (count > 2) ++report->non_manifold_edges;
    }
    report->height_m = tmpl.vertices.col(1).maxCoeff() - tmpl.vertices.col(1).minCoeff();
    for (int v = 0; v < num_vertices; ++v) {
      const int k = tmpl.vertex_joint[v];
      const int p = tmpl.joints[k].parent;
      double kept = 0.0;
      for (const JointWeight& jw : vertex_weights[v]) {
        if (jw.joint == k || jw.joint == p) kept += jw.weight;
      }
      report->max_joint_weight_loss = std::max(report->max_joint_weight_loss, 1.0 - kept);
    }
  }
  if (lbs_weights != nullptr) *lbs_weights = std::move(vertex_weights);
  return tmpl;
}

}  // namespace artex
