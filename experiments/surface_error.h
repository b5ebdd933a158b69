// Distance of tracked vertices to a ground-truth surface (the output stage's per-frame vertex
// error, experiments/pipeline_stages.h): per tracked vertex, the distance to the nearest truth
// vertex, refined to the distance to that vertex's tangent plane (never more than the vertex
// distance). The nearest vertex is found exactly in a uniform grid (NearestGrid) built per
// frame in linear time (the truth moves every frame); it replaced a kd-tree rebuilt per frame,
// with the same results (tests/experiments/surface_error_test.cc compares it with a
// brute-force search).
#pragma once

#include <Eigen/Core>
#include <vector>

namespace artex {

// Mean and maximum of the distances above over the rows of `tracked` (0 and 0 when empty).
// truth_normals: unit vertex normals of `truth` (a row of norm <= sqrt(0.5) is no normal: the
// vertex distance is used).
// nearest (optional): in, a guess of each tracked vertex's nearest truth vertex (the previous
// frame's answer); out, the nearest truth vertex of each (-1 past a non-finite vertex). A guess
// only bounds the search, since the nearest vertex is no farther than any vertex: the results
// are the same bit for bit whatever it holds (entries out of range and a vector of another
// size are ignored; of exactly coincident truth vertices another may be met first, at the same
// distance), and a close guess spares most of the grid's cells.
void SurfaceErrors(const Eigen::MatrixX3d& tracked, const Eigen::MatrixX3d& truth,
                   const Eigen::MatrixX3d& truth_normals, double* mean, double* max,
                   std::vector<int>* nearest = nullptr);

}  // namespace artex
