#include "models/normals.h"

#include <Eigen/Geometry>
#include <cmath>
#include <sstream>

#include "models/error.h"

namespace artex {

namespace {

void CheckTriangles(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                    const char* function) {
  if (triangles.rows() == 0) return;
  const int lo = triangles.minCoeff();
  const int hi = triangles.maxCoeff();
  if (lo < 0 || hi >= vertices.rows()) {
    std::ostringstream msg;
    msg << function << ": triangles: expected vertex indices in [0, " << vertices.rows()
        << "), found " << lo << ".." << hi;
    throw Error(msg.str());
  }
}

// Unit normal of triangle f, zero when degenerate (zero or non-finite area vector).
Eigen::Vector3d TriangleNormal(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                               int f) {
  const Eigen::Vector3d p0 = vertices.row(triangles(f, 0)).transpose();
  const Eigen::Vector3d p1 = vertices.row(triangles(f, 1)).transpose();
  const Eigen::Vector3d p2 = vertices.row(triangles(f, 2)).transpose();
  const Eigen::Vector3d n = (p1 - p0).cross(p2 - p0);
  const double norm = n.norm();
  if (!(norm > 0.0) || !std::isfinite(norm)) return Eigen::Vector3d::Zero();
  return n / norm;
}

}  // namespace

void ComputeTriangleNormals(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                            Eigen::MatrixX3d* normals) {
  CheckTriangles(vertices, triangles, "ComputeTriangleNormals");
  normals->resize(triangles.rows(), 3);
  for (int f = 0; f < triangles.rows(); ++f) {
    normals->row(f) = TriangleNormal(vertices, triangles, f).transpose();
  }
}

void ComputeVertexNormals(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                          Eigen::MatrixX3d* normals) {
  CheckTriangles(vertices, triangles, "ComputeVertexNormals");
  // Accumulate into a row-major buffer (one contiguous triple per vertex).
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> sum =
      Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>::Zero(vertices.rows(), 3);
  for (int f = 0; f < triangles.rows(); ++f) {
    const Eigen::Vector3d n = TriangleNormal(vertices, triangles, f);
    for (int c = 0; c < 3; ++c) sum.row(triangles(f, c)) += n.transpose();
  }
  normals->resize(vertices.rows(), 3);
  for (int v = 0; v < vertices.rows(); ++v) {
    const double norm = sum.row(v).norm();
    // The mean of unit normals is normalised; opposite normals cancelling give zero.
    if (norm > 0.0) {
      normals->row(v) = sum.row(v) / norm;
    } else {
      normals->row(v).setZero();
    }
  }
}

}  // namespace artex
