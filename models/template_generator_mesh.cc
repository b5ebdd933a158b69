// Template generator's surfaces (template_generator_internal.h): iso-surface, remeshing.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <unordered_map>
#include <utility>
#include <vector>

#include "models/error.h"
#include "models/template_generator_internal.h"

namespace artex {
namespace generator_internal {
namespace {

// Iso-surface vertices stay this far (fraction of the edge) from grid points, so that marching
// tetrahedra produce no zero-length edges.
constexpr double kEdgeClamp = 0.02;
// Isotropic remeshing (Botsch & Kobbelt 2004): split above 4/3, collapse below 4/5 of the target.
constexpr double kSplitFactor = 4.0 / 3.0;
constexpr double kCollapseFactor = 4.0 / 5.0;
// A collapse may turn no incident face normal by more than acos(0.2) ~ 78 degrees; no edge is
// flipped across a dihedral angle above 60 degrees (cos 0.5).
constexpr double kCollapseNormalCosine = 0.2;
constexpr double kFlipCreaseCosine = 0.5;
// Newton projection onto f = 0: step cap (fraction of the target edge length) and the forward
// difference step (fraction of the stature).
constexpr double kMaxProjectionStep = 0.5;
constexpr double kGradientStep = 1e-5;

}  // namespace

// ----------------------------------------------------------------------------------------------
// Iso-surface extraction: marching tetrahedra on the Kuhn subdivision of a regular grid
// (consistent across cells, so the result is a closed 2-manifold for a field without zeros at
// grid points).

TriangleMesh ExtractIsoSurface(const Body& body, double cell) {
  const Vec3 lo = body.box_min - Vec3::Constant(2.0 * cell);
  const Vec3 hi = body.box_max + Vec3::Constant(2.0 * cell);
  const int nx = static_cast<int>(std::ceil((hi.x() - lo.x()) / cell)) + 1;
  const int ny = static_cast<int>(std::ceil((hi.y() - lo.y()) / cell)) + 1;
  const int nz = static_cast<int>(std::ceil((hi.z() - lo.z()) / cell)) + 1;
  auto index = [&](int i, int j, int k) { return (static_cast<int64_t>(k) * ny + j) * nx + i; };
  auto point = [&](int i, int j, int k) -> Vec3 { return lo + cell * Vec3(i, j, k); };
  // Coarse-to-fine sampling: blocks of kBlock^3 cells whose corners are all farther from the
  // surface than (safety * block diagonal) cannot contain it; their points only need the sign.
  constexpr int kBlock = 4;
  constexpr double kSafety = 1.5;
  const int bx = (nx - 1 + kBlock - 1) / kBlock, by = (ny - 1 + kBlock - 1) / kBlock,
            bz = (nz - 1 + kBlock - 1) / kBlock;
  auto coarse_index = [&](int i, int j, int k) {
    return (static_cast<int64_t>(k) * (by + 1) + j) * (bx + 1) + i;
  };
  std::vector<float> coarse(static_cast<size_t>(bx + 1) * (by + 1) * (bz + 1));
  auto sample = [&](int i, int j, int k) {
    double f = body.Field(point(i, j, k));
    if (f == 0.0) f = 1e-12;  // no grid value exactly on the iso-level
    return static_cast<float>(f);
  };
  tbb::parallel_for(tbb::blocked_range<int>(0, bz + 1), [&](const tbb::blocked_range<int>& r) {
    for (int k = r.begin(); k < r.end(); ++k) {
      for (int j = 0; j <= by; ++j) {
        for (int i = 0; i <= bx; ++i)
          coarse[coarse_index(i, j, k)] = sample(i * kBlock, j * kBlock, k * kBlock);
      }
    }
  });
  const double threshold = kSafety * kBlock * cell * std::sqrt(3.0);
  auto block_index = [&](int ib, int jb, int kb) {
    return (static_cast<int64_t>(kb) * by + jb) * bx + ib;
  };
  std::vector<char> near(static_cast<size_t>(bx) * by * bz);
  std::vector<float> block_sign(near.size());
  for (int kb = 0; kb < bz; ++kb) {
    for (int jb = 0; jb < by; ++jb) {
      for (int ib = 0; ib < bx; ++ib) {
        float min_abs = std::numeric_limits<float>::infinity();
        float corner = 0.0f;
        for (int c = 0; c < 8; ++c) {
          corner = coarse[coarse_index(ib + (c & 1), jb + ((c >> 1) & 1), kb + ((c >> 2) & 1))];
          min_abs = std::min(min_abs, std::abs(corner));
        }
        near[block_index(ib, jb, kb)] = min_abs < threshold;
        block_sign[block_index(ib, jb, kb)] = corner;
      }
    }
  }
  // A grid point is sampled exactly when one of the blocks containing it is near the surface;
  // far blocks cannot contain the surface, so elsewhere only the sign matters.
  std::vector<float> values(static_cast<size_t>(nx) * ny * nz);
  auto block_range = [](int i, int nb) {
    const int hi = std::min(i / kBlock, nb - 1);
    const int lo = (i % kBlock == 0 && i > 0) ? i / kBlock - 1 : hi;
    return std::make_pair(std::min(lo, hi), hi);
  };
  tbb::parallel_for(tbb::blocked_range<int>(0, nz), [&](const tbb::blocked_range<int>& r) {
    for (int k = r.begin(); k < r.end(); ++k) {
      const auto [k0, k1] = block_range(k, bz);
      for (int j = 0; j < ny; ++j) {
        const auto [j0, j1] = block_range(j, by);
        for (int i = 0; i < nx; ++i) {
          const auto [i0, i1] = block_range(i, bx);
          bool exact = false;
          for (int kb = k0; kb <= k1 && !exact; ++kb) {
            for (int jb = j0; jb <= j1 && !exact; ++jb) {
              for (int ib = i0; ib <= i1 && !exact; ++ib) exact = near[block_index(ib, jb, kb)];
            }
          }
          values[index(i, j, k)] = exact ? sample(i, j, k) : block_sign[block_index(i1, j1, k1)];
        }
      }
    }
  });

  TriangleMesh mesh;
  std::unordered_map<int64_t, int> edge_vertex;
  auto corner_offset = [](int c) { return Eigen::Vector3i(c & 1, (c >> 1) & 1, (c >> 2) & 1); };
  static constexpr int kTets[6][4] = {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7},
                                      {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};
  auto vertex_on_edge = [&](const Eigen::Vector3i& base, int ca, int cb) {
    // Corners of a Kuhn edge: one corner's bits are a subset of the other's.
    if ((ca & cb) != ca) std::swap(ca, cb);
    const Eigen::Vector3i pa = base + corner_offset(ca);
    const Eigen::Vector3i pb = base + corner_offset(cb);
    const int64_t key = index(pa.x(), pa.y(), pa.z()) * 8 + (cb ^ ca);
    auto it = edge_vertex.find(key);
    if (it != edge_vertex.end()) return it->second;
    const double fa = values[index(pa.x(), pa.y(), pa.z())];
    const double fb = values[index(pb.x(), pb.y(), pb.z())];
    const double t = std::clamp(fa / (fa - fb), kEdgeClamp, 1.0 - kEdgeClamp);
    const Vec3 p = (1.0 - t) * point(pa.x(), pa.y(), pa.z()) + t * point(pb.x(), pb.y(), pb.z());
    const int id = static_cast<int>(mesh.vertices.size());
    mesh.vertices.push_back(p);
    edge_vertex.emplace(key, id);
    return id;
  };
  auto emit = [&](int a, int b, int c, const Vec3& outward) {
    const Vec3 n = (mesh.vertices[b] - mesh.vertices[a]).cross(mesh.vertices[c] - mesh.vertices[a]);
    if (n.dot(outward) < 0.0) std::swap(b, c);
    mesh.triangles.push_back({a, b, c});
  };
  for (int k = 0; k + 1 < nz; ++k) {
    for (int j = 0; j + 1 < ny; ++j) {
      for (int i = 0; i + 1 < nx; ++i) {
        float f[8];
        int inside = 0;
        for (int cidx = 0; cidx < 8; ++cidx) {
          const Eigen::Vector3i o = corner_offset(cidx);
          f[cidx] = values[index(i + o.x(), j + o.y(), k + o.z())];
          inside += f[cidx] < 0.0f;
        }
        if (inside == 0 || inside == 8) continue;
        const Eigen::Vector3i base(i, j, k);
        for (const auto& tet : kTets) {
          int in[4], out[4], n_in = 0, n_out = 0;
          for (int v : tet) {
            if (f[v] < 0.0f)
              in[n_in++] = v;
            else
              out[n_out++] = v;
          }
          if (n_in == 0 || n_out == 0) continue;
          Vec3 in_centre = Vec3::Zero(), out_centre = Vec3::Zero();
          for (int q = 0; q < n_in; ++q) in_centre += corner_offset(in[q]).cast<double>() / n_in;
          for (int q = 0; q < n_out; ++q)
            out_centre += corner_offset(out[q]).cast<double>() / n_out;
          const Vec3 outward = out_centre - in_centre;
          if (n_in == 1 || n_out == 1) {
            const int lone = n_in == 1 ? in[0] : out[0];
            const int* others = n_in == 1 ? out : in;
            emit(vertex_on_edge(base, lone, others[0]), vertex_on_edge(base, lone, others[1]),
                 vertex_on_edge(base, lone, others[2]), outward);
          } else {
            const int a = vertex_on_edge(base, in[0], out[0]);
            const int b = vertex_on_edge(base, in[0], out[1]);
            const int c2 = vertex_on_edge(base, in[1], out[1]);
            const int d = vertex_on_edge(base, in[1], out[0]);
            emit(a, b, c2, outward);
            emit(a, c2, d, outward);
          }
        }
      }
    }
  }
  return mesh;
}

int KeepLargestComponent(TriangleMesh* mesh) {
  const int nv = static_cast<int>(mesh->vertices.size());
  std::vector<int> parent(nv);
  std::iota(parent.begin(), parent.end(), 0);
  std::function<int(int)> find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (const auto& t : mesh->triangles) {
    parent[find(t[0])] = find(t[1]);
    parent[find(t[1])] = find(t[2]);
  }
  std::map<int, int> count;
  for (const auto& t : mesh->triangles) ++count[find(t[0])];
  int best = -1, best_count = -1;
  for (const auto& [root, n] : count) {
    if (n > best_count) {
      best = root;
      best_count = n;
    }
  }
  std::vector<int> remap(nv, -1);
  TriangleMesh kept;
  for (const auto& t : mesh->triangles) {
    if (find(t[0]) != best) continue;
    std::array<int, 3> nt;
    for (int q = 0; q < 3; ++q) {
      if (remap[t[q]] < 0) {
        remap[t[q]] = static_cast<int>(kept.vertices.size());
        kept.vertices.push_back(mesh->vertices[t[q]]);
      }
      nt[q] = remap[t[q]];
    }
    kept.triangles.push_back(nt);
  }
  *mesh = std::move(kept);
  return static_cast<int>(count.size()) - 1;
}

// ----------------------------------------------------------------------------------------------
// Isotropic remeshing (Botsch & Kobbelt 2004) with projection onto the implicit surface.

namespace {

struct OmTraits : public OpenMesh::DefaultTraits {
  using Point = OpenMesh::Vec3d;
  using Normal = OpenMesh::Vec3d;
  VertexAttributes(OpenMesh::Attributes::Status | OpenMesh::Attributes::Normal);
  EdgeAttributes(OpenMesh::Attributes::Status);
  FaceAttributes(OpenMesh::Attributes::Status | OpenMesh::Attributes::Normal);
  HalfedgeAttributes(OpenMesh::Attributes::PrevHalfedge);
};
using OmMesh = OpenMesh::TriMesh_ArrayKernelT<OmTraits>;

Vec3 ToEigen(const OpenMesh::Vec3d& p) { return Vec3(p[0], p[1], p[2]); }
OpenMesh::Vec3d ToOm(const Vec3& p) { return OpenMesh::Vec3d(p.x(), p.y(), p.z()); }

Vec3 ProjectToSurface(const Body& body, Vec3 p, int iterations, double eps, double max_step) {
  for (int it = 0; it < iterations; ++it) {
    const double f = body.Field(p);
    if (std::abs(f) < 1e-9) break;
    const Vec3 g = body.Gradient(p, f, eps);
    const double g2 = g.squaredNorm();
    if (g2 < 1e-12) break;
    Vec3 step = -f * g / g2;
    if (step.norm() > max_step) step *= max_step / step.norm();
    p += step;
  }
  return p;
}

class Remesher {
 public:
  Remesher(const Body& body, const TriangleMesh& input, double edge_length,
           const MeshingOptions& options)
      : body_(body), target_(edge_length), options_(options) {
    std::vector<OmMesh::VertexHandle> handles;
    handles.reserve(input.vertices.size());
    for (const Vec3& p : input.vertices) handles.push_back(mesh_.add_vertex(ToOm(p)));
    for (const auto& t : input.triangles) {
      const auto fh = mesh_.add_face(handles[t[0]], handles[t[1]], handles[t[2]]);
      if (!fh.is_valid()) throw Error("template generator: iso-surface is not a manifold");
    }
  }

