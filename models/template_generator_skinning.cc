// Template generator's segmentation, skinning constants, UV charts and seam costs.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <map>
#include <numeric>
#include <queue>
#include <sstream>
#include <unordered_map>
#include <utility>
#include <vector>

#include "models/error.h"
#include "models/numeric.h"
#include "models/template_generator_internal.h"

namespace artex {
namespace generator_internal {
namespace {

// Lengths of SkinningBands are given for this stature and scaled with the height.
constexpr double kReferenceStature = 1.75;

enum class Chart : int {
  kHeadFront = 0,
  kHeadBack,
  kTorsoFront,
  kTorsoBack,
  kLUpperArm,
  kLForearm,
  kLPalm,
  kLHandBack,
  kRUpperArm,
  kRForearm,
  kRPalm,
  kRHandBack,
  kLThigh,
  kLShank,
  kLFootMedial,
  kLFootLateral,
  kRThigh,
  kRShank,
  kRFootMedial,
  kRFootLateral
};

int Depth(int joint) {
  int d = 0;
  for (int j = joint; kParents[j] >= 0; j = kParents[j]) ++d;
  return d;
}

bool InSubtree(int joint, int root) {
  for (int j = joint; j >= 0; j = kParents[j]) {
    if (j == root) return true;
  }
  return false;
}

// Multi-source Dijkstra restricted to edges inside one segment (same label).
std::vector<double> SegmentDistance(const Eigen::MatrixX3d& verts,
                                    const std::vector<std::vector<int>>& adj,
                                    const std::vector<int>& label,
                                    const std::vector<char>& is_source) {
  const int n = static_cast<int>(adj.size());
  std::vector<double> dist(n, kInf);
  using Item = std::pair<double, int>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
  for (int v = 0; v < n; ++v) {
    if (is_source[v]) {
      dist[v] = 0.0;
      queue.emplace(0.0, v);
    }
  }
  while (!queue.empty()) {
    const auto [d, v] = queue.top();
    queue.pop();
    if (d > dist[v]) continue;
    for (int w : adj[v]) {
      if (label[w] != label[v]) continue;
      const double nd = d + (verts.row(v) - verts.row(w)).norm();
      if (nd < dist[w]) {
        dist[w] = nd;
        queue.emplace(nd, w);
      }
    }
  }
  return dist;
}

double SmoothStep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

double BandHalfWidth(const SkinningBands& b, int joint) {
  switch (joint) {
    case kSpine:
      return b.spine;
    case kChest:
      return b.chest;
    case kNeck:
      return b.neck;
    case kHead:
      return b.head;
    case kLShoulder:
    case kRShoulder:
      return b.shoulder;
    case kLElbow:
    case kRElbow:
      return b.elbow;
    case kLWrist:
    case kRWrist:
      return b.wrist;
    case kLHip:
    case kRHip:
      return b.hip;
    case kLKnee:
    case kRKnee:
      return b.knee;
    case kLAnkle:
    case kRAnkle:
      return b.ankle;
    default:
      return 0.0;
  }
}

}  // namespace

// ----------------------------------------------------------------------------------------------
// Mesh adjacency helpers.

std::vector<std::vector<int>> VertexNeighbours(int nv, const Eigen::MatrixX3i& tris) {
  std::vector<std::vector<int>> adj(nv);
  for (int f = 0; f < tris.rows(); ++f) {
    for (int q = 0; q < 3; ++q) {
      adj[tris(f, q)].push_back(tris(f, (q + 1) % 3));
      adj[tris(f, q)].push_back(tris(f, (q + 2) % 3));
    }
  }
  for (auto& a : adj) {
    std::sort(a.begin(), a.end());
    a.erase(std::unique(a.begin(), a.end()), a.end());
  }
  return adj;
}

int MergeIslands(const std::vector<std::vector<int>>& adjacent, std::vector<int>* labels) {
  const int n = static_cast<int>(labels->size());
  std::vector<int> component(n, -1);
  std::vector<int> component_size;
  std::vector<int> component_label;
  for (int s = 0; s < n; ++s) {
    if (component[s] >= 0) continue;
    const int id = static_cast<int>(component_size.size());
    component_size.push_back(0);
    component_label.push_back((*labels)[s]);
    std::vector<int> stack = {s};
    component[s] = id;
    while (!stack.empty()) {
      const int x = stack.back();
      stack.pop_back();
      ++component_size[id];
      for (int y : adjacent[x]) {
        if (component[y] < 0 && (*labels)[y] == (*labels)[x]) {
          component[y] = id;
          stack.push_back(y);
        }
      }
    }
  }
  std::map<int, int> largest;  // label -> component id
  for (int id = 0; id < static_cast<int>(component_size.size()); ++id) {
    auto it = largest.find(component_label[id]);
    if (it == largest.end() || component_size[id] > component_size[it->second])
      largest[component_label[id]] = id;
  }
  int changed = 0;
  // Relabel island by island, smallest first, to the majority outside label.
  std::vector<int> order(component_size.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return component_size[a] < component_size[b]; });
  std::vector<std::vector<int>> members(component_size.size());
  for (int x = 0; x < n; ++x) members[component[x]].push_back(x);
  for (int id : order) {
    if (largest[component_label[id]] == id) continue;
    std::map<int, int> votes;
    for (int x : members[id]) {
      for (int y : adjacent[x]) {
        if (component[y] != id) ++votes[(*labels)[y]];
      }
    }
    if (votes.empty()) continue;
    int best = -1, best_votes = -1;
    for (const auto& [label, v] : votes) {
      if (v > best_votes) {
        best = label;
        best_votes = v;
      }
    }
    for (int x : members[id]) {
      (*labels)[x] = best;
      component[x] = largest.count(best) ? largest[best] : id;
    }
    changed += static_cast<int>(members[id].size());
  }
  return changed;
}

int FixSegmentAdjacency(const std::vector<std::vector<int>>& adj, std::vector<int>* joint) {
  int changed = 0;
  for (int round = 0; round < 64; ++round) {
    std::vector<int> move;
    for (int v = 0; v < static_cast<int>(adj.size()); ++v) {
      const int a = (*joint)[v];
      for (int w : adj[v]) {
        const int b = (*joint)[w];
        if (a == b || kParents[a] == b || kParents[b] == a || kParents[a] == kParents[b]) continue;
        const bool a_deeper = Depth(a) > Depth(b) || (Depth(a) == Depth(b) && a > b);
        if (a_deeper) {
          move.push_back(v);
          break;
        }
      }
    }
    if (move.empty()) return changed;
    for (int v : move) (*joint)[v] = kParents[(*joint)[v]];
    changed += static_cast<int>(move.size());
  }
  throw Error("template generator: body segmentation did not converge");
}

std::vector<int> SegmentBody(const Body& body, const SkinningBands& bands,
                             const Eigen::MatrixX3d& verts) {
  const double scale = body.height / kReferenceStature;
  const int nv = static_cast<int>(verts.rows());
  std::vector<int> joint(nv, kPelvis);
  auto past = [&](const Vec3& p, int j) {
    return (p - body.centre[j]).dot(body.incoming[j]) >= -BandHalfWidth(bands, j) * scale;
  };
  const double neck_radius = bands.neck_radius * scale;
  // Trunk side: hips below their planes (split at x = 0), the neck within neck_radius of its
  // axis above its plane, then chest / spine / pelvis by horizontal planes.
  auto trunk_joint = [&](const Vec3& p) {
    if (p.x() >= 0.0 && past(p, kLHip)) return static_cast<int>(kLHip);
    if (p.x() < 0.0 && past(p, kRHip)) return static_cast<int>(kRHip);
    const Vec3 r = p - body.centre[kNeck];
    const double radial = (r - r.dot(body.axis[kNeck]) * body.axis[kNeck]).norm();
    if (past(p, kNeck) && radial < neck_radius) {
      return static_cast<int>(past(p, kHead) ? kHead : kNeck);
    }
    return static_cast<int>(past(p, kChest) ? kChest : (past(p, kSpine) ? kSpine : kPelvis));
  };
  tbb::parallel_for(tbb::blocked_range<int>(0, nv), [&](const tbb::blocked_range<int>& r) {
    for (int v = r.begin(); v < r.end(); ++v) {
      const Vec3 p = verts.row(v).transpose();
      int root = -1;
      // clang-format off
      switch (body.DominantGroup(p)) {
        case Group::kTrunk:
          joint[v] = trunk_joint(p);
          continue;
        case Group::kNeckHead:
          joint[v] = past(p, kHead) ? kHead : (past(p, kNeck) ? kNeck : trunk_joint(p));
          continue;
        case Group::kLeftArm: root = kLShoulder; break;
        case Group::kRightArm: root = kRShoulder; break;
        case Group::kLeftLeg: root = kLHip; break;
        case Group::kRightLeg: root = kRHip; break;
      }
      // clang-format on
      // Limb vertices on the trunk side of the limb root's plane belong to the trunk.
      joint[v] = past(p, root + 2)   ? root + 2
                 : past(p, root + 1) ? root + 1
                 : past(p, root)     ? root
                                     : trunk_joint(p);
    }
  });
  return joint;
}

void ComputeSkinningConstants(const Body& body, const SkinningBands& bands,
                              const Eigen::MatrixX3d& verts,
                              const std::vector<std::vector<int>>& adj,
                              const std::vector<int>& joint, Eigen::VectorXd* w_l,
                              Eigen::VectorXd* tau) {
  const int nv = static_cast<int>(verts.rows());
  const double scale = body.height / kReferenceStature;
  std::vector<char> proximal(nv, 0), distal(nv, 0);
  for (int v = 0; v < nv; ++v) {
    const int k = joint[v];
    for (int w : adj[v]) {
      const int b = joint[w];
      if (b == k) continue;
      if (InSubtree(b, k))
        distal[v] = 1;
      else
        proximal[v] = 1;
    }
  }
  const std::vector<double> g_p = SegmentDistance(verts, adj, joint, proximal);
  const std::vector<double> g_d = SegmentDistance(verts, adj, joint, distal);
  int num_children[kDefaultNumJoints] = {};
  for (int j = 1; j < kDefaultNumJoints; ++j) ++num_children[kParents[j]];
  w_l->resize(nv);
  tau->resize(nv);
  for (int v = 0; v < nv; ++v) {
    const int k = joint[v];
    if (k == kPelvis) {
      (*w_l)[v] = 1.0;
      (*tau)[v] = 1.0;
      continue;
    }
    if (!std::isfinite(g_p[v])) {
      std::ostringstream msg;
      msg << "template generator: segment " << kJointNames[k] << " does not touch its parent";
      throw Error(msg.str());
    }
    const double ramp = 2.0 * BandHalfWidth(bands, k) * scale;
    if (proximal[v]) {
      (*w_l)[v] = 0.0;
      (*tau)[v] = 0.0;
      continue;
    }
    if (std::isfinite(g_d[v])) {
      // Must reach w_l = tau = 1 at the children's border.
      const double span = g_p[v] + g_d[v];
      const double w = SmoothStep(g_p[v] / std::min(ramp, span));
      (*w_l)[v] = w;
      (*tau)[v] = num_children[k] == 1 ? std::clamp(g_p[v] / span, 0.0, 1.0) : w;
    } else {
      const double w = SmoothStep(g_p[v] / ramp);
      (*w_l)[v] = w;
      (*tau)[v] = w;
    }
  }
}

// ----------------------------------------------------------------------------------------------
// Charts.

Eigen::VectorXi AssignCharts(const Body& body, const Eigen::MatrixX3d& verts,
                             const Eigen::MatrixX3i& tris, const std::vector<int>& joint) {
  const int nf = static_cast<int>(tris.rows());
  std::vector<int> chart(nf);
  for (int f = 0; f < nf; ++f) {
    const int a = joint[tris(f, 0)], b = joint[tris(f, 1)], c = joint[tris(f, 2)];
    int k = (a == b || a == c) ? a : (b == c ? b : std::max({a, b, c}, [](int x, int y) {
      return Depth(x) < Depth(y) || (Depth(x) == Depth(y) && x < y);
    }));
    const Vec3 centroid =
        (verts.row(tris(f, 0)) + verts.row(tris(f, 1)) + verts.row(tris(f, 2))).transpose() / 3.0;
    Chart ch = Chart::kTorsoFront;
    // clang-format off
    switch (k) {
      case kPelvis: case kSpine: case kChest:
        ch = centroid.z() >= body.torso_mid_z ? Chart::kTorsoFront : Chart::kTorsoBack;
        break;
      case kNeck: case kHead:
        ch = centroid.z() >= body.head_mid_z ? Chart::kHeadFront : Chart::kHeadBack;
        break;
      case kLShoulder: ch = Chart::kLUpperArm; break;
      case kRShoulder: ch = Chart::kRUpperArm; break;
      case kLElbow: ch = Chart::kLForearm; break;
      case kRElbow: ch = Chart::kRForearm; break;
      case kLWrist: case kRWrist: {
        const int side = k == kLWrist ? 0 : 1;
        const bool palm = (centroid - body.centre[k]).dot(body.palm_normal[side]) >= 0.0;
        ch = side == 0 ? (palm ? Chart::kLPalm : Chart::kLHandBack)
                       : (palm ? Chart::kRPalm : Chart::kRHandBack);
        break;
      }
      case kLHip: ch = Chart::kLThigh; break;
      case kRHip: ch = Chart::kRThigh; break;
      case kLKnee: ch = Chart::kLShank; break;
      case kRKnee: ch = Chart::kRShank; break;
      case kLAnkle: case kRAnkle: {
        const double sx = k == kLAnkle ? 1.0 : -1.0;
        const bool lateral = sx * (centroid.x() - body.centre[k].x()) >= 0.0;
        if (k == kLAnkle) ch = lateral ? Chart::kLFootLateral : Chart::kLFootMedial;
        else ch = lateral ? Chart::kRFootLateral : Chart::kRFootMedial;
        break;
      }
      default: break;
    }
    // clang-format on
    chart[f] = static_cast<int>(ch);
  }
  // Triangle adjacency over shared edges, then island merging so that charts are connected.
  std::unordered_map<int64_t, int> edge_face;
  std::vector<std::vector<int>> adj(nf);
  const int64_t nv = verts.rows();
  for (int f = 0; f < nf; ++f) {
    for (int q = 0; q < 3; ++q) {
      int64_t a = tris(f, q), b = tris(f, (q + 1) % 3);
      if (a > b) std::swap(a, b);
      const int64_t key = a * nv + b;
      auto it = edge_face.find(key);
      if (it == edge_face.end()) {
        edge_face.emplace(key, f);
      } else {
        adj[f].push_back(it->second);
        adj[it->second].push_back(f);
      }
    }
  }
  for (int round = 0; round < 16 && MergeIslands(adj, &chart) > 0; ++round) {
  }
  return Eigen::Map<Eigen::VectorXi>(chart.data(), nf);
}

Eigen::VectorXd SeamCost(const Body& body, const Eigen::MatrixX3d& verts,
                         const std::vector<int>& joint) {
  const int nv = static_cast<int>(verts.rows());
  Eigen::VectorXd cost = Eigen::VectorXd::Zero(nv);
  for (int v = 0; v < nv; ++v) {
    const int k = joint[v];
    Vec3 seam;
    // clang-format off
    switch (k) {
      case kLShoulder: case kLElbow: seam = body.arm_seam[0]; break;
      case kRShoulder: case kRElbow: seam = body.arm_seam[1]; break;
      case kLHip: case kLKnee: seam = body.leg_seam[0]; break;
      case kRHip: case kRKnee: seam = body.leg_seam[1]; break;
      default: continue;
    }
    // clang-format on
    const Vec3 a = body.axis[k];
    Vec3 radial = verts.row(v).transpose() - body.centre[k];
    radial -= radial.dot(a) * a;
    if (radial.norm() < 1e-12) continue;
    cost[v] = 0.5 * (1.0 - radial.normalized().dot(seam));
  }
  return cost;
}

}  // namespace generator_internal
}  // namespace artex
