// Export of posed meshes for inspection in mesh viewers: PLY (binary little endian) or OBJ via
// OpenMesh, chosen by the file extension; ".glb" writes a static glTF (models/template_io.h).
// Files are written to a temporary in the same folder and renamed: never partially.
#pragma once

#include <functional>
#include <ostream>
#include <string>

#include <Eigen/Core>

#include "models/template.h"

namespace artex {

struct MeshExportOptions {
  bool binary_ply = true;  // PLY only; OBJ is always ASCII
  int ascii_precision = 9;  // significant digits of ASCII numbers (OBJ, ASCII PLY)
};

// vertices: V x 3 (m); triangles: F x 3 (CCW from outside); colors: empty or V x 3 in [0,1]
// (PLY: per-vertex uchar colours; OBJ: ignored); normals: empty or V x 3.
// Extensions .ply, .obj (case-insensitive) or .glb (geometry only, a one-joint template).
// Throws artex::Error naming `path` for another extension, bad shapes, indices out of range,
// non-finite values or an I/O failure.
void WritePosedMesh(const std::string& path, const Eigen::MatrixX3d& vertices,
                    const Eigen::MatrixX3i& triangles,
                    const Eigen::MatrixX3d& colors = Eigen::MatrixX3d(),
                    const Eigen::MatrixX3d& normals = Eigen::MatrixX3d(),
                    const MeshExportOptions& options = MeshExportOptions());

// Writes `contents` to `path` through a temporary file in the same folder and a rename.
// Throws artex::Error naming `path` on failure (the temporary is removed).
void WriteFileAtomically(const std::string& path, const std::string& contents);
// The same, with the contents written by `write` (an exception from it removes the temporary
// and propagates).
void WriteFileAtomically(const std::string& path,
                         const std::function<void(std::ostream&)>& write);
// The file name a temporary of WriteFileAtomically (".<name>.tmp-<pid>-<thread>", in the
// target's folder) is written for: <name>; empty for any other file name. For cleaning up
// after a writer that crashed.
std::string AtomicWriteTarget(const std::string& file_name);

// Lower-case extension of `path` including the dot ("" when none).
std::string LowerCaseExtension(const std::string& path);

}  // namespace artex
