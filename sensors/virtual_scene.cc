#include "sensors/virtual_scene.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <functional>
#include <sstream>

#include "models/error.h"
#include "models/numeric.h"
#include "sensors/option_text.h"
#include "sensors/synth_random.h"

namespace artex {
namespace {

using synth_random::Hash01;
using synth_random::kStreamBoxes;
using synth_random::kStreamScene;

constexpr int kMaxBoxes = 32;

using option_text::Fail;
using option_text::Str;

// Box k's local frame: x along its width, z along its depth (yaw about +Y).
Eigen::Matrix3d BoxRotation(const SceneBox& b) {
  return Eigen::AngleAxisd(b.yaw_deg * kDegToRad, Eigen::Vector3d::UnitY()).toRotationMatrix();
}

}  // namespace

bool SceneBox::IsValid(std::string* error) const {
  if (!center_xz.allFinite() || !std::isfinite(yaw_deg))
    return Fail(error, "box centre and yaw must be finite");
  if (!size_m.allFinite() || !(size_m.minCoeff() > 0))
    return Fail(error, "box size_m must be finite and > 0, found (" + Str(size_m.x()) + ", " +
                           Str(size_m.y()) + ", " + Str(size_m.z()) + ")");
  if (!rgb.allFinite() || rgb.minCoeff() < 0 || rgb.maxCoeff() > 1)
    return Fail(error, "box rgb must be in [0, 1]");
  return true;
}

bool SceneOptions::IsValid(std::string* error) const {
  if (!(half_width_m > 0 && wall_height_m > 0))
    return Fail(error, "scene.half_width_m and scene.wall_height_m must be > 0");
  if (!(floor_front_z_m > wall_z_m))
    return Fail(error, "scene.floor_front_z_m must exceed scene.wall_z_m, found " +
                           Str(floor_front_z_m) + " <= " + Str(wall_z_m));
  if (!(cell_m > 0.01)) return Fail(error, "scene.cell_m must be > 0.01, found " + Str(cell_m));
  if (!(pattern_m > 0)) return Fail(error, "scene.pattern_m must be > 0, found " + Str(pattern_m));
  if (boxes.size() > static_cast<size_t>(kMaxBoxes))
    return Fail(error, "scene.boxes: expected at most " + Str(kMaxBoxes) + " boxes, found " +
                           Str(boxes.size()));
  for (size_t k = 0; k < boxes.size(); ++k) {
    std::string why;
    if (!boxes[k].IsValid(&why)) return Fail(error, "scene.boxes[" + Str(k) + "]: " + why);
  }
  return true;
}

bool BoxLayoutOptions::IsValid(std::string* error) const {
  auto range = [&](const char* name, double lo, double hi) {
    if (lo > 0 && hi >= lo && std::isfinite(hi)) return true;
    return Fail(error, std::string("box_layout: expected 0 < min_") + name + "_m <= max_" + name +
                           "_m, found " + Str(lo) + ", " + Str(hi));
  };
  if (!range("width", min_width_m, max_width_m) || !range("depth", min_depth_m, max_depth_m) ||
      !range("height", min_height_m, max_height_m))
    return false;
  if (!(clear_radius_m >= 0 && max_side_m > 0 && max_behind_m >= 0 && max_front_m >= 0 &&
        std::isfinite(max_side_m + max_behind_m + max_front_m + clear_radius_m)))
    return Fail(error,
                "box_layout: clear_radius_m, max_behind_m, max_front_m must be >= 0 and "
                "max_side_m > 0");
  if (!(max_yaw_deg >= 0 && max_yaw_deg <= 180))
    return Fail(error, "box_layout.max_yaw_deg must be in [0, 180], found " + Str(max_yaw_deg));
  return true;
}

std::vector<SceneBox> GenerateSceneBoxes(const SceneOptions& scene, const BoxLayoutOptions& layout,
                                         int count, uint64_t seed,
                                         const Eigen::Vector3d& clear_center) {
  std::string why;
  if (!layout.IsValid(&why)) throw Error(why);
  if (count < 0 || count > kMaxBoxes)
    throw Error("boxes: expected a count in [0, " + Str(kMaxBoxes) + "], found " + Str(count));
  if (!clear_center.allFinite()) throw Error("boxes: the clear centre must be finite");
  std::vector<SceneBox> boxes;
  constexpr int kAttempts = 64;  // rejection sampling against overlaps (then accepted anyway)
  for (int k = 0; k < count; ++k) {
    const double side = (k % 2 == 0) ? -1.0 : 1.0;  // left (-x) first
    SceneBox best;
    for (int a = 0; a < kAttempts; ++a) {
      auto u = [&](int i) { return Hash01(seed, kStreamBoxes, k * kAttempts + a, i); };
      SceneBox b;
      b.size_m =
          Eigen::Vector3d(layout.min_width_m + (layout.max_width_m - layout.min_width_m) * u(0),
                          layout.min_height_m + (layout.max_height_m - layout.min_height_m) * u(1),
                          layout.min_depth_m + (layout.max_depth_m - layout.min_depth_m) * u(2));
      b.yaw_deg = layout.max_yaw_deg * (2 * u(3) - 1);
      const double radius = 0.5 * std::hypot(b.size_m.x(), b.size_m.z());
      const double inner = layout.clear_radius_m + radius;
      const double x = inner + std::max(0.0, layout.max_side_m - inner) * u(4);
      const double z_lo =
          std::max(clear_center.z() - layout.max_behind_m, scene.wall_z_m + radius + 0.05);
      const double z_hi = std::max(z_lo, clear_center.z() + layout.max_front_m);
      b.center_xz = Eigen::Vector2d(clear_center.x() + side * x, z_lo + (z_hi - z_lo) * u(5));
      b.rgb = Eigen::Vector3d(0.25 + 0.6 * u(6), 0.2 + 0.55 * u(7), 0.15 + 0.5 * u(8));
      best = b;
      bool overlaps = false;
      for (const SceneBox& o : boxes) {
        const double ro = 0.5 * std::hypot(o.size_m.x(), o.size_m.z());
        overlaps |= (o.center_xz - b.center_xz).norm() < radius + ro + 0.05;
      }
      if (!overlaps) break;
    }
    boxes.push_back(best);
  }
  return boxes;
}

SceneMesh BuildSceneMesh(const SceneOptions& s) {
  std::vector<Eigen::Vector3d> v;
  std::vector<Eigen::Vector3i> t;
  std::vector<int> part;
  auto grid = [&](int nu, int nv, int which,
                  const std::function<Eigen::Vector3d(double, double)>& at) {
    const int base = static_cast<int>(v.size());
    for (int j = 0; j <= nv; ++j) {
      for (int i = 0; i <= nu; ++i)
        v.push_back(at(static_cast<double>(i) / nu, static_cast<double>(j) / nv));
    }
    for (int j = 0; j < nv; ++j) {
      for (int i = 0; i < nu; ++i) {
        const int a = base + j * (nu + 1) + i, b = a + 1, c = a + nu + 1, d = c + 1;
        // Counter-clockwise in (u, v): the normal is du x dv.
        t.emplace_back(a, b, d);
        t.emplace_back(a, d, c);
        part.push_back(which);
        part.push_back(which);
      }
    }
  };
  auto cells = [&](double length) {
    return std::max(1, static_cast<int>(std::ceil(length / s.cell_m)));
  };
  const double w = s.half_width_m;
  const int nx = cells(2 * w);
  if (s.floor) {
    // u: x from -w to w, v: z from front to wall; du x dv = (+x) x (-z) = +y (up).
    grid(nx, cells(s.floor_front_z_m - s.wall_z_m), static_cast<int>(ScenePart::kFloor),
         [&](double a, double b) {
           return Eigen::Vector3d(-w + 2 * w * a, 0.0,
                                  s.floor_front_z_m + (s.wall_z_m - s.floor_front_z_m) * b);
         });
  }
  if (s.back_wall) {
    // u: x from -w to w, v: y upwards; du x dv = +z (towards the subject and the cameras).
    grid(nx, cells(s.wall_height_m), static_cast<int>(ScenePart::kWall), [&](double a, double b) {
      return Eigen::Vector3d(-w + 2 * w * a, s.wall_height_m * b, s.wall_z_m);
    });
  }
  for (size_t k = 0; k < s.boxes.size(); ++k) {
    const SceneBox& box = s.boxes[k];
    const Eigen::Matrix3d r = BoxRotation(box);
    const Eigen::Vector3d centre(box.center_xz.x(), 0.5 * box.size_m.y(), box.center_xz.y());
    const Eigen::Vector3d half = 0.5 * box.size_m;
    const int which = static_cast<int>(ScenePart::kBox) + static_cast<int>(k);
    // Five faces (no bottom); local axes 0 = x (width), 1 = y (height), 2 = z (depth). Face
    // f spans (e_u, e_v) with e_u x e_v = its outward normal e_n, so the grid is
    // counter-clockwise seen from outside.
    struct Face {
      int n;
      double sign;
      int u, v;
    };
    const Face faces[5] = {{0, 1, 1, 2}, {0, -1, 2, 1}, {2, 1, 0, 1}, {2, -1, 1, 0}, {1, 1, 2, 0}};
    for (const Face& f : faces) {
      const Eigen::Vector3d en = f.sign * Eigen::Vector3d::Unit(f.n);
      const Eigen::Vector3d origin = centre + r * (half[f.n] * en);
      const Eigen::Vector3d eu = r * Eigen::Vector3d::Unit(f.u),
                            ev = r * Eigen::Vector3d::Unit(f.v);
      const double lu = box.size_m[f.u], lv = box.size_m[f.v];
      grid(cells(lu), cells(lv), which, [&](double a, double b) {
        return Eigen::Vector3d(origin + (a - 0.5) * lu * eu + (b - 0.5) * lv * ev);
      });
    }
  }
  SceneMesh mesh;
  mesh.vertices.resize(static_cast<int>(v.size()), 3);
  for (size_t i = 0; i < v.size(); ++i) mesh.vertices.row(i) = v[i].transpose();
  mesh.triangles.resize(static_cast<int>(t.size()), 3);
  for (size_t i = 0; i < t.size(); ++i) mesh.triangles.row(i) = t[i].transpose();
  mesh.part = std::move(part);
  return mesh;
}

Eigen::Vector3d SceneAlbedo(const SceneOptions& s, uint64_t seed, int part,
                            const Eigen::Vector3d& x) {
  const double p = s.pattern_m;
  if (part == static_cast<int>(ScenePart::kFloor)) {
    // Floor: planks along z (width p / 2, length 4 p, staggered), grain and dark joints.
    const double plank_w = 0.5 * p, plank_l = 4 * p;
    const double fx = x.x() / plank_w;
    const int64_t i = static_cast<int64_t>(std::floor(fx));
    const double fz = x.z() / plank_l + Hash01(seed, kStreamScene, 11, i);
    const int64_t k = static_cast<int64_t>(std::floor(fz));
    const double tone = 0.75 + 0.5 * Hash01(seed, kStreamScene, 13 + i, k);
    const double grain =
        1.0 +
        0.08 * std::sin(2 * kPi * (x.z() / (0.03 * p) + 7 * Hash01(seed, kStreamScene, 17 + i, k)));
    Eigen::Vector3d c = Eigen::Vector3d(0.55, 0.38, 0.22) * tone * grain;
    if (Frac(fx) < 0.03 || Frac(fz) < 0.008) c *= 0.35;
    return c;
  }
  if (part >= static_cast<int>(ScenePart::kBox)) {
    // Box: its colour, horizontal boards of height p / 2 with dark joints and a faint tone
    // variation per board.
    const int k = part - static_cast<int>(ScenePart::kBox);
    const SceneBox& box = s.boxes[k];
    const double fy = x.y() / (0.5 * p);
    const int64_t board = static_cast<int64_t>(std::floor(fy));
    Eigen::Vector3d c = box.rgb * (0.85 + 0.3 * Hash01(seed, kStreamScene, 47 + k, board));
    if (Frac(fy) < 0.04) c *= 0.4;
    return c.cwiseMin(1.0);
  }
  // Wall: wallpaper of diamonds, a few posters, a skirting board.
  if (x.y() < 0.1) return Eigen::Vector3d(0.9, 0.9, 0.88);
  const int num_posters = 4;
  for (int k = 0; k < num_posters; ++k) {
    const double px =
        -s.half_width_m + 0.5 + (2 * s.half_width_m - 1.0) * Hash01(seed, kStreamScene, 19, k);
    const double py = 0.9 + 1.2 * Hash01(seed, kStreamScene, 23, k);
    const double hw = 0.25 + 0.2 * Hash01(seed, kStreamScene, 29, k),
                 hh = 0.3 + 0.2 * Hash01(seed, kStreamScene, 31, k);
    const double u = (x.x() - px) / hw, v = (x.y() - py) / hh;
    if (std::abs(u) < 1 && std::abs(v) < 1) {
      const Eigen::Vector3d a(Hash01(seed, kStreamScene, 37, k), Hash01(seed, kStreamScene, 41, k),
                              Hash01(seed, kStreamScene, 43, k));
      const Eigen::Vector3d b = Eigen::Vector3d::Ones() - a;
      const bool band = Frac(3 * v + 2 * u) < 0.5;
      return (std::abs(u) > 0.92 || std::abs(v) > 0.94) ? Eigen::Vector3d(0.05, 0.05, 0.05)
                                                        : (band ? a : b);
    }
  }
  const double du = Frac((x.x() + x.y()) / p), dv = Frac((x.x() - x.y()) / p);
  const bool diamond = (du < 0.5) != (dv < 0.5);
  return diamond ? Eigen::Vector3d(0.78, 0.74, 0.66) : Eigen::Vector3d(0.66, 0.70, 0.74);
}

// ---------------------------------------------------------------------------------------------
// Camera placement and the second person

bool CameraPlacement::IsValid(std::string* error) const {
  if (!(height_m > 0 && std::isfinite(height_m)))
    return Fail(error,
                "camera_placement.height_m (--camera-height) must be > 0, found " + Str(height_m));
  if (!(distance_m > 0.05 && std::isfinite(distance_m)))
    return Fail(error, "camera_placement.distance_m (--camera-distance) must be > 0.05, found " +
                           Str(distance_m));
  if (!std::isfinite(azimuth_deg))
    return Fail(error, "camera_placement.azimuth_deg (--camera-azimuth) must be finite, found " +
                           Str(azimuth_deg));
  if (!std::isfinite(target_height_m))
    return Fail(error,
                "camera_placement.target_height_m (--camera-target-height) must be finite, "
                "found " +
                    Str(target_height_m));
  return true;
}

Eigen::Vector3d CameraPlacement::Eye(const Eigen::Vector3d& p) const {
  const double a = azimuth_deg * kDegToRad;
  return Eigen::Vector3d(p.x() + distance_m * std::sin(a), height_m,
                         p.z() + distance_m * std::cos(a));
}

Eigen::Vector3d CameraPlacement::Target(const Eigen::Vector3d& p) const {
  return Eigen::Vector3d(p.x(), target_height_m, p.z());
}

CameraPlacement UpperBodyCameraPlacement(double stature_m) {
  CameraPlacement c;
  c.height_m = 0.88 * stature_m;
  c.distance_m = 1.0;
  c.azimuth_deg = 0.0;
  c.target_height_m = c.height_m;
  return c;
}

BodyShapeOptions DefaultSecondPersonShape() {
  BodyShapeOptions s;
  s.height = 1.63;
  s.girth = 0.95;
  s.shoulder_width = 0.92;
  s.hip_width = 1.1;
  s.arm_length = 1.0;
  s.leg_length = 0.97;
  return s;
}

bool SecondPersonOptions::IsValid(std::string* error) const {
  if (!enabled) return true;
  std::string why;
  if (!shape.IsValid(&why)) return Fail(error, "second_person.shape: " + why);
  if (!texture.IsValid(&why)) return Fail(error, "second_person.texture: " + why);
  MotionOptions m = motion;
  m.frames = 1;  // replaced by the subject's
  if (!m.IsValid(&why)) return Fail(error, "second_person.motion: " + why);
  if (!std::isfinite(behind_m) || !std::isfinite(start_across_m))
    return Fail(error, "second_person.behind_m and start_across_m must be finite");
  if (!(std::abs(speed_m_s) <= 5))
    return Fail(error,
                "second_person.speed_m_s (--second-person-speed) must be in [-5, 5], found " +
                    Str(speed_m_s));
  return true;
}

}  // namespace artex