  void Run() {
    const double high = kSplitFactor * target_;
    const double low = kCollapseFactor * target_;
    for (int it = 0; it < options_.remesh_iterations; ++it) {
      SplitLongEdges(high);
      CollapseShortEdges(low, high);
      EqualizeValences();
      TangentialRelaxation();
      Project();
    }
  }

  TriangleMesh Result() {
    mesh_.garbage_collection();
    TriangleMesh out;
    for (auto vh : mesh_.vertices()) out.vertices.push_back(ToEigen(mesh_.point(vh)));
    for (auto fh : mesh_.faces()) {
      std::array<int, 3> t;
      int q = 0;
      for (auto vh : mesh_.fv_range(fh)) t[q++] = vh.idx();
      out.triangles.push_back(t);
    }
    return out;
  }

 private:
  Vec3 P(OmMesh::VertexHandle v) const { return ToEigen(mesh_.point(v)); }

  void SplitLongEdges(double high) {
    for (size_t i = 0; i < mesh_.n_edges(); ++i) {
      const auto eh = mesh_.edge_handle(static_cast<int>(i));
      if (mesh_.status(eh).deleted()) continue;
      const auto hh = mesh_.halfedge_handle(eh, 0);
      const Vec3 a = P(mesh_.from_vertex_handle(hh));
      const Vec3 b = P(mesh_.to_vertex_handle(hh));
      if ((a - b).norm() <= high) continue;
      const auto vh = mesh_.add_vertex(ToOm(0.5 * (a + b)));
      mesh_.split(eh, vh);
    }
  }

