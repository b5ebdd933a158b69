#include "models/mesh_export.h"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <thread>

// GCC reports a false -Wmaybe-uninitialized inside OpenMesh's PropertyT<Vec3uc>::push_back.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <unistd.h>

#include "models/error.h"
#include "models/template_io.h"

namespace artex {
namespace {

struct ExportTraits : public OpenMesh::DefaultTraits {
  typedef OpenMesh::Vec3d Point;
  typedef OpenMesh::Vec3d Normal;
  typedef OpenMesh::Vec3uc Color;
};
using ExportMesh = OpenMesh::TriMesh_ArrayKernelT<ExportTraits>;

void CheckShapes(const std::string& path, const Eigen::MatrixX3d& vertices,
                 const Eigen::MatrixX3i& triangles, const Eigen::MatrixX3d& colors,
                 const Eigen::MatrixX3d& normals) {
  const int v = static_cast<int>(vertices.rows());
  if (v == 0) throw Error(path + ": no vertices to write");
  if (!vertices.allFinite()) throw Error(path + ": vertices contain a non-finite coordinate");
  if (triangles.rows() > 0 && (triangles.minCoeff() < 0 || triangles.maxCoeff() >= v)) {
    throw Error(path + ": triangle indices outside [0, " + std::to_string(v) + ")");
  }
  if (colors.rows() != 0 && colors.rows() != v) {
    throw Error(path + ": colors: expected " + std::to_string(v) + " rows, found " +
                std::to_string(colors.rows()));
  }
  if (colors.rows() != 0 && !colors.allFinite()) {
    throw Error(path + ": colors contain a non-finite value");
  }
  if (normals.rows() != 0 && normals.rows() != v) {
    throw Error(path + ": normals: expected " + std::to_string(v) + " rows, found " +
                std::to_string(normals.rows()));
  }
  if (normals.rows() != 0 && !normals.allFinite()) {
    throw Error(path + ": normals contain a non-finite value");
  }
}

// A one-joint template carrying the geometry, for .glb output.
Template GeometryTemplate(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles) {
  Template tmpl;
  tmpl.vertices = vertices;
  tmpl.triangles = triangles;
  Joint root;
  root.name = "root";
  root.center = vertices.colwise().mean().transpose();
  tmpl.joints.push_back(root);
  tmpl.vertex_joint = Eigen::VectorXi::Zero(vertices.rows());
  tmpl.lbs_weight = Eigen::VectorXd::Ones(vertices.rows());
  tmpl.slerp_tau = Eigen::VectorXd::Zero(vertices.rows());
  return tmpl;
}

}  // namespace

std::string LowerCaseExtension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

void WriteFileAtomically(const std::string& path, const std::string& contents) {
  WriteFileAtomically(path, [&contents](std::ostream& out) {
    out.write(contents.data(), static_cast<std::streamsize>(contents.size()));
  });
}

namespace {
// A temporary file's name: "." + the target's + this + "<pid>-<thread>".
constexpr char kTemporaryMarker[] = ".tmp-";
}  // namespace

std::string AtomicWriteTarget(const std::string& file_name) {
  if (file_name.size() < 2 || file_name[0] != '.') return "";
  const std::size_t marker = file_name.rfind(kTemporaryMarker);
  if (marker == std::string::npos || marker < 2) return "";
  return file_name.substr(1, marker - 1);
}

void WriteFileAtomically(const std::string& path,
                         const std::function<void(std::ostream&)>& write) {
  namespace fs = std::filesystem;
  const fs::path target(path);
  const fs::path dir = target.has_parent_path() ? target.parent_path() : fs::path(".");
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    throw Error(path + ": cannot write (folder " + dir.string() + " does not exist)");
  }
  const fs::path tmp =
      dir / ("." + target.filename().string() + kTemporaryMarker + std::to_string(::getpid()) +
             "-" + std::to_string(std::hash<std::thread::id>()(std::this_thread::get_id())));
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw Error(path + ": cannot write (cannot create a temporary file in " +
                          dir.string() + ")");
    try {
      write(out);
    } catch (...) {
      out.close();
      fs::remove(tmp, ec);
      throw;
    }
    out.flush();
    if (!out) {
      out.close();
      fs::remove(tmp, ec);
      throw Error(path + ": cannot write (write failed; disk full?)");
    }
  }
  fs::rename(tmp, target, ec);
  if (ec) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw Error(path + ": cannot write (rename failed: " + ec.message() + ")");
  }
}

void WritePosedMesh(const std::string& path, const Eigen::MatrixX3d& vertices,
                    const Eigen::MatrixX3i& triangles, const Eigen::MatrixX3d& colors,
                    const Eigen::MatrixX3d& normals, const MeshExportOptions& options) {
  const std::string ext = LowerCaseExtension(path);
  if (ext != ".ply" && ext != ".obj" && ext != ".glb") {
    throw Error(path + ": unsupported mesh format '" + ext + "' (expected .ply, .obj or .glb)");
  }
  CheckShapes(path, vertices, triangles, colors, normals);
  if (ext == ".glb") {
    if (triangles.rows() == 0) throw Error(path + ": .glb output needs at least one triangle");
    WriteTemplateGlb(path, GeometryTemplate(vertices, triangles));
    return;
  }
  ExportMesh mesh;
  const bool with_colors = colors.rows() != 0 && ext == ".ply";
  const bool with_normals = normals.rows() != 0;
  if (with_colors) mesh.request_vertex_colors();
  if (with_normals) mesh.request_vertex_normals();
  std::vector<ExportMesh::VertexHandle> handles(vertices.rows());
  for (int v = 0; v < vertices.rows(); ++v) {
    handles[v] = mesh.add_vertex(ExportMesh::Point(vertices(v, 0), vertices(v, 1), vertices(v, 2)));
    if (with_colors) {
      auto to_byte = [](double c) {
        return static_cast<unsigned char>(std::lround(std::clamp(c, 0.0, 1.0) * 255.0));
      };
      mesh.set_color(handles[v], ExportMesh::Color(to_byte(colors(v, 0)), to_byte(colors(v, 1)),
                                                   to_byte(colors(v, 2))));
    }
    if (with_normals) {
      mesh.set_normal(handles[v], ExportMesh::Normal(normals(v, 0), normals(v, 1), normals(v, 2)));
    }
  }
  for (int f = 0; f < triangles.rows(); ++f) {
    const auto face = mesh.add_face(handles[triangles(f, 0)], handles[triangles(f, 1)],
                                    handles[triangles(f, 2)]);
    if (!face.is_valid()) {
      throw Error(path + ": triangle " + std::to_string(f) +
                  " makes the mesh non-manifold or is degenerate; cannot export it");
    }
  }
  OpenMesh::IO::Options io_options;
  if (ext == ".ply" && options.binary_ply) {
    io_options += OpenMesh::IO::Options::Binary;
    io_options += OpenMesh::IO::Options::LSB;
  }
  if (with_colors) io_options += OpenMesh::IO::Options::VertexColor;
  if (with_normals) io_options += OpenMesh::IO::Options::VertexNormal;
  std::ostringstream out(std::ios::binary);
  // OpenMesh's writers log progress to omlog(); artex libraries do not print.
  const bool log_enabled = omlog().is_enabled();
  omlog().disable();
  const bool written =
      OpenMesh::IO::write_mesh(mesh, out, ext, io_options, options.ascii_precision);
  if (log_enabled) omlog().enable();
  if (!written) {
    throw Error(path + ": OpenMesh could not encode the mesh as " + ext);
  }
  WriteFileAtomically(path, out.str());
}

}  // namespace artex
