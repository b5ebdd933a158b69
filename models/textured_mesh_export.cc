#include "models/textured_mesh_export.h"

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <sstream>
#include <utility>
#include <vector>

#include "models/error.h"
#include "models/mesh_export.h"

namespace artex {

const std::map<std::string, UpAxis>& UpAxisNames() {
  static const std::map<std::string, UpAxis> kNames = {{"y", UpAxis::kY}, {"z", UpAxis::kZ}};
  return kNames;
}

Eigen::MatrixX3d ToUpAxis(const Eigen::MatrixX3d& points, UpAxis up) {
  if (up == UpAxis::kY) return points;
  Eigen::MatrixX3d out(points.rows(), 3);
  out.col(0) = points.col(0);
  out.col(1) = -points.col(2);
  out.col(2) = points.col(1);
  return out;
}

void WriteTexturedMesh(const std::string& path, const Template& tmpl, const Eigen::MatrixX3d& posed,
                       const TexturedMeshOptions& options) {
  const std::string ext = LowerCaseExtension(path);
  if (ext != ".obj" && ext != ".ply") {
    throw Error(path + ": unsupported textured mesh format '" + ext + "' (expected .obj or .ply)");
  }
  if (posed.rows() != tmpl.num_vertices()) {
    throw Error(path + ": expected " + std::to_string(tmpl.num_vertices()) +
                " posed vertices, found " + std::to_string(posed.rows()));
  }
  if (!posed.allFinite()) throw Error(path + ": posed vertices contain a non-finite coordinate");
  const Eigen::MatrixX3d p = ToUpAxis(posed, options.up);
  const bool uvs = tmpl.has_uvs();
  auto v_of = [&options](double v) { return options.flip_v ? 1.0 - v : v; };
  namespace fs = std::filesystem;

  if (ext == ".obj") {
    std::ostringstream out;
    out.precision(options.ascii_precision);
    out << "# artex posed template (" << (options.up == UpAxis::kZ ? "Z" : "Y") << " up)\n";
    const std::string mtl = fs::path(path).stem().string() + ".mtl";
    if (!options.texture_file.empty()) out << "mtllib " << mtl << "\nusemtl artex_texture\n";
    for (int v = 0; v < p.rows(); ++v)
      out << "v " << p(v, 0) << " " << p(v, 1) << " " << p(v, 2) << "\n";
    if (uvs) {
      for (int t = 0; t < tmpl.uvs.rows(); ++t)
        out << "vt " << tmpl.uvs(t, 0) << " " << v_of(tmpl.uvs(t, 1)) << "\n";
    }
    for (int f = 0; f < tmpl.num_triangles(); ++f) {
      out << "f";
      for (int c = 0; c < 3; ++c) {
        out << " " << tmpl.triangles(f, c) + 1;
        if (uvs) out << "/" << tmpl.uv_triangles(f, c) + 1;
      }
      out << "\n";
    }
    WriteFileAtomically(path, out.str());
    if (!options.texture_file.empty()) {
      const fs::path mtl_path = fs::path(path).parent_path() / mtl;
      WriteFileAtomically(mtl_path.string(),
                          "newmtl artex_texture\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\nmap_Kd " +
                              options.texture_file + "\n");
    }
    return;
  }

  // PLY: one vertex per (template vertex, uv index) corner pair.
  std::vector<std::pair<int, int>> pairs;
  for (int f = 0; f < tmpl.num_triangles(); ++f) {
    for (int c = 0; c < 3; ++c)
      pairs.emplace_back(tmpl.triangles(f, c), uvs ? tmpl.uv_triangles(f, c) : -1);
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  auto index = [&pairs](int v, int uv) {
    return static_cast<int32_t>(
        std::lower_bound(pairs.begin(), pairs.end(), std::make_pair(v, uv)) - pairs.begin());
  };
  std::ostringstream out(std::ios::binary);
  out << "ply\nformat binary_little_endian 1.0\ncomment artex posed template ("
      << (options.up == UpAxis::kZ ? "Z" : "Y") << " up)\n";
  if (!options.texture_file.empty()) out << "comment TextureFile " << options.texture_file << "\n";
  out << "element vertex " << pairs.size()
      << "\nproperty float x\nproperty float y\nproperty float z\n";
  if (uvs) out << "property float s\nproperty float t\n";
  out << "element face " << tmpl.num_triangles()
      << "\nproperty list uchar int vertex_indices\nend_header\n";
  auto put = [&out](const void* data, std::size_t n) {
    out.write(static_cast<const char*>(data), static_cast<std::streamsize>(n));
  };
  for (const auto& [v, uv] : pairs) {
    const float xyz[3] = {static_cast<float>(p(v, 0)), static_cast<float>(p(v, 1)),
                          static_cast<float>(p(v, 2))};
    put(xyz, sizeof(xyz));
    if (uvs) {
      const float st[2] = {static_cast<float>(tmpl.uvs(uv, 0)),
                           static_cast<float>(v_of(tmpl.uvs(uv, 1)))};
      put(st, sizeof(st));
    }
  }
  for (int f = 0; f < tmpl.num_triangles(); ++f) {
    const uint8_t three = 3;
    put(&three, 1);
    for (int c = 0; c < 3; ++c) {
      const int32_t i = index(tmpl.triangles(f, c), uvs ? tmpl.uv_triangles(f, c) : -1);
      put(&i, sizeof(i));
    }
  }
  WriteFileAtomically(path, out.str());
}

}  // namespace artex