  // True when moving vertex `v` to `p` (ignoring faces that contain `skip`) keeps every
  // incident face's orientation.
  bool KeepsOrientation(OmMesh::VertexHandle v, const Vec3& p, OmMesh::VertexHandle skip) const {
    for (auto fh : mesh_.vf_range(v)) {
      std::array<Vec3, 3> old_pts, new_pts;
      bool has_skip = false;
      int q = 0;
      for (auto w : mesh_.fv_range(fh)) {
        if (w == skip) has_skip = true;
        old_pts[q] = P(w);
        new_pts[q] = w == v ? p : P(w);
        ++q;
      }
      if (has_skip) continue;
      const Vec3 n0 = FaceNormal(old_pts[0], old_pts[1], old_pts[2]);
      const Vec3 n1 = FaceNormal(new_pts[0], new_pts[1], new_pts[2]);
      if (n1.norm() < 1e-14 || n0.dot(n1) <= kCollapseNormalCosine * n0.norm() * n1.norm()) {
        return false;
      }
    }
    return true;
  }

  void CollapseShortEdges(double low, double high) {
    const size_t n = mesh_.n_edges();
    for (size_t i = 0; i < n; ++i) {
      const auto eh = mesh_.edge_handle(static_cast<int>(i));
      if (mesh_.status(eh).deleted()) continue;
      auto hh = mesh_.halfedge_handle(eh, 0);
      auto v0 = mesh_.from_vertex_handle(hh);
      auto v1 = mesh_.to_vertex_handle(hh);
      const Vec3 mid = 0.5 * (P(v0) + P(v1));
      if ((P(v0) - P(v1)).norm() >= low) continue;
      if (!mesh_.is_collapse_ok(hh)) {
        hh = mesh_.opposite_halfedge_handle(hh);
        std::swap(v0, v1);
        if (!mesh_.is_collapse_ok(hh)) continue;
      }
      bool ok = true;
      for (auto w : mesh_.vv_range(v0)) {
        if ((P(w) - mid).norm() > high) ok = false;
      }
      for (auto w : mesh_.vv_range(v1)) {
        if ((P(w) - mid).norm() > high) ok = false;
      }
      if (!ok || !KeepsOrientation(v0, mid, v1) || !KeepsOrientation(v1, mid, v0)) continue;
      mesh_.set_point(v1, ToOm(mid));
      mesh_.collapse(hh);
    }
    mesh_.garbage_collection();
  }

