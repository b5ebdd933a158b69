// Shared by the template file tests (template_io_test.cc: writing, reading and rejecting
// artex templates; template_import_test.cc: plain glTF import, the Khronos validator, the
// summary and posed mesh export): a hand-built tube template, GLB surgery for corrupted files,
// a temporary-folder fixture.
#pragma once

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "models/error.h"
#include "models/template_io.h"
#include "models/makehuman_import.h"
#include "models/mesh_export.h"
#include "models/skinning.h"

namespace artex {
namespace testing_util {

namespace fs = std::filesystem;
using json = nlohmann::json;

// ---------------------------------------------------------------------------------------------
// A hand-built template: a tube along +Y over three chained joints (plus a side joint without
// vertices), with a UV seam, two charts and one unreferenced vertex.
inline Template MakeTube(int rings = 8, int segments = 8) {
  Template t;
  const int num_surface = (rings + 1) * segments;
  t.vertices.resize(num_surface + 1, 3);
  for (int r = 0; r <= rings; ++r) {
    const double y = 2.0 * r / rings;
    const double radius = 0.1 + 0.02 * std::sin(3.0 * y);
    for (int s = 0; s < segments; ++s) {
      const double a = 2.0 * M_PI * s / segments;
      t.vertices.row(r * segments + s) << radius * std::cos(a), y, -radius * std::sin(a);
    }
  }
  t.vertices.row(num_surface) << 0.0, 2.5, 0.0;  // not used by any triangle
  t.uvs.resize((rings + 1) * (segments + 1), 2);
  for (int r = 0; r <= rings; ++r) {
    for (int s = 0; s <= segments; ++s) {
      t.uvs.row(r * (segments + 1) + s) << 0.05 + 0.9 * s / segments, 0.95 - 0.9 * r / rings;
    }
  }
  const int f = 2 * rings * segments;
  t.triangles.resize(f, 3);
  t.uv_triangles.resize(f, 3);
  t.triangle_chart.resize(f);
  int n = 0;
  for (int r = 0; r < rings; ++r) {
    for (int s = 0; s < segments; ++s) {
      const int s1 = (s + 1) % segments;
      const int a = r * segments + s, b = r * segments + s1, c = (r + 1) * segments + s1,
                d = (r + 1) * segments + s;
      const int ua = r * (segments + 1) + s, ub = ua + 1, uc = ub + segments + 1,
                ud = ua + segments + 1;
      t.triangles.row(n) << a, b, c;
      t.uv_triangles.row(n) << ua, ub, uc;
      t.triangle_chart[n++] = s < segments / 2 ? 0 : 1;
      t.triangles.row(n) << a, c, d;
      t.uv_triangles.row(n) << ua, uc, ud;
      t.triangle_chart[n++] = s < segments / 2 ? 0 : 1;
    }
  }
  auto add_joint = [&t](const std::string& name, int parent, const Eigen::Vector3d& center,
                        const Eigen::Vector3d& axis) {
    Joint joint;
    joint.name = name;
    joint.parent = parent;
    joint.center = center;
    joint.twist_axis = axis.normalized();
    t.joints.push_back(joint);
  };
  add_joint("root", -1, {0.0, 0.1, 0.0}, {0.0, 1.0, 0.0});
  add_joint("mid", 0, {0.01, 0.8, 0.0}, {0.0, 1.0, 0.05});
  add_joint("tip", 1, {0.0, 1.5, 0.02}, {0.02, 1.0, 0.0});
  add_joint("side", 0, {0.3, 0.5, 0.0}, {1.0, 0.0, 0.0});
  const int v_count = t.num_vertices();
  t.vertex_joint.resize(v_count);
  t.lbs_weight.resize(v_count);
  t.slerp_tau.resize(v_count);
  for (int v = 0; v < v_count; ++v) {
    const double y = t.vertices(v, 1);
    const int k = y < 0.6 ? 0 : (y < 1.3 ? 1 : 2);
    t.vertex_joint[v] = k;
    const double base = k == 0 ? 0.1 : (k == 1 ? 0.8 : 1.5);
    t.lbs_weight[v] = std::clamp((y - base + 0.2) / 0.5, 0.0, 1.0);  // includes 0 and 1
    t.slerp_tau[v] = std::clamp(0.2 + 0.3 * y, 0.0, 1.0);
  }
  std::string error;
  EXPECT_TRUE(t.IsValid(&error)) << error;
  return t;
}

// ---------------------------------------------------------------------------------------------
// GLB container helpers for building corrupted files.
struct Glb {
  json gltf;
  std::string bin;
};

inline uint32_t U32(const std::string& s, size_t offset) {
  uint32_t v;
  std::memcpy(&v, s.data() + offset, 4);
  return v;
}

inline Glb ParseGlb(const std::string& bytes) {
  Glb glb;
  const uint32_t json_length = U32(bytes, 12);
  glb.gltf = json::parse(bytes.substr(20, json_length));
  const size_t bin_header = 20 + json_length;
  if (bin_header + 8 <= bytes.size()) glb.bin = bytes.substr(bin_header + 8, U32(bytes, bin_header));
  return glb;
}

inline void AppendU32(std::string* s, uint32_t v) { s->append(reinterpret_cast<const char*>(&v), 4); }

inline std::string BuildGlb(const Glb& glb) {
  std::string text = glb.gltf.dump();
  while (text.size() % 4) text.push_back(' ');
  std::string bin = glb.bin;
  while (bin.size() % 4) bin.push_back('\0');
  std::string out = "glTF";
  AppendU32(&out, 2);
  AppendU32(&out, static_cast<uint32_t>(12 + 8 + text.size() + (bin.empty() ? 0 : 8 + bin.size())));
  AppendU32(&out, static_cast<uint32_t>(text.size()));
  AppendU32(&out, 0x4E4F534A);
  out += text;
  if (!bin.empty()) {
    AppendU32(&out, static_cast<uint32_t>(bin.size()));
    AppendU32(&out, 0x004E4942);
    out += bin;
  }
  return out;
}

inline int AttributeAccessor(const Glb& glb, const std::string& name) {
  return glb.gltf["meshes"][0]["primitives"][0]["attributes"][name].get<int>();
}

// Byte offset of element `i`, component `c` of a tightly packed accessor in the BIN chunk.
inline size_t ElementOffset(const Glb& glb, int accessor, size_t i, int c, size_t component_size,
                     int components) {
  const json& a = glb.gltf["accessors"][accessor];
  const json& view = glb.gltf["bufferViews"][a["bufferView"].get<int>()];
  return view.value("byteOffset", size_t{0}) + a.value("byteOffset", size_t{0}) +
         (i * components + c) * component_size;
}

inline float ReadFloat(const Glb& glb, int accessor, size_t i, int c, int components) {
  float v;
  std::memcpy(&v, glb.bin.data() + ElementOffset(glb, accessor, i, c, 4, components), 4);
  return v;
}

inline void WriteFloat(Glb* glb, int accessor, size_t i, int c, int components, float v) {
  std::memcpy(&glb->bin[ElementOffset(*glb, accessor, i, c, 4, components)], &v, 4);
}

inline uint16_t ReadU16(const Glb& glb, int accessor, size_t i, int c, int components) {
  uint16_t v;
  std::memcpy(&v, glb.bin.data() + ElementOffset(glb, accessor, i, c, 2, components), 2);
  return v;
}

inline void WriteU16(Glb* glb, int accessor, size_t i, int c, int components, uint16_t v) {
  std::memcpy(&glb->bin[ElementOffset(*glb, accessor, i, c, 2, components)], &v, 2);
}

// Removes every _ARTEX_* attribute: a plain glTF skinned mesh.
inline Glb StripArtexAttributes(Glb glb) {
  json& attributes = glb.gltf["meshes"][0]["primitives"][0]["attributes"];
  std::vector<std::string> names;
  for (auto it = attributes.begin(); it != attributes.end(); ++it) {
    if (it.key().rfind("_ARTEX", 0) == 0) names.push_back(it.key());
  }
  for (const std::string& name : names) attributes.erase(name);
  return glb;
}

class TemplateIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("artex_template_io_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  static std::string ReadBytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
  }
  static void WriteBytes(const std::string& path, const std::string& bytes) {
    std::ofstream out(path, std::ios::binary);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  }

