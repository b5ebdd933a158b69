// SummarizeTemplate (models/template_io.h): counts, topology and UV coverage of a template.
#include <Eigen/Core>
#include <algorithm>
#include <string>
#include <utility>
#include <vector>

#include "models/error.h"
#include "models/template_io.h"
#include "models/uv_raster.h"

namespace artex {

TemplateSummary SummarizeTemplate(const Template& tmpl, const TemplateSummaryOptions& options) {
  std::string error;
  if (!tmpl.IsValid(&error)) throw Error("template: " + error);
  if (options.uv_grid < 16) {
    throw Error("TemplateSummaryOptions.uv_grid: expected at least 16, found " +
                std::to_string(options.uv_grid));
  }
  TemplateSummary s;
  s.num_vertices = tmpl.num_vertices();
  s.num_triangles = tmpl.num_triangles();
  s.num_joints = tmpl.num_joints();
  s.num_pose_parameters = tmpl.num_pose_parameters();
  s.vertices_per_joint.assign(s.num_joints, 0);
  for (int v = 0; v < s.num_vertices; ++v) ++s.vertices_per_joint[tmpl.vertex_joint[v]];
  s.bbox_min = tmpl.vertices.colwise().minCoeff().transpose();
  s.bbox_max = tmpl.vertices.colwise().maxCoeff().transpose();

  // Edges: undirected incidence counts and directed duplicates.
  std::vector<std::pair<int, int>> directed;
  directed.reserve(static_cast<size_t>(s.num_triangles) * 3);
  for (int f = 0; f < s.num_triangles; ++f) {
    for (int c = 0; c < 3; ++c)
      directed.emplace_back(tmpl.triangles(f, c), tmpl.triangles(f, (c + 1) % 3));
  }
  std::vector<std::pair<int, int>> undirected(directed.size());
  for (size_t i = 0; i < directed.size(); ++i) {
    undirected[i] = {std::min(directed[i].first, directed[i].second),
                     std::max(directed[i].first, directed[i].second)};
  }
  std::sort(directed.begin(), directed.end());
  std::sort(undirected.begin(), undirected.end());
  int num_edges = 0;
  for (size_t i = 0; i < undirected.size();) {
    size_t j = i;
    while (j < undirected.size() && undirected[j] == undirected[i]) ++j;
    const size_t count = j - i;
    ++num_edges;
    if (count == 1) ++s.boundary_edges;
    if (count > 2) ++s.non_manifold_edges;
    i = j;
  }
  for (size_t i = 1; i < directed.size(); ++i) {
    if (directed[i] == directed[i - 1]) ++s.misoriented_edges;
  }

  // Components over referenced vertices (union-find).
  std::vector<int> parent(s.num_vertices);
  for (int v = 0; v < s.num_vertices; ++v) parent[v] = v;
  auto find = [&parent](int x) {
    while (parent[x] != x) {
      parent[x] = parent[parent[x]];
      x = parent[x];
    }
    return x;
  };
  std::vector<char> referenced(s.num_vertices, 0);
  for (int f = 0; f < s.num_triangles; ++f) {
    for (int c = 0; c < 3; ++c) {
      referenced[tmpl.triangles(f, c)] = 1;
      const int a = find(tmpl.triangles(f, c)), b = find(tmpl.triangles(f, (c + 1) % 3));
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
  }
  int num_referenced = 0;
  for (int v = 0; v < s.num_vertices; ++v) {
    if (!referenced[v]) {
      ++s.unreferenced_vertices;
      continue;
    }
    ++num_referenced;
    if (find(v) == v) ++s.components;
  }
  s.euler_characteristic = num_referenced - num_edges + s.num_triangles;

  if (tmpl.has_uvs()) {
    s.num_uvs = static_cast<int>(tmpl.uvs.rows());
    // Rasterise UV triangles: cell centres inside a triangle (inclusive edges) are covered.
    const int n = options.uv_grid;
    std::vector<unsigned char> count(static_cast<size_t>(n) * n, 0);
    for (int f = 0; f < s.num_triangles; ++f) {
      const UvTriangleCells t = UvTriangleOnGrid(tmpl, f, n);
      if (t.area2 == 0.0) continue;
      ForEachCellInside(t, [&](int x, int y) {
        unsigned char& cell = count[static_cast<size_t>(y) * n + x];
        if (cell < 255) ++cell;
      });
    }
    size_t covered = 0, multiple = 0;
    for (unsigned char c : count) {
      covered += c > 0;
      multiple += c > 1;
    }
    s.uv_coverage = static_cast<double>(covered) / (static_cast<double>(n) * n);
    s.uv_overlap = covered > 0 ? static_cast<double>(multiple) / covered : 0.0;
  }
  if (tmpl.triangle_chart.size() == s.num_triangles && s.num_triangles > 0) {
    std::vector<int> charts(tmpl.triangle_chart.data(),
                            tmpl.triangle_chart.data() + tmpl.triangle_chart.size());
    std::sort(charts.begin(), charts.end());
    s.num_charts = static_cast<int>(std::unique(charts.begin(), charts.end()) - charts.begin());
  }
  return s;
}

}  // namespace artex