  void EqualizeValences() {
    for (auto eh : mesh_.edges()) {
      if (!mesh_.is_flip_ok(eh)) continue;
      const auto h0 = mesh_.halfedge_handle(eh, 0);
      const auto h1 = mesh_.halfedge_handle(eh, 1);
      const auto a = mesh_.to_vertex_handle(h0);
      const auto b = mesh_.to_vertex_handle(h1);
      const auto c = mesh_.to_vertex_handle(mesh_.next_halfedge_handle(h0));
      const auto d = mesh_.to_vertex_handle(mesh_.next_halfedge_handle(h1));
      auto dev = [](int valence) { return (valence - 6) * (valence - 6); };
      const int va = static_cast<int>(mesh_.valence(a)), vb = static_cast<int>(mesh_.valence(b));
      const int vc = static_cast<int>(mesh_.valence(c)), vd = static_cast<int>(mesh_.valence(d));
      if (va <= 3 || vb <= 3) continue;
      const int before = dev(va) + dev(vb) + dev(vc) + dev(vd);
      const int after = dev(va - 1) + dev(vb - 1) + dev(vc + 1) + dev(vd + 1);
      if (after >= before) continue;
      // Faces (a, c, b) and (b, d, a) become (c, d, b)... check both new faces against the
      // old normals so that no fold is introduced.
      const Vec3 n_old =
          FaceNormal(P(b), P(a), P(c)).normalized() + FaceNormal(P(a), P(b), P(d)).normalized();
      const Vec3 n1 = FaceNormal(P(c), P(d), P(a));
      const Vec3 n2 = FaceNormal(P(d), P(c), P(b));
      if (n1.dot(n_old) <= 0.0 || n2.dot(n_old) <= 0.0) continue;
      const Vec3 f1 = FaceNormal(P(b), P(a), P(c)), f2 = FaceNormal(P(a), P(b), P(d));
      if (f1.normalized().dot(f2.normalized()) < kFlipCreaseCosine) continue;
      mesh_.flip(eh);
    }
  }