  // Expects ReadTemplateGlb(path) to throw artex::Error whose message names the file and
  // contains `fragment`.
  static void ExpectReadError(const std::string& path, const std::string& fragment) {
    try {
      ReadTemplateGlb(path);
      ADD_FAILURE() << "no error for " << path << " (expected '" << fragment << "')";
    } catch (const Error& e) {
      const std::string message = e.what();
      EXPECT_NE(message.find(path), std::string::npos) << message;
      EXPECT_NE(message.find(fragment), std::string::npos) << message;
    }
  }

  fs::path dir_;
};

inline void ExpectSameTemplate(const Template& a, const Template& b) {
  ASSERT_EQ(a.num_vertices(), b.num_vertices());
  ASSERT_EQ(a.num_triangles(), b.num_triangles());
  ASSERT_EQ(a.num_joints(), b.num_joints());
  // Positions and per-vertex constants are stored as float: exact up to float rounding.
  EXPECT_LE((a.vertices - b.vertices).cwiseAbs().maxCoeff(), 1e-6 * a.vertices.cwiseAbs().maxCoeff());
  EXPECT_TRUE((a.triangles.array() == b.triangles.array()).all());
  EXPECT_EQ(a.uvs.rows(), b.uvs.rows());
  if (a.uvs.rows() == b.uvs.rows() && a.uvs.rows() > 0) {
    EXPECT_LE((a.uvs - b.uvs).cwiseAbs().maxCoeff(), 1e-7);
  }
  ASSERT_EQ(a.uv_triangles.rows(), b.uv_triangles.rows());
  EXPECT_TRUE((a.uv_triangles.array() == b.uv_triangles.array()).all());
  ASSERT_EQ(a.triangle_chart.size(), b.triangle_chart.size());
  EXPECT_TRUE((a.triangle_chart.array() == b.triangle_chart.array()).all());
  for (int j = 0; j < a.num_joints(); ++j) {
    EXPECT_EQ(a.joints[j].name, b.joints[j].name);
    EXPECT_EQ(a.joints[j].parent, b.joints[j].parent);
    EXPECT_EQ(a.joints[j].center, b.joints[j].center);          // JSON doubles: exact
    EXPECT_EQ(a.joints[j].twist_axis, b.joints[j].twist_axis);  // JSON doubles: exact
  }
  EXPECT_TRUE((a.vertex_joint.array() == b.vertex_joint.array()).all());
  EXPECT_LE((a.lbs_weight - b.lbs_weight).cwiseAbs().maxCoeff(), 1e-7);
  EXPECT_LE((a.slerp_tau - b.slerp_tau).cwiseAbs().maxCoeff(), 1e-7);
}

// Random pose whose joint rotations have no twist about the joints' axes (there the glTF
// linear-blend skin reproduces the paper's model exactly).
inline Pose RandomSwingPose(const Template& tmpl, std::mt19937_64& rng, double max_angle) {
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  Pose pose = Pose::Identity(tmpl.num_joints());
  pose.scale = 1.0 + 0.2 * uniform(rng);
  pose.translation = Eigen::Vector3d(uniform(rng), uniform(rng), uniform(rng));
  pose.rotation = Eigen::AngleAxisd(M_PI * uniform(rng),
                                    Eigen::Vector3d(uniform(rng), uniform(rng), 1.0).normalized())
                      .toRotationMatrix();
  for (int j = 0; j < tmpl.num_joints(); ++j) {
    const Eigen::Vector3d a = tmpl.joints[j].twist_axis;
    Eigen::Vector3d d(uniform(rng), uniform(rng), uniform(rng));
    d -= a * a.dot(d);
    pose.joint_rotations[j] =
        Eigen::AngleAxisd(max_angle * uniform(rng), d.normalized()).toRotationMatrix();
  }
  return pose;
}

}  // namespace testing_util
}  // namespace artex
