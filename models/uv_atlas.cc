#include "models/uv_atlas.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <queue>
#include <sstream>
#include <unordered_map>
#include <unordered_set>
#include <utility>

#include <Eigen/Geometry>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <Eigen/SparseLU>

#include "models/error.h"
#include "models/numeric.h"

namespace artex {
namespace {

using Vec2 = Eigen::Vector2d;
using Vec3 = Eigen::Vector3d;

double Cross2(const Vec2& a, const Vec2& b, const Vec2& c) {
  return (b.x() - a.x()) * (c.y() - a.y()) - (b.y() - a.y()) * (c.x() - a.x());
}

struct UnionFind {
  explicit UnionFind(int n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
  int Find(int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void Merge(int a, int b) { parent[Find(a)] = Find(b); }
  std::vector<int> parent;
};

int64_t EdgeKey(int64_t a, int64_t b, int64_t n) { return a < b ? a * n + b : b * n + a; }

// Corners (3 f + q) of the same vertex are glued across edges shared by two triangles of the
// same chart, unless the edge is cut. Returns uv_triangles and the mesh vertex of each uv.
void GlueCorners(const Eigen::MatrixX3i& tris, const Eigen::VectorXi& chart, int64_t nv,
                 const std::unordered_set<int64_t>& cuts, Eigen::MatrixX3i* uv_tris,
                 std::vector<int>* uv_vertex) {
  const int nf = static_cast<int>(tris.rows());
  std::unordered_map<int64_t, std::pair<int, int>> first;  // edge -> (face, local edge)
  first.reserve(3 * nf);
  UnionFind uf(3 * nf);
  for (int f = 0; f < nf; ++f) {
    for (int q = 0; q < 3; ++q) {
      const int a = tris(f, q), b = tris(f, (q + 1) % 3);
      const int64_t key = EdgeKey(a, b, nv);
      auto it = first.find(key);
      if (it == first.end()) {
        first.emplace(key, std::make_pair(f, q));
        continue;
      }
      const int g = it->second.first;
      if (chart[g] != chart[f] || cuts.count(key)) continue;
      for (int r = 0; r < 3; ++r) {
        if (tris(g, r) == a) uf.Merge(3 * f + q, 3 * g + r);
        if (tris(g, r) == b) uf.Merge(3 * f + (q + 1) % 3, 3 * g + r);
      }
    }
  }
  std::vector<int> id(3 * nf, -1);
  uv_tris->resize(nf, 3);
  uv_vertex->clear();
  for (int c = 0; c < 3 * nf; ++c) {
    const int root = uf.Find(c);
    if (id[root] < 0) {
      id[root] = static_cast<int>(uv_vertex->size());
      uv_vertex->push_back(tris(c / 3, c % 3));
    }
    (*uv_tris)(c / 3, c % 3) = id[root];
  }
}

// One chart in local numbering.
struct ChartMesh {
  std::vector<int> faces;               // global triangle ids
  std::vector<int> uv_ids;              // local -> global uv index
  std::vector<std::array<int, 3>> tri;  // local uv indices
  std::vector<std::vector<int>> loops;  // boundary loops (local ids, in face orientation)
  int num_edges = 0;
  bool bowtie = false;
  int euler() const {
    return static_cast<int>(uv_ids.size()) - num_edges + static_cast<int>(tri.size());
  }
};

ChartMesh BuildChartMesh(const std::vector<int>& faces, const Eigen::MatrixX3i& uv_tris) {
  ChartMesh cm;
  cm.faces = faces;
  std::unordered_map<int, int> local;
  for (int f : faces) {
    std::array<int, 3> t;
    for (int q = 0; q < 3; ++q) {
      const int g = uv_tris(f, q);
      auto it = local.find(g);
      if (it == local.end()) {
        it = local.emplace(g, static_cast<int>(cm.uv_ids.size())).first;
        cm.uv_ids.push_back(g);
      }
      t[q] = it->second;
    }
    cm.tri.push_back(t);
  }
  const int64_t n = static_cast<int64_t>(cm.uv_ids.size());
  std::unordered_map<int64_t, int> directed;
  for (const auto& t : cm.tri) {
    for (int q = 0; q < 3; ++q) directed[t[q] * n + t[(q + 1) % 3]]++;
  }
  std::unordered_map<int, int> next;
  int64_t undirected2 = 0;
  for (const auto& [key, count] : directed) {
    const int64_t a = key / n, b = key % n;
    undirected2 += directed.count(b * n + a) ? 1 : 2;
    if (!directed.count(b * n + a)) {
      if (next.count(static_cast<int>(a))) cm.bowtie = true;
      next[static_cast<int>(a)] = static_cast<int>(b);
    }
  }
  cm.num_edges = static_cast<int>(undirected2 / 2);
  // Deterministic loop order: start from the smallest unvisited boundary vertex.
  std::vector<int> starts;
  for (const auto& [a, b] : next) starts.push_back(a);
  std::sort(starts.begin(), starts.end());
  std::unordered_set<int> visited;
  for (int s : starts) {
    if (visited.count(s)) continue;
    std::vector<int> loop;
    int x = s;
    while (!visited.count(x)) {
      visited.insert(x);
      loop.push_back(x);
      auto it = next.find(x);
      if (it == next.end()) break;
      x = it->second;
    }
    cm.loops.push_back(loop);
  }
  return cm;
}

bool Connected(const ChartMesh& cm) {
  UnionFind uf(static_cast<int>(cm.uv_ids.size()));
  for (const auto& t : cm.tri) {
    uf.Merge(t[0], t[1]);
    uf.Merge(t[1], t[2]);
  }
  int roots = 0;
  for (int v = 0; v < static_cast<int>(cm.uv_ids.size()); ++v) roots += uf.Find(v) == v;
  return roots == 1;
}

bool IsDisc(const ChartMesh& cm) {
  return !cm.bowtie && cm.loops.size() == 1 && cm.euler() == 1 && Connected(cm);
}

// Cheapest interior path from loop 0 to loop 1 of an annulus; returns local vertex ids.
std::vector<int> SeamPath(const ChartMesh& cm, const std::vector<Vec3>& pos,
                          const std::vector<double>& cost, double weight) {
  const int n = static_cast<int>(cm.uv_ids.size());
  std::vector<std::vector<int>> adj(n);
  for (const auto& t : cm.tri) {
    for (int q = 0; q < 3; ++q) {
      adj[t[q]].push_back(t[(q + 1) % 3]);
      adj[t[(q + 1) % 3]].push_back(t[q]);
    }
  }
  for (auto& a : adj) {
    std::sort(a.begin(), a.end());
    a.erase(std::unique(a.begin(), a.end()), a.end());
  }
  std::vector<int> loop_of(n, -1);
  for (int l = 0; l < 2; ++l) {
    for (int v : cm.loops[l]) loop_of[v] = l;
  }
  // Multi-source: the path may start anywhere on the first loop.
  std::vector<double> dist(n, kInf);
  std::vector<int> prev(n, -1);
  using Item = std::pair<double, int>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
  for (int v : cm.loops[0]) {
    dist[v] = 0.0;
    queue.emplace(0.0, v);
  }
  while (!queue.empty()) {
    const auto [d, v] = queue.top();
    queue.pop();
    if (d > dist[v] || loop_of[v] == 1) continue;
    for (int w : adj[v]) {
      if (loop_of[w] == 0) continue;  // only the start lies on the first loop
      const double len = (pos[v] - pos[w]).norm() * (1.0 + weight * 0.5 * (cost[v] + cost[w]));
      if (d + len < dist[w]) {
        dist[w] = d + len;
        prev[w] = v;
        queue.emplace(dist[w], w);
      }
    }
  }
  int end = -1;
  for (int v : cm.loops[1]) {
    if (dist[v] < kInf && (end < 0 || dist[v] < dist[end])) end = v;
  }
  std::vector<int> path;
  if (end < 0) return path;
  for (int v = end; v >= 0; v = prev[v]) path.push_back(v);
  std::reverse(path.begin(), path.end());
  return path;
}

// Local orthonormal 2D coordinates of a triangle (counter-clockwise).
void TriangleFrame(const Vec3& p0, const Vec3& p1, const Vec3& p2, Vec2 x[3]) {
  const Vec3 e1 = (p1 - p0).normalized();
  const Vec3 n = (p1 - p0).cross(p2 - p0).normalized();
  const Vec3 e2 = n.cross(e1);
  x[0] = Vec2::Zero();
  x[1] = Vec2((p1 - p0).norm(), 0.0);
  x[2] = Vec2((p2 - p0).dot(e1), (p2 - p0).dot(e2));
}

// Least-squares conformal map with two pinned boundary vertices (u right, v up).
bool Lscm(const ChartMesh& cm, const std::vector<Vec3>& pos, std::vector<Vec2>* uv) {
  const int n = static_cast<int>(cm.uv_ids.size());
  const std::vector<int>& loop = cm.loops[0];
  // Pins: approximately the two farthest boundary vertices.
  int a = loop[0];
  for (int v : loop) if ((pos[v] - pos[loop[0]]).norm() > (pos[a] - pos[loop[0]]).norm()) a = v;
  int b = a;
  for (int v : loop) if ((pos[v] - pos[a]).norm() > (pos[b] - pos[a]).norm()) b = v;
  if (a == b) return false;
  std::vector<int> var(2 * n, -1);
  int nfree = 0;
  for (int v = 0; v < n; ++v) {
    if (v == a || v == b) continue;
    var[2 * v] = nfree++;
    var[2 * v + 1] = nfree++;
  }
  Eigen::VectorXd pinned = Eigen::VectorXd::Zero(2 * n);
  pinned[2 * b] = (pos[a] - pos[b]).norm();
  std::vector<Eigen::Triplet<double>> trip;
  std::vector<double> rhs;
  int row = 0;
  for (const auto& t : cm.tri) {
    Vec2 x[3];
    TriangleFrame(pos[t[0]], pos[t[1]], pos[t[2]], x);
    const double area = 0.5 * Cross2(x[0], x[1], x[2]);
    if (!(area > 1e-16)) continue;
    const double s = 1.0 / (2.0 * std::sqrt(area));
    double r1 = 0.0, r2 = 0.0;
    for (int j = 0; j < 3; ++j) {
      const Vec2 e = x[(j + 2) % 3] - x[(j + 1) % 3];
      // Cauchy-Riemann residuals u_x - v_y and u_y + v_x with gradient (-e_y, e_x) / 2A.
      const double cu1 = -e.y() * s, cv1 = -e.x() * s;
      const double cu2 = e.x() * s, cv2 = -e.y() * s;
      const int v = t[j];
      if (var[2 * v] >= 0) {
        trip.emplace_back(row, var[2 * v], cu1);
        trip.emplace_back(row, var[2 * v + 1], cv1);
        trip.emplace_back(row + 1, var[2 * v], cu2);
        trip.emplace_back(row + 1, var[2 * v + 1], cv2);
      } else {
        r1 -= cu1 * pinned[2 * v] + cv1 * pinned[2 * v + 1];
        r2 -= cu2 * pinned[2 * v] + cv2 * pinned[2 * v + 1];
      }
    }
    rhs.push_back(r1);
    rhs.push_back(r2);
    row += 2;
  }
  Eigen::SparseMatrix<double> m(row, nfree);
  m.setFromTriplets(trip.begin(), trip.end());
  const Eigen::SparseMatrix<double> normal = m.transpose() * m;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver(normal);
  if (solver.info() != Eigen::Success) return false;
  const Eigen::VectorXd x =
      solver.solve(m.transpose() * Eigen::Map<const Eigen::VectorXd>(rhs.data(), row));
  if (solver.info() != Eigen::Success || !x.allFinite()) return false;
  uv->assign(n, Vec2::Zero());
  for (int v = 0; v < n; ++v) {
    if (var[2 * v] >= 0) (*uv)[v] = Vec2(x[var[2 * v]], x[var[2 * v + 1]]);
    else (*uv)[v] = Vec2(pinned[2 * v], pinned[2 * v + 1]);
  }
  return true;
}

bool SegmentsIntersect(const Vec2& p, const Vec2& q, const Vec2& r, const Vec2& s) {
  const double d1 = Cross2(p, q, r), d2 = Cross2(p, q, s);
  const double d3 = Cross2(r, s, p), d4 = Cross2(r, s, q);
  return ((d1 > 0) != (d2 > 0)) && ((d3 > 0) != (d4 > 0)) && d1 != 0 && d2 != 0 && d3 != 0 &&
         d4 != 0;
}

// A map without folds whose boundary is a simple polygon is injective.
bool IsInjective(const ChartMesh& cm, const std::vector<Vec3>& pos, const std::vector<Vec2>& uv,
                 double min_ratio) {
  double area3 = 0.0, area2 = 0.0;
  for (const auto& t : cm.tri) {
    area3 += 0.5 * (pos[t[1]] - pos[t[0]]).cross(pos[t[2]] - pos[t[0]]).norm();
    area2 += 0.5 * Cross2(uv[t[0]], uv[t[1]], uv[t[2]]);
  }
  if (!(area2 > 0.0)) return false;
  const double ratio = area2 / area3;
  for (const auto& t : cm.tri) {
    const double a3 = 0.5 * (pos[t[1]] - pos[t[0]]).cross(pos[t[2]] - pos[t[0]]).norm();
    const double a2 = 0.5 * Cross2(uv[t[0]], uv[t[1]], uv[t[2]]);
    if (!(a2 > min_ratio * ratio * a3) || !(a2 > 0.0)) return false;
  }
  const std::vector<int>& loop = cm.loops[0];
  const int m = static_cast<int>(loop.size());
  // Boundary self-intersection test, O(m^2) with a bounding-box prefilter.
  for (int i = 0; i < m; ++i) {
    const Vec2& p = uv[loop[i]];
    const Vec2& q = uv[loop[(i + 1) % m]];
    for (int j = i + 2; j < m; ++j) {
      if (i == 0 && j == m - 1) continue;
      const Vec2& r = uv[loop[j]];
      const Vec2& s = uv[loop[(j + 1) % m]];
      if (std::max(p.x(), q.x()) < std::min(r.x(), s.x()) ||
          std::max(r.x(), s.x()) < std::min(p.x(), q.x()) ||
          std::max(p.y(), q.y()) < std::min(r.y(), s.y()) ||
          std::max(r.y(), s.y()) < std::min(p.y(), q.y()))
        continue;
      if (SegmentsIntersect(p, q, r, s)) return false;
    }
  }
  return true;
}

// Tutte embedding with mean-value weights onto a circle (boundary by arc length): injective
// for any disc (Floater 2003).
bool Tutte(const ChartMesh& cm, const std::vector<Vec3>& pos, std::vector<Vec2>* uv) {
  const int n = static_cast<int>(cm.uv_ids.size());
  const std::vector<int>& loop = cm.loops[0];
  std::vector<int> boundary_index(n, -1);
  double perimeter = 0.0;
  for (size_t i = 0; i < loop.size(); ++i) {
    boundary_index[loop[i]] = static_cast<int>(i);
    perimeter += (pos[loop[(i + 1) % loop.size()]] - pos[loop[i]]).norm();
  }
  uv->assign(n, Vec2::Zero());
  double acc = 0.0;
  for (size_t i = 0; i < loop.size(); ++i) {
    const double angle = 2.0 * kPi * acc / perimeter;
    (*uv)[loop[i]] = Vec2(std::cos(angle), std::sin(angle));
    acc += (pos[loop[(i + 1) % loop.size()]] - pos[loop[i]]).norm();
  }
  std::vector<int> var(n, -1);
  int nfree = 0;
  for (int v = 0; v < n; ++v) {
    if (boundary_index[v] < 0) var[v] = nfree++;
  }
  if (nfree == 0) return true;
  // Mean-value weight of edge (i, j) from the angles at i in the two triangles on (i, j).
  std::map<std::pair<int, int>, double> weight;
  for (const auto& t : cm.tri) {
    for (int q = 0; q < 3; ++q) {
      const int i = t[q], j = t[(q + 1) % 3], k = t[(q + 2) % 3];
      const Vec3 eij = pos[j] - pos[i], eik = pos[k] - pos[i];
      const double angle = std::atan2(eij.cross(eik).norm(), eij.dot(eik));
      const double tan_half = std::tan(0.5 * angle);
      weight[{i, j}] += tan_half / std::max(eij.norm(), 1e-12);
      weight[{i, k}] += tan_half / std::max(eik.norm(), 1e-12);
    }
  }
  std::vector<Eigen::Triplet<double>> trip;
  Eigen::MatrixX2d rhs = Eigen::MatrixX2d::Zero(nfree, 2);
  std::vector<double> diag(nfree, 0.0);
  for (const auto& [edge, w] : weight) {
    const int i = edge.first, j = edge.second;
    if (var[i] < 0) continue;
    diag[var[i]] += w;
    if (var[j] >= 0) trip.emplace_back(var[i], var[j], -w);
    else rhs.row(var[i]) += w * (*uv)[j].transpose();
  }
  for (int i = 0; i < nfree; ++i) trip.emplace_back(i, i, diag[i]);
  Eigen::SparseMatrix<double> m(nfree, nfree);
  m.setFromTriplets(trip.begin(), trip.end());
  Eigen::SparseLU<Eigen::SparseMatrix<double>> solver;
  solver.compute(m);
  if (solver.info() != Eigen::Success) return false;
  const Eigen::MatrixX2d x = solver.solve(rhs);
  if (solver.info() != Eigen::Success || !x.allFinite()) return false;
  for (int v = 0; v < n; ++v) {
    if (var[v] >= 0) (*uv)[v] = x.row(var[v]).transpose();
  }
  return true;
}

struct PackedChart {
  std::vector<Vec2> uv;  // local, metres, min corner at the origin
  double width = 0.0, height = 0.0;
};

// Rotates the chart to the tightest bounding box (landscape) and moves it to the origin.
void Orient(int steps, PackedChart* chart) {
  double best_area = kInf, best_angle = 0.0;
  for (int s = 0; s < steps; ++s) {
    const double angle = 0.5 * kPi * s / steps;
    const double c = std::cos(angle), sn = std::sin(angle);
    Vec2 lo = Vec2::Constant(kInf), hi = Vec2::Constant(-kInf);
    for (const Vec2& p : chart->uv) {
      const Vec2 r(c * p.x() - sn * p.y(), sn * p.x() + c * p.y());
      lo = lo.cwiseMin(r);
      hi = hi.cwiseMax(r);
    }
    const double area = (hi - lo).prod();
    if (area < best_area - 1e-15) {
      best_area = area;
      best_angle = angle;
    }
  }
  auto rotate = [&](double angle) {
    const double c = std::cos(angle), sn = std::sin(angle);
    for (Vec2& p : chart->uv) p = Vec2(c * p.x() - sn * p.y(), sn * p.x() + c * p.y());
  };
  rotate(best_angle);
  Vec2 lo = Vec2::Constant(kInf), hi = Vec2::Constant(-kInf);
  for (const Vec2& p : chart->uv) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  if (hi.y() - lo.y() > hi.x() - lo.x()) {
    rotate(0.5 * kPi);
    lo = Vec2::Constant(kInf);
    hi = Vec2::Constant(-kInf);
    for (const Vec2& p : chart->uv) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  }
  for (Vec2& p : chart->uv) p -= lo;
  chart->width = hi.x() - lo.x();
  chart->height = hi.y() - lo.y();
}

// Shelf packing of boxes (scaled by `scale`) into the unit square; returns false if they do not
// fit. `order` lists charts by decreasing height.
bool Shelf(const std::vector<PackedChart>& charts, const std::vector<int>& order, double scale,
           double pad, std::vector<Vec2>* offsets) {
  offsets->assign(charts.size(), Vec2::Zero());
  double x = pad, y = pad, row = 0.0;
  for (int c : order) {
    const double w = charts[c].width * scale, h = charts[c].height * scale;
    if (w + 2.0 * pad > 1.0) return false;
    if (x + w + pad > 1.0) {
      y += row + pad;
      x = pad;
      row = 0.0;
    }
    (*offsets)[c] = Vec2(x, y);
    x += w + pad;
    row = std::max(row, h);
  }
  return y + row + pad <= 1.0;
}

}  // namespace

bool UvAtlasOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (atlas_size < 16) {
    msg << "atlas_size: expected at least 16 texels, found " << atlas_size;
  } else if (!(padding_texels >= 0.0 && padding_texels <= atlas_size / 8.0)) {
    msg << "padding_texels: expected a value in [0, atlas_size / 8], found " << padding_texels;
  } else if (rotation_steps < 1 || rotation_steps > 3600) {
    msg << "rotation_steps: expected a count in [1, 3600], found " << rotation_steps;
  } else if (!(seam_cost_weight >= 0.0 && std::isfinite(seam_cost_weight))) {
    msg << "seam_cost_weight: expected a finite value >= 0, found " << seam_cost_weight;
  } else if (packing_iterations < 1 || packing_iterations > 200) {
    msg << "packing_iterations: expected a count in [1, 200], found " << packing_iterations;
  } else if (!(min_uv_area_ratio >= 0.0 && min_uv_area_ratio < 1.0)) {
    msg << "min_uv_area_ratio: expected a value in [0, 1), found " << min_uv_area_ratio;
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

double UvSignedArea(const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                    const Eigen::Vector2d& c) {
  return -0.5 * Cross2(a, b, c);  // v points down in the image
}

void MeasureUvAtlas(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                    const Eigen::MatrixX2d& uvs, const Eigen::MatrixX3i& uv_triangles,
                    int atlas_size, UvAtlasSummary* summary) {
  const int nf = static_cast<int>(triangles.rows());
  std::vector<std::pair<double, double>> density;  // (relative density, 3D area)
  double total3 = 0.0, total2 = 0.0;
  std::vector<double> a3(nf), a2(nf);
  for (int f = 0; f < nf; ++f) {
    const Vec3 p0 = vertices.row(triangles(f, 0)).transpose();
    const Vec3 p1 = vertices.row(triangles(f, 1)).transpose();
    const Vec3 p2 = vertices.row(triangles(f, 2)).transpose();
    a3[f] = 0.5 * (p1 - p0).cross(p2 - p0).norm();
    a2[f] = std::abs(UvSignedArea(uvs.row(uv_triangles(f, 0)).transpose(),
                                  uvs.row(uv_triangles(f, 1)).transpose(),
                                  uvs.row(uv_triangles(f, 2)).transpose()));
    total3 += a3[f];
    total2 += a2[f];
  }
  summary->coverage = total2;
  if (total3 <= 0.0 || total2 <= 0.0) return;
  const double mean = std::sqrt(total2 / total3);
  summary->texels_per_metre = mean * atlas_size;
  for (int f = 0; f < nf; ++f) {
    if (a3[f] <= 1e-14) continue;
    density.emplace_back(std::sqrt(a2[f] / a3[f]) / mean, a3[f]);
  }
  std::sort(density.begin(), density.end());
  summary->density_min = density.front().first;
  summary->density_max = density.back().first;
  double acc = 0.0;
  summary->density_p05 = density.front().first;
  summary->density_p95 = density.back().first;
  bool p05 = false, p95 = false;
  for (const auto& [d, w] : density) {
    acc += w / total3;
    if (!p05 && acc >= 0.05) {
      summary->density_p05 = d;
      p05 = true;
    }
    if (!p95 && acc >= 0.95) {
      summary->density_p95 = d;
      p95 = true;
    }
  }
}

void BuildUvAtlas(const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles,
                  const Eigen::VectorXi& triangle_chart, const Eigen::VectorXd& seam_cost,
                  const UvAtlasOptions& options, UvAtlas* atlas, UvAtlasSummary* summary) {
  std::string error;
  if (!options.IsValid(&error)) throw Error("uv atlas options: " + error);
  const int nv = static_cast<int>(vertices.rows());
  const int nf = static_cast<int>(triangles.rows());
  if (triangle_chart.size() != nf) {
    throw Error("uv atlas: triangle_chart must have " + std::to_string(nf) + " entries, found " +
                std::to_string(triangle_chart.size()));
  }
  if (seam_cost.size() != 0 && seam_cost.size() != nv) {
    throw Error("uv atlas: seam_cost must be empty or have " + std::to_string(nv) +
                " entries, found " + std::to_string(seam_cost.size()));
  }
  if (nf == 0 || triangle_chart.minCoeff() < 0) {
    throw Error("uv atlas: expected triangles with chart ids >= 0");
  }
  UvAtlasSummary local;
  UvAtlasSummary& sum = summary ? *summary : local;
  sum = UvAtlasSummary();

  std::map<int, std::vector<int>> chart_faces;
  for (int f = 0; f < nf; ++f) chart_faces[triangle_chart[f]].push_back(f);
  sum.num_charts = static_cast<int>(chart_faces.size());

  // Glue, open annuli along seam paths, glue again.
  std::unordered_set<int64_t> cuts;
  Eigen::MatrixX3i uv_tris;
  std::vector<int> uv_vertex;
  GlueCorners(triangles, triangle_chart, nv, cuts, &uv_tris, &uv_vertex);
  for (const auto& [id, faces] : chart_faces) {
    const ChartMesh cm = BuildChartMesh(faces, uv_tris);
    if (IsDisc(cm)) continue;
    if (cm.bowtie || cm.loops.size() != 2 || cm.euler() != 0 || !Connected(cm)) {
      std::ostringstream msg;
      msg << "uv atlas: chart " << id << " is neither a disc nor an annulus (" << cm.uv_ids.size()
          << " vertices, " << cm.num_edges << " edges, " << cm.tri.size() << " triangles, "
          << cm.loops.size() << " boundary loops" << (cm.bowtie ? ", pinched boundary" : "")
          << ")";
      throw Error(msg.str());
    }
    std::vector<Vec3> pos(cm.uv_ids.size());
    std::vector<double> cost(cm.uv_ids.size(), 0.0);
    for (size_t v = 0; v < cm.uv_ids.size(); ++v) {
      const int mv = uv_vertex[cm.uv_ids[v]];
      pos[v] = vertices.row(mv).transpose();
      if (seam_cost.size() != 0) cost[v] = seam_cost[mv];
    }
    const std::vector<int> path = SeamPath(cm, pos, cost, options.seam_cost_weight);
    if (path.size() < 2) {
      throw Error("uv atlas: no seam path across annulus chart " + std::to_string(id));
    }
    for (size_t i = 0; i + 1 < path.size(); ++i) {
      cuts.insert(EdgeKey(uv_vertex[cm.uv_ids[path[i]]], uv_vertex[cm.uv_ids[path[i + 1]]], nv));
    }
    ++sum.num_cylinder_cuts;
  }
  if (!cuts.empty()) GlueCorners(triangles, triangle_chart, nv, cuts, &uv_tris, &uv_vertex);

  // Parameterise each chart, in metres.
  std::vector<PackedChart> packed;
  std::vector<ChartMesh> meshes;
  for (const auto& [id, faces] : chart_faces) {
    ChartMesh cm = BuildChartMesh(faces, uv_tris);
    if (!IsDisc(cm)) {
      throw Error("uv atlas: chart " + std::to_string(id) + " is not a disc after cutting");
    }
    std::vector<Vec3> pos(cm.uv_ids.size());
    for (size_t v = 0; v < cm.uv_ids.size(); ++v) {
      pos[v] = vertices.row(uv_vertex[cm.uv_ids[v]]).transpose();
    }
    std::vector<Vec2> uv;
    if (!Lscm(cm, pos, &uv) || !IsInjective(cm, pos, uv, options.min_uv_area_ratio)) {
      ++sum.num_tutte_fallbacks;
      if (!Tutte(cm, pos, &uv) || !IsInjective(cm, pos, uv, 0.0)) {
        throw Error("uv atlas: could not parameterise chart " + std::to_string(id));
      }
    }
    double area3 = 0.0, area2 = 0.0;
    for (const auto& t : cm.tri) {
      area3 += 0.5 * (pos[t[1]] - pos[t[0]]).cross(pos[t[2]] - pos[t[0]]).norm();
      area2 += 0.5 * Cross2(uv[t[0]], uv[t[1]], uv[t[2]]);
    }
    const double s = std::sqrt(area3 / area2);
    PackedChart pc;
    // Mirror v so that charts keep their orientation in the image (v downwards).
    for (const Vec2& p : uv) pc.uv.push_back(Vec2(p.x() * s, -p.y() * s));
    Orient(options.rotation_steps, &pc);
    packed.push_back(std::move(pc));
    meshes.push_back(std::move(cm));
  }

  // Shelf packing: the largest scale that fits, by bisection.
  std::vector<int> order(packed.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return packed[a].height > packed[b].height; });
  const double pad = options.padding_texels / options.atlas_size;
  double total = 0.0;
  for (const PackedChart& pc : packed) total += pc.width * pc.height;
  double lo = 0.0, hi = 1.0 / std::sqrt(total);
  std::vector<Vec2> offsets;
  for (int it = 0; it < options.packing_iterations; ++it) {
    const double mid = 0.5 * (lo + hi);
    if (Shelf(packed, order, mid, pad, &offsets)) lo = mid; else hi = mid;
  }
  if (!(lo > 0.0) || !Shelf(packed, order, lo, pad, &offsets)) {
    throw Error("uv atlas: charts do not fit the atlas with padding " +
                std::to_string(options.padding_texels) + " texels");
  }

  atlas->uvs.resize(static_cast<Eigen::Index>(uv_vertex.size()), 2);
  atlas->uv_triangles = uv_tris;
  atlas->uv_vertex = Eigen::Map<const Eigen::VectorXi>(uv_vertex.data(),
                                                       static_cast<Eigen::Index>(uv_vertex.size()));
  for (size_t c = 0; c < meshes.size(); ++c) {
    for (size_t v = 0; v < meshes[c].uv_ids.size(); ++v) {
      const Vec2 p = offsets[c] + lo * packed[c].uv[v];
      atlas->uvs.row(meshes[c].uv_ids[v]) =
          p.cwiseMax(Vec2::Zero()).cwiseMin(Vec2::Ones()).transpose();
    }
  }
  MeasureUvAtlas(vertices, triangles, atlas->uvs, atlas->uv_triangles, options.atlas_size, &sum);
}

}  // namespace artex
