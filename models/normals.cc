#include "models/normals.h"

#include <Eigen/Geometry>
#include <algorithm>
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

IncidentTriangles FindIncidentTriangles(const Eigen::MatrixX3i& triangles,
                                        const std::vector<int>& which, int num_vertices) {
  if (triangles.rows() > 0 && (triangles.minCoeff() < 0 || triangles.maxCoeff() >= num_vertices)) {
    std::ostringstream msg;
    msg << "FindIncidentTriangles: triangles: expected vertex indices in [0, " << num_vertices
        << "), found " << triangles.minCoeff() << ".." << triangles.maxCoeff();
    throw Error(msg.str());
  }
  // Each vertex's position in `which` (-1: not asked for).
  std::vector<int> slot(num_vertices, -1);
  for (size_t i = 0; i < which.size(); ++i) {
    if (which[i] < 0 || which[i] >= num_vertices) {
      std::ostringstream msg;
      msg << "FindIncidentTriangles: which[" << i << "]: expected a vertex index in [0, "
          << num_vertices << "), found " << which[i];
      throw Error(msg.str());
    }
    if (slot[which[i]] >= 0) {
      std::ostringstream msg;
      msg << "FindIncidentTriangles: which: vertex " << which[i] << " listed twice";
      throw Error(msg.str());
    }
    slot[which[i]] = static_cast<int>(i);
  }
  IncidentTriangles result;
  result.offset.assign(which.size() + 1, 0);
  for (int f = 0; f < triangles.rows(); ++f) {
    for (int c = 0; c < 3; ++c) {
      if (slot[triangles(f, c)] >= 0) ++result.offset[slot[triangles(f, c)] + 1];
    }
  }
  for (size_t i = 0; i < which.size(); ++i) result.offset[i + 1] += result.offset[i];
  result.triangles.resize(result.offset.back());
  std::vector<int> next(result.offset.begin(), result.offset.end() - 1);
  for (int f = 0; f < triangles.rows(); ++f) {  // ascending f per vertex
    for (int c = 0; c < 3; ++c) {
      const int i = slot[triangles(f, c)];
      if (i >= 0) result.triangles[next[i]++] = f;
    }
  }
  result.num_vertices = num_vertices;
  result.num_triangles = static_cast<int>(triangles.rows());
  return result;
}

void ComputeVertexNormalsOf(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                            const IncidentTriangles& incident, Eigen::MatrixX3d* normals) {
  if (vertices.rows() != incident.num_vertices || triangles.rows() != incident.num_triangles) {
    std::ostringstream msg;
    msg << "ComputeVertexNormalsOf: expected the mesh of the incident triangles ("
        << incident.num_vertices << " vertices, " << incident.num_triangles << " triangles), found "
        << vertices.rows() << " vertices, " << triangles.rows() << " triangles";
    throw Error(msg.str());
  }
  const int n = std::max(0, static_cast<int>(incident.offset.size()) - 1);
  // The same types and operations, in the same order, as ComputeVertexNormals per vertex.
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> sum(1, 3);
  normals->resize(n, 3);
  for (int i = 0; i < n; ++i) {
    sum.setZero();
    for (int k = incident.offset[i]; k < incident.offset[i + 1]; ++k) {
      sum.row(0) += TriangleNormal(vertices, triangles, incident.triangles[k]).transpose();
    }
    const double norm = sum.row(0).norm();
    if (norm > 0.0) {
      normals->row(i) = sum.row(0) / norm;
    } else {
      normals->row(i).setZero();
    }
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
