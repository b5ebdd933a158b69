// Vertex normals as the (normalised) mean of incident unit triangle normals, as the paper
// defines n(.) for both scan and template (eq. 4). Vertices without a non-degenerate incident
// triangle get a zero normal.
#pragma once

#include <Eigen/Core>

namespace artex {

// vertices: V x 3; triangles: F x 3 (counter-clockwise from outside); normals: V x 3.
void ComputeVertexNormals(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                          Eigen::MatrixX3d* normals);
// F x 3 unit triangle normals (zero for degenerate triangles).
void ComputeTriangleNormals(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                            Eigen::MatrixX3d* normals);

}  // namespace artex
