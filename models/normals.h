// Vertex normals as the (normalised) mean of incident unit triangle normals, as the paper
// defines n(.) for both scan and template (eq. 4). Vertices without a non-degenerate incident
// triangle get a zero normal.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace artex {

// vertices: V x 3; triangles: F x 3 (counter-clockwise from outside); normals: V x 3.
void ComputeVertexNormals(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                          Eigen::MatrixX3d* normals);
// The triangles incident to a list of a mesh's vertices, ascending per vertex: those of the
// list's i-th vertex are triangles[offset[i] .. offset[i + 1]).
struct IncidentTriangles {
  std::vector<int> offset, triangles;
  int num_vertices = 0, num_triangles = 0;  // the mesh's
};
// Throws artex::Error for a vertex index outside [0, num_vertices) in `which` or `triangles`,
// or a vertex listed twice in `which`.
IncidentTriangles FindIncidentTriangles(const Eigen::MatrixX3i& triangles,
                                        const std::vector<int>& which, int num_vertices);
// The normals ComputeVertexNormals gives the listed vertices, bit for bit, computed from their
// incident triangles alone: row i is the list's i-th vertex. Throws artex::Error for a mesh of
// another vertex or triangle count than incident's.
void ComputeVertexNormalsOf(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                            const IncidentTriangles& incident, Eigen::MatrixX3d* normals);
// F x 3 unit triangle normals (zero for degenerate triangles).
void ComputeTriangleNormals(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                            Eigen::MatrixX3d* normals);

}  // namespace artex
