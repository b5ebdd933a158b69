// The fitted vertex subset of EMFitter (EMFitterOptions::fit_vertex_selection kVoxel).
#pragma once

#include <Eigen/Core>
#include <vector>

namespace artex {

// At most `count` vertices spread evenly over the surface: the rest-pose vertices binned on a
// cubic grid whose cell is the smallest (bisection over the cell size) giving at most `count`
// occupied cells, one vertex per cell (the one nearest the cell centre), in Z-curve order of
// the cells (neighbouring fitted vertices are close in space). No vertices or count <= 0: none;
// all vertices at one point: the first.
std::vector<int> VoxelVertexSubset(const Eigen::MatrixX3d& vertices, int count);

}  // namespace artex