  void TangentialRelaxation() {
    mesh_.update_face_normals();
    mesh_.update_vertex_normals();
    std::vector<OpenMesh::Vec3d> updated(mesh_.n_vertices());
    for (auto vh : mesh_.vertices()) {
      Vec3 q = Vec3::Zero();
      int n = 0;
      for (auto w : mesh_.vv_range(vh)) {
        q += P(w);
        ++n;
      }
      const Vec3 p = P(vh);
      if (n == 0) {
        updated[vh.idx()] = ToOm(p);
        continue;
      }
      q /= n;
      const Vec3 normal = ToEigen(mesh_.normal(vh));
      const Vec3 moved = q + normal * normal.dot(p - q);
      updated[vh.idx()] = ToOm(moved);
    }
    for (auto vh : mesh_.vertices()) mesh_.set_point(vh, updated[vh.idx()]);
  }

  void Project() {
    const double eps = kGradientStep * body_.height;
    std::vector<OmMesh::VertexHandle> handles(mesh_.vertices().begin(), mesh_.vertices().end());
    tbb::parallel_for(
        tbb::blocked_range<size_t>(0, handles.size()), [&](const tbb::blocked_range<size_t>& r) {
          for (size_t i = r.begin(); i < r.end(); ++i) {
            const Vec3 p = ProjectToSurface(body_, P(handles[i]), options_.projection_iterations,
                                            eps, kMaxProjectionStep * target_);
            mesh_.point(handles[i]) = ToOm(p);
          }
        });
  }

  const Body& body_;
  OmMesh mesh_;
  double target_;
  const MeshingOptions& options_;
};

}  // namespace

TriangleMesh Remesh(const Body& body, const TriangleMesh& input, double edge_length,
                    const MeshingOptions& options) {
  Remesher remesher(body, input, edge_length, options);
  remesher.Run();
  return remesher.Result();
}

}  // namespace generator_internal
}  // namespace artex
