// The subject's foreground without background frames (sensors/scene_segmentation.h): floors
// and walls and the depth range removed, 3-D connected components on the depth image grid
// (tight and loose passes, stacked parts joined, touching people split between their heads),
// the subject chosen and tracked from frame to frame. Planes and the world frame:
// scene_planes.cc.
#include <algorithm>
#include <cmath>
#include <sstream>
#include <unordered_map>

#include "models/error.h"
#include "sensors/scene_segmentation.h"
#include "sensors/scene_segmentation_internal.h"

namespace artex {

const std::map<std::string, SubjectChoice>& SubjectChoiceNames() {
  static const std::map<std::string, SubjectChoice> names = {{"central", SubjectChoice::kCentral},
                                                             {"nearest", SubjectChoice::kNearest},
                                                             {"largest", SubjectChoice::kLargest},
                                                             {"pixel", SubjectChoice::kPixel}};
  return names;
}

bool SubjectSegmentationOptions::IsValid(std::string* error) const {
  if (!planes.IsValid(error)) return false;
  std::ostringstream msg;
  if (!(min_depth >= 0) || !(max_depth > min_depth)) {
    msg << "min_depth/max_depth: expected 0 <= min_depth < max_depth, found " << min_depth << " / "
        << max_depth;
  } else if (!(plane_margin >= 0) || !(plane_margin_growth >= 0)) {
    msg << "plane_margin/plane_margin_growth: expected >= 0, found " << plane_margin << " / "
        << plane_margin_growth;
  } else if (!(connect_distance > 0) || !(connect_growth >= 0) || !(merge_relative >= 0) ||
             !(fragment_height >= 0) || !(stacked_max_overlap >= 0 && stacked_max_overlap <= 1) ||
             !(stacked_max_gap >= 0)) {
    msg << "connect_distance/connect_growth/merge_relative/fragment_height/stacked_max_overlap/"
           "stacked_max_gap: expected > 0 / >= 0 / >= 0 / >= 0 / in [0, 1] / >= 0";
  } else if (min_pixels < 1) {
    msg << "min_pixels: expected >= 1, found " << min_pixels;
  } else if (!(min_height >= 0) || !(max_height > min_height) || !(max_width > 0)) {
    msg << "min_height/max_height/max_width: expected 0 <= min_height < max_height, "
           "max_width > 0";
  } else if (choice == SubjectChoice::kPixel && (pixel.x() < 0 || pixel.y() < 0)) {
    msg << "pixel: expected a pixel (column, row) >= 0 with choice pixel, found " << pixel.x()
        << "," << pixel.y();
  } else if (!(track_max_distance > 0)) {
    msg << "track_max_distance: expected > 0 (m), found " << track_max_distance;
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

SubjectSegmenter::SubjectSegmenter(const PinholeCamera& intrinsics, const Distortion& distortion,
                                   double depth_scale, const Eigen::Vector3d& up_camera,
                                   const SubjectSegmentationOptions& options)
    : SubjectSegmenter(DepthBackProjector(intrinsics, distortion), depth_scale, up_camera,
                       options) {}

SubjectSegmenter::SubjectSegmenter(const DepthBackProjector& projector, double depth_scale,
                                   const Eigen::Vector3d& up_camera,
                                   const SubjectSegmentationOptions& options)
    : projector_(projector),
      depth_scale_(depth_scale),
      up_(up_camera.normalized()),
      options_(options) {
  std::string error;
  if (!options.IsValid(&error)) throw Error("subject segmentation options: " + error);
  if (!(depth_scale > 0)) throw Error("subject segmentation: expected a positive depth_scale");
  if (!up_.allFinite()) throw Error("subject segmentation: expected a finite up direction");
}

void SubjectSegmenter::SetPlanes(const std::vector<ScenePlane>& planes) {
  planes_ = planes;
  planes_known_ = true;
}

namespace {

int Find(std::vector<int>& parent, int i) {
  while (parent[i] != i) {
    parent[i] = parent[parent[i]];
    i = parent[i];
  }
  return i;
}

void Union(std::vector<int>& parent, int a, int b) {
  a = Find(parent, a);
  b = Find(parent, b);
  if (a == b) return;
  if (a < b) std::swap(a, b);
  parent[a] = b;
}

struct Component {
  int root = -1;
  int pixels = 0;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double u_sum = 0, v_sum = 0;
  double up_min = 1e300, up_max = -1e300;
  double z_min = 1e300;
  bool contains_pixel = false;
  Eigen::Vector3d centroid() const { return sum / std::max(1, pixels); }
};

}  // namespace

void SubjectSegmenter::Segment(const cv::Mat& depth, cv::Mat* mask, SegmentationStats* stats) {
  scene_internal::CheckDepth(depth, projector_.camera(), "subject segmentation");
  if (!planes_known_) {
    SetPlanes(DetectScenePlanes(depth, projector_, depth_scale_, up_, options_.planes));
  }
  std::vector<const ScenePlane*> removed;
  for (const ScenePlane& p : planes_)
    if (p.kind != PlaneKind::kOther) removed.push_back(&p);

  const int w = depth.cols, h = depth.rows, n = w * h;
  parent_.resize(n);
  z_.assign(n, 0.0f);
  const double inv_scale = 1.0 / depth_scale_;
  SegmentationStats local;
  // Candidates: valid, in range, in front of every floor/wall by more than the margin.
  for (int v = 0; v < h; ++v) {
    const uint16_t* row = depth.ptr<uint16_t>(v);
    const float* ray = RayRow(v);
    for (int u = 0; u < w; ++u) {
      const int i = v * w + u;
      parent_[i] = i;
      if (row[u] == 0) continue;
      const double z = row[u] * inv_scale;
      if (z < options_.min_depth || z > options_.max_depth) continue;
      const Eigen::Vector3d x(ray[2 * u] * z, ray[2 * u + 1] * z, z);
      bool keep = true;
      const double margin = options_.plane_margin + options_.plane_margin_growth * z * z;
      for (const ScenePlane* p : removed) {
        if (p->SignedDistance(x) < margin) {
          keep = false;
          break;
        }
      }
      if (!keep) continue;
      z_[i] = static_cast<float>(z);
      ++local.candidate_pixels;
    }
  }
  // Components: a tight 4-connected pass, then fragments merged across the loose limit.
  const float growth = static_cast<float>(options_.connect_growth);
  const float base = static_cast<float>(options_.connect_distance);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const int i = v * w + u;
      const float z = z_[i];
      if (z == 0.0f) continue;
      const float limit = base + growth * z * z;
      if (u + 1 < w && z_[i + 1] != 0.0f && std::abs(z_[i + 1] - z) < limit)
        Union(parent_, i, i + 1);
      if (v + 1 < h && z_[i + w] != 0.0f && std::abs(z_[i + w] - z) < limit)
        Union(parent_, i, i + w);
    }
  }
  if (options_.fragment_height > 0 && options_.merge_relative > 0) {
    low_.assign(n, 1e30f);
    high_.assign(n, -1e30f);
    const Eigen::Vector3f up = up_.cast<float>();
    for (int v = 0; v < h; ++v) {
      const float* ray = RayRow(v);
      for (int u = 0; u < w; ++u) {
        const int i = v * w + u;
        if (z_[i] == 0.0f) continue;
        const int r = Find(parent_, i);
        const float height = z_[i] * (up.x() * ray[2 * u] + up.y() * ray[2 * u + 1] + up.z());
        low_[r] = std::min(low_[r], height);
        high_[r] = std::max(high_[r], height);
      }
    }
    const float rel = static_cast<float>(options_.merge_relative);
    const float tall = static_cast<float>(options_.fragment_height);
    auto merge = [&](int a, int b) {
      int ra = Find(parent_, a), rb = Find(parent_, b);
      if (ra == rb) return;
      if (high_[ra] - low_[ra] >= tall && high_[rb] - low_[rb] >= tall) return;
      if (ra < rb) std::swap(ra, rb);
      parent_[ra] = rb;
      low_[rb] = std::min(low_[rb], low_[ra]);
      high_[rb] = std::max(high_[rb], high_[ra]);
    };
    for (int v = 0; v < h; ++v) {
      for (int u = 0; u < w; ++u) {
        const int i = v * w + u;
        const float z = z_[i];
        if (z == 0.0f) continue;
        const float limit = std::max(base, rel * z);
        // 8-neighbours, and across one missing pixel (the sensor drops pixels along depth
        // edges, and a diagonal chain of them can cut a body in two).
        const auto link = [&](int j) {
          if (z_[j] != 0.0f && std::abs(z_[j] - z) < limit) merge(i, j);
        };
        if (u + 1 < w) {
          link(i + 1);
          if (z_[i + 1] == 0.0f && u + 2 < w) link(i + 2);
        }
        if (v + 1 < h) {
          link(i + w);
          if (u + 1 < w) link(i + w + 1);
          if (u > 0) link(i + w - 1);
          if (z_[i + w] == 0.0f && v + 2 < h) link(i + 2 * w);
        }
      }
    }
  }
  if (options_.fragment_height > 0 && options_.stacked_max_overlap > 0) JoinStackedParts(w, h);
  // Flatten: parent_[i] is the root of every candidate pixel.
  for (int i = 0; i < n; ++i)
    if (z_[i] != 0.0f) parent_[i] = Find(parent_, i);
  if (options_.split_people) SplitPeople(w, h, &local.people_splits);
  // Component statistics.
  std::vector<int> slot(n, -1);
  std::vector<Component> components;
  const bool pick_pixel = options_.choice == SubjectChoice::kPixel;
  for (int v = 0; v < h; ++v) {
    const float* ray = RayRow(v);
    for (int u = 0; u < w; ++u) {
      const int i = v * w + u;
      if (z_[i] == 0.0f) continue;
      const int r = parent_[i];
      if (slot[r] < 0) {
        slot[r] = static_cast<int>(components.size());
        components.emplace_back();
        components.back().root = r;
      }
      Component& c = components[slot[r]];
      const double z = z_[i];
      const Eigen::Vector3d x(ray[2 * u] * z, ray[2 * u + 1] * z, z);
      ++c.pixels;
      c.sum += x;
      c.u_sum += u;
      c.v_sum += v;
      const double height = up_.dot(x);
      c.up_min = std::min(c.up_min, height);
      c.up_max = std::max(c.up_max, height);
      c.z_min = std::min(c.z_min, z);
      if (pick_pixel && u == options_.pixel.x() && v == options_.pixel.y()) c.contains_pixel = true;
    }
  }
  // Person-sized components; the horizontal extent needs a second pass (about the centroid).
  std::vector<int> sized;
  for (int k = 0; k < static_cast<int>(components.size()); ++k) {
    const Component& c = components[k];
    if (c.pixels < options_.min_pixels) continue;
    ++local.components;
    const double height = c.up_max - c.up_min;
    if (height >= options_.min_height && height <= options_.max_height) sized.push_back(k);
  }
  std::vector<double> radius(components.size(), 0.0);
  if (!sized.empty()) {
    std::vector<uint8_t> in_sized(components.size(), 0);
    for (int k : sized) in_sized[k] = 1;
    for (int v = 0; v < h; ++v) {
      const float* ray = RayRow(v);
      for (int u = 0; u < w; ++u) {
        const int i = v * w + u;
        if (z_[i] == 0.0f) continue;
        const int k = slot[parent_[i]];
        if (!in_sized[k]) continue;
        const double z = z_[i];
        Eigen::Vector3d d =
            Eigen::Vector3d(ray[2 * u] * z, ray[2 * u + 1] * z, z) - components[k].centroid();
        d -= up_.dot(d) * up_;
        radius[k] = std::max(radius[k], d.norm());
      }
    }
    sized.erase(std::remove_if(sized.begin(), sized.end(),
                               [&](int k) { return 2.0 * radius[k] > options_.max_width; }),
                sized.end());
  }
  local.person_sized = static_cast<int>(sized.size());

  // The subject: the tracked one, else a new choice.
  int chosen = -1;
  if (has_subject_) {
    double best = options_.track_max_distance;
    for (int k : sized) {
      const double d = (components[k].centroid() - subject_centroid_).norm();
      if (d < best) {
        best = d;
        chosen = k;
      }
    }
    local.tracked = chosen >= 0;
  }
  if (chosen < 0) {
    double best = -1e300;
    const double cu = 0.5 * (w - 1), cv = 0.5 * (h - 1), scale = 0.25 * w;
    for (int k : sized) {
      const Component& c = components[k];
      double score = 0;
      switch (options_.choice) {
        case SubjectChoice::kCentral: {
          // Most complete near the centre: pixels damped by the centroid's image distance.
          const double du = c.u_sum / c.pixels - cu, dv = c.v_sum / c.pixels - cv;
          score = c.pixels / (1.0 + (du * du + dv * dv) / (scale * scale));
          break;
        }
        case SubjectChoice::kNearest:
          score = -c.z_min;
          break;
        case SubjectChoice::kLargest:
          score = c.pixels;
          break;
        case SubjectChoice::kPixel: {
          const double du = c.u_sum / c.pixels - options_.pixel.x();
          const double dv = c.v_sum / c.pixels - options_.pixel.y();
          score = c.contains_pixel ? 1e300 : -(du * du + dv * dv);
          break;
        }
      }
      if (score > best) {
        best = score;
        chosen = k;
      }
    }
  }
  mask->create(h, w, CV_8UC1);
  mask->setTo(0);
  has_subject_ = chosen >= 0;
  if (has_subject_) {
    const Component& c = components[chosen];
    subject_centroid_ = c.centroid();
    local.subject_pixels = c.pixels;
    local.subject_centroid = subject_centroid_;
    local.subject_height = c.up_max - c.up_min;
    local.subject_width = 2.0 * radius[chosen];
    const int root = c.root;
    for (int v = 0; v < h; ++v) {
      uint8_t* out = mask->ptr<uint8_t>(v);
      for (int u = 0; u < w; ++u) {
        const int i = v * w + u;
        if (z_[i] != 0.0f && parent_[i] == root) out[u] = 255;
      }
    }
  }
  if (stats) *stats = local;
}

void SubjectSegmenter::JoinStackedParts(int w, int h) {
  // Parts of one body that no pixel chain links (a band of dropped pixels along the near arm
  // cuts a walking body seen from the side at the waist): one above the other, overlapping in
  // image columns, at about one depth, one person's height in all.
  struct Part {
    int root = -1, pixels = 0, u_min = 1 << 30, u_max = -1;
    float low = 1e30f, high = -1e30f, z_min = 1e30f, z_max = -1e30f;
  };
  std::vector<int> slot(parent_.size(), -1);
  std::vector<Part> parts;
  const Eigen::Vector3f up = up_.cast<float>();
  for (int v = 0; v < h; ++v) {
    const float* ray = RayRow(v);
    for (int u = 0; u < w; ++u) {
      const int i = v * w + u;
      if (z_[i] == 0.0f) continue;
      const int r = Find(parent_, i);
      if (slot[r] < 0) {
        slot[r] = static_cast<int>(parts.size());
        parts.emplace_back();
        parts.back().root = r;
      }
      Part& p = parts[slot[r]];
      const float height = z_[i] * (up.x() * ray[2 * u] + up.y() * ray[2 * u + 1] + up.z());
      ++p.pixels;
      p.u_min = std::min(p.u_min, u);
      p.u_max = std::max(p.u_max, u);
      p.low = std::min(p.low, height);
      p.high = std::max(p.high, height);
      p.z_min = std::min(p.z_min, z_[i]);
      p.z_max = std::max(p.z_max, z_[i]);
    }
  }
  std::vector<int> big;
  for (int k = 0; k < static_cast<int>(parts.size()); ++k) {
    if (parts[k].pixels >= options_.min_pixels) big.push_back(k);
  }
  const float gap = static_cast<float>(options_.stacked_max_gap);
  const double rel = options_.merge_relative;
  for (size_t a = 0; a < big.size(); ++a) {
    for (size_t b = a + 1; b < big.size(); ++b) {
      Part& pa = parts[big[a]];
      Part& pb = parts[big[b]];
      const float overlap = std::min(pa.high, pb.high) - std::max(pa.low, pb.low);
      const float shorter = std::min(pa.high - pa.low, pb.high - pb.low);
      const float height = std::max(pa.high, pb.high) - std::min(pa.low, pb.low);
      // Depth ranges that overlap, or nearly (merge_relative * z apart).
      const float depth_gap = std::max(pa.z_min, pb.z_min) - std::min(pa.z_max, pb.z_max);
      const float near = std::max(pa.z_min, pb.z_min);
      const bool columns = std::min(pa.u_max, pb.u_max) > std::max(pa.u_min, pb.u_min);
      if (!(columns && overlap > -gap && overlap < options_.stacked_max_overlap * shorter &&
            height <= options_.max_height && depth_gap < rel * near)) {
        continue;
      }
      const int ra = Find(parent_, pa.root), rb = Find(parent_, pb.root);
      if (ra == rb) continue;
      parent_[std::max(ra, rb)] = std::min(ra, rb);
      // The joined part's extent, for the following pairs.
      for (Part* p : {&pa, &pb}) {
        p->low = std::min(pa.low, pb.low);
        p->high = std::max(pa.high, pb.high);
        p->u_min = std::min(pa.u_min, pb.u_min);
        p->u_max = std::max(pa.u_max, pb.u_max);
        p->z_min = std::min(pa.z_min, pb.z_min);
        p->z_max = std::max(pa.z_max, pb.z_max);
      }
    }
  }
}

void SubjectSegmenter::SplitPeople(int w, int h, int* splits) {
  const SubjectSegmentationOptions& o = options_;
  Eigen::Vector3d lateral = Eigen::Vector3d::UnitX() - up_.x() * up_;
  if (lateral.norm() < 1e-6) return;
  lateral.normalize();
  struct Profile {
    float lmin = 1e30f, lmax = -1e30f, top = -1e30f;
    int pixels = 0;
    std::vector<float> tops;  // per lateral bin, -inf when empty
    std::vector<float> cuts;  // lateral split positions, ascending
    std::vector<int> part_root;
  };
  std::unordered_map<int, Profile> profiles;
  auto point = [&](int u, int v, int i) { return projector_.CameraPoint(u, v, z_[i]); };
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const int i = v * w + u;
      if (z_[i] == 0.0f) continue;
      Profile& p = profiles[parent_[i]];
      const Eigen::Vector3d x = point(u, v, i);
      const float l = static_cast<float>(lateral.dot(x));
      p.lmin = std::min(p.lmin, l);
      p.lmax = std::max(p.lmax, l);
      p.top = std::max(p.top, static_cast<float>(up_.dot(x)));
      ++p.pixels;
    }
  }
  bool any = false;
  for (auto& [root, p] : profiles) {
    if (p.pixels < o.min_pixels || p.lmax - p.lmin < 2 * o.min_head_separation) continue;
    p.tops.assign(static_cast<size_t>((p.lmax - p.lmin) / o.head_bin) + 1, -1e30f);
    any = true;
  }
  if (!any) return;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const int i = v * w + u;
      if (z_[i] == 0.0f) continue;
      Profile& p = profiles[parent_[i]];
      if (p.tops.empty()) continue;
      const Eigen::Vector3d x = point(u, v, i);
      const size_t b = static_cast<size_t>((lateral.dot(x) - p.lmin) / o.head_bin);
      float& t = p.tops[std::min(b, p.tops.size() - 1)];
      t = std::max(t, static_cast<float>(up_.dot(x)));
    }
  }
  const int window = std::max(1, static_cast<int>(0.5 * o.min_head_separation / o.head_bin));
  for (auto& [root, p] : profiles) {
    if (p.tops.empty()) continue;
    const int nb = static_cast<int>(p.tops.size());
    // Width (m) of the run of bins around b whose top reaches `level`.
    auto run_width = [&](int b, float level) {
      int a = b, c = b;
      while (a > 0 && p.tops[a - 1] >= level) --a;
      while (c + 1 < nb && p.tops[c + 1] >= level) ++c;
      return (c - a + 1) * o.head_bin;
    };
    std::vector<int> heads;
    for (int b = 0; b < nb; ++b) {
      const float t = p.tops[b];
      if (t < p.top - o.head_top_range) continue;
      bool peak = true;
      for (int k = std::max(0, b - window); k <= std::min(nb - 1, b + window) && peak; ++k)
        peak = p.tops[k] < t || (p.tops[k] == t && k >= b);
      if (!peak) continue;
      if (run_width(b, t - static_cast<float>(o.head_depth)) > o.max_head_width) continue;
      if (run_width(b, t - static_cast<float>(o.shoulder_drop)) < o.min_shoulder_width) continue;
      heads.push_back(b);
    }
    for (size_t k = 1; k < heads.size(); ++k) {
      const int a = heads[k - 1], b = heads[k];
      if ((b - a) * o.head_bin < o.min_head_separation) continue;
      int valley = a;
      for (int m = a; m <= b; ++m)
        if (p.tops[m] < p.tops[valley]) valley = m;
      if (p.tops[valley] > std::min(p.tops[a], p.tops[b]) - o.min_valley) continue;
      p.cuts.push_back(p.lmin + (valley + 0.5f) * static_cast<float>(o.head_bin));
    }
    if (!p.cuts.empty()) {
      p.part_root.assign(p.cuts.size() + 1, -1);
      ++*splits;
    }
  }
  if (*splits == 0) return;
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const int i = v * w + u;
      if (z_[i] == 0.0f) continue;
      auto it = profiles.find(parent_[i]);
      if (it == profiles.end() || it->second.cuts.empty()) continue;
      Profile& p = it->second;
      const float l = static_cast<float>(lateral.dot(point(u, v, i)));
      const size_t part =
          static_cast<size_t>(std::upper_bound(p.cuts.begin(), p.cuts.end(), l) - p.cuts.begin());
      if (p.part_root[part] < 0) p.part_root[part] = i;
      parent_[i] = p.part_root[part];
    }
  }
}

}  // namespace artex
