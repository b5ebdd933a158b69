// Distance of tracked vertices to a ground-truth surface (the output stage's per-frame vertex
// error, experiments/pipeline_stages.h): per tracked vertex, the distance to the nearest truth
// vertex, refined to the distance to that vertex's tangent plane (never more than the vertex
// distance). The nearest vertex is found exactly in a uniform grid built per frame in linear
// time (the truth moves every frame); it replaced a kd-tree rebuilt per frame, with the same
// results (tests/experiments/surface_error_test.cc compares it with a brute-force search).
#pragma once

#include <Eigen/Core>
#include <vector>

namespace artex {

// Exact nearest-point queries over a fixed set of points (N x 3, kept by reference).
class NearestPointGrid {
 public:
  explicit NearestPointGrid(const Eigen::MatrixX3d& points);
  // Index of the nearest point to p (among equidistant ones the lowest index) and its squared
  // distance; -1 when there are no points.
  int Nearest(const Eigen::Vector3d& p, double* squared_distance) const;

 private:
  int Cell(double x, int axis) const;
  // Points of one cell into the running nearest (*best: its squared distance).
  void Visit(int cell, const Eigen::Vector3d& p, double* best, int* best_index) const;
  const Eigen::MatrixX3d& points_;
  Eigen::Vector3d origin_ = Eigen::Vector3d::Zero();
  double cell_ = 1.0;
  int dims_[3] = {1, 1, 1};
  std::vector<int> cell_begin_;  // per cell (x fastest): first entry in order_; + end sentinel
  std::vector<int> order_;       // point indices sorted by cell
  std::vector<double> sorted_;   // their coordinates (x, y, z) in that order
};

// Mean and maximum of the distances above over the rows of `tracked` (0 and 0 when empty).
// truth_normals: unit vertex normals of `truth` (a row of norm <= sqrt(0.5) is no normal: the
// vertex distance is used).
void SurfaceErrors(const Eigen::MatrixX3d& tracked, const Eigen::MatrixX3d& truth,
                   const Eigen::MatrixX3d& truth_normals, double* mean, double* max);

}  // namespace artex
