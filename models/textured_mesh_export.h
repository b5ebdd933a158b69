// Export of a posed template with its UV atlas and texture for mesh tools (Blender, MeshLab):
// OBJ with per-corner UVs and a material (.mtl beside it, map_Kd = the texture image) or PLY
// (binary little endian; vertices split at UV seams, per-vertex texture coordinates s, t and
// "comment TextureFile <image>", the MeshLab convention Blender's importer also reads the
// coordinates of). Optional Z-up axes for tools whose up axis is +Z (Blender).
#pragma once

#include <Eigen/Core>
#include <map>
#include <string>

#include "models/template.h"

namespace artex {

// kY: artex's frame (Y up, the template faces +Z). kZ: (x, y, z) -> (x, -z, y), Z up and the
// template facing -Y, Blender's front view.
enum class UpAxis { kY, kZ };
const std::map<std::string, UpAxis>& UpAxisNames();  // "y", "z"

struct TexturedMeshOptions {
  UpAxis up = UpAxis::kY;
  // Texture image file name written into the OBJ material / PLY comment, relative to the mesh
  // file (e.g. "texture.png"); "" writes no texture reference.
  std::string texture_file;
  bool flip_v = true;       // store 1 - v (OBJ/PLY put v = 0 at the image bottom; artex at the top)
  int ascii_precision = 9;  // OBJ digits
};

// Writes `posed` (V x 3, m) with tmpl's triangles and per-corner UVs (tmpl.has_uvs(); without
// UVs no texture coordinates are written) to path (.obj or .ply by extension; .obj also writes
// <stem>.mtl when texture_file is set). Atomic; throws artex::Error naming the path for another
// extension, a vertex count differing from the template's or an I/O failure.
void WriteTexturedMesh(const std::string& path, const Template& tmpl, const Eigen::MatrixX3d& posed,
                       const TexturedMeshOptions& options = TexturedMeshOptions());

// The vertex transform of `up` (row-wise on V x 3).
Eigen::MatrixX3d ToUpAxis(const Eigen::MatrixX3d& points, UpAxis up);

}  // namespace artex
