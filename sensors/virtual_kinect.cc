#include "sensors/virtual_kinect.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <opencv2/core.hpp>
#include <random>
#include <sstream>

#include "models/error.h"
#include "models/normals.h"
#include "models/skinning.h"
#include "models/template_io.h"
#include "render/rasterizer.h"
#include "sensors/bvh.h"

namespace artex {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDegToRad = kPi / 180.0;

// Independent noise streams (mixed into the per-row generator seeds).
constexpr uint64_t kStreamFrameDepth = 1;
constexpr uint64_t kStreamBackgroundDepth = 2;
constexpr uint64_t kStreamColor = 3;
constexpr uint64_t kStreamColorWalk = 4;
constexpr uint64_t kStreamScene = 5;

uint64_t SplitMix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}
uint64_t MixSeed(uint64_t seed, uint64_t stream, uint64_t frame, uint64_t row) {
  return SplitMix(SplitMix(SplitMix(SplitMix(seed) ^ stream) ^ frame) ^ row);
}
double Hash01(uint64_t a, uint64_t b, uint64_t c) {
  return (MixSeed(a, kStreamScene, b, c) >> 11) * (1.0 / 9007199254740992.0);
}
double Frac(double x) { return x - std::floor(x); }

bool Fail(std::string* error, const std::string& message) {
  if (error) *error = message;
  return false;
}
template <typename T>
std::string Str(const T& value) {
  std::ostringstream s;
  s << value;
  return s.str();
}

Eigen::Isometry3d Translation(const Eigen::Vector3d& t) {
  Eigen::Isometry3d m = Eigen::Isometry3d::Identity();
  m.translation() = t;
  return m;
}

// Reflects x into [-limit, limit] (and flips the velocity accordingly).
void Reflect(double limit, double* x, double* v) {
  if (limit <= 0) {
    *x = 0;
    return;
  }
  for (int k = 0; k < 4 && std::abs(*x) > limit; ++k) {
    *x = (*x > 0 ? 2 * limit : -2 * limit) - *x;
    *v = -*v;
  }
  *x = std::clamp(*x, -limit, limit);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Options

NoiseLevel ParseNoiseLevel(const std::string& name) {
  if (name == "off") return NoiseLevel::kOff;
  if (name == "default") return NoiseLevel::kDefault;
  if (name == "high") return NoiseLevel::kHigh;
  throw Error("noise level: expected one of off, default, high; found '" + name + "'");
}

const char* NoiseLevelName(NoiseLevel level) {
  switch (level) {
    case NoiseLevel::kOff:
      return "off";
    case NoiseLevel::kDefault:
      return "default";
    case NoiseLevel::kHigh:
      return "high";
  }
  return "default";
}

bool DepthNoiseOptions::IsValid(std::string* error) const {
  if (!(baseline_m > 0))
    return Fail(error, "depth_noise.baseline_m must be > 0, found " + Str(baseline_m));
  if (!(disparity_step_px >= 0))
    return Fail(error,
                "depth_noise.disparity_step_px must be >= 0, found " + Str(disparity_step_px));
  if (!(disparity_noise_px >= 0))
    return Fail(error,
                "depth_noise.disparity_noise_px must be >= 0, found " + Str(disparity_noise_px));
  if (!(min_depth_m >= 0 && max_depth_m > min_depth_m))
    return Fail(error, "depth_noise: expected 0 <= min_depth_m < max_depth_m, found " +
                           Str(min_depth_m) + ", " + Str(max_depth_m));
  if (!(edge_jump_m > 0))
    return Fail(error, "depth_noise.edge_jump_m must be > 0, found " + Str(edge_jump_m));
  if (edge_radius_px < 0 || edge_radius_px > 8)
    return Fail(error,
                "depth_noise.edge_radius_px must be in [0, 8], found " + Str(edge_radius_px));
  if (!(edge_drop_probability >= 0 && edge_drop_probability <= 1))
    return Fail(error, "depth_noise.edge_drop_probability must be in [0, 1], found " +
                           Str(edge_drop_probability));
  if (!(grazing_angle_deg > 0 && grazing_angle_deg <= 90))
    return Fail(
        error, "depth_noise.grazing_angle_deg must be in (0, 90], found " + Str(grazing_angle_deg));
  if (!projector_offset_m.allFinite())
    return Fail(error, "depth_noise.projector_offset_m must be finite");
  if (!(shadow_tolerance_m >= 0))
    return Fail(error,
                "depth_noise.shadow_tolerance_m must be >= 0, found " + Str(shadow_tolerance_m));
  if (projector_margin_px < 0 || projector_margin_px > 4096)
    return Fail(error, "depth_noise.projector_margin_px must be in [0, 4096], found " +
                           Str(projector_margin_px));
  if (!(random_dropout >= 0 && random_dropout <= 1))
    return Fail(error,
                "depth_noise.random_dropout must be in [0, 1], found " + Str(random_dropout));
  return true;
}

bool ColorModelOptions::IsValid(std::string* error) const {
  if (!(ambient >= 0 && ambient <= 1))
    return Fail(error, "color_model.ambient must be in [0, 1], found " + Str(ambient));
  if (!light_direction.allFinite() || light_direction.norm() == 0)
    return Fail(error, "color_model.light_direction must be a finite non-zero vector");
  if (!(noise_std >= 0))
    return Fail(error, "color_model.noise_std must be >= 0, found " + Str(noise_std));
  if (!(exposure_step >= 0 && exposure_limit >= 0 && white_balance_step >= 0 &&
        white_balance_limit >= 0))
    return Fail(error, "color_model: exposure/white-balance steps and limits must be >= 0");
  if (!(walk_smoothing >= 0 && walk_smoothing < 1))
    return Fail(error,
                "color_model.walk_smoothing must be in [0, 1), found " + Str(walk_smoothing));
  if (!background_rgb.allFinite()) return Fail(error, "color_model.background_rgb must be finite");
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
  return true;
}

bool VirtualKinectOptions::IsValid(std::string* error) const {
  const PinholeCamera& d = depth_intrinsics;
  if (d.width <= 0 || d.height <= 0 || !(d.fx > 0) || !(d.fy > 0))
    return Fail(error, "depth camera: expected positive size and focal lengths, found " +
                           Str(d.width) + " x " + Str(d.height) + ", f " + Str(d.fx) + ", " +
                           Str(d.fy));
  if (color_width <= 0 || color_height <= 0 || color_width > 8192 || color_height > 8192)
    return Fail(error, "color camera size must be in [1, 8192]^2, found " + Str(color_width) +
                           " x " + Str(color_height));
  if (!(color_vertical_fov_deg > 1 && color_vertical_fov_deg < 170))
    return Fail(error,
                "color_vertical_fov_deg must be in (1, 170), found " + Str(color_vertical_fov_deg));
  if (!depth_eye.allFinite() || !depth_target.allFinite() ||
      (depth_eye - depth_target).norm() < 1e-6)
    return Fail(error, "depth_eye and depth_target must be finite and distinct");
  if (!color_offset_m.allFinite() || !std::isfinite(color_yaw_deg) ||
      !std::isfinite(color_pitch_deg))
    return Fail(error, "color camera offset / yaw / pitch must be finite");
  if (!(depth_scale > 0)) return Fail(error, "depth_scale must be > 0, found " + Str(depth_scale));
  if (!(frame_rate > 0)) return Fail(error, "frame_rate must be > 0, found " + Str(frame_rate));
  if (!(near_plane_m > 0))
    return Fail(error, "near_plane_m must be > 0, found " + Str(near_plane_m));
  return scene.IsValid(error) && depth_noise.IsValid(error) && color_model.IsValid(error);
}

void VirtualKinectOptions::SetNoiseLevel(NoiseLevel level) {
  DepthNoiseOptions d;
  ColorModelOptions c;
  // Geometry of the sensor is kept from the current options.
  d.baseline_m = depth_noise.baseline_m;
  d.projector_offset_m = depth_noise.projector_offset_m;
  d.min_depth_m = depth_noise.min_depth_m;
  d.max_depth_m = depth_noise.max_depth_m;
  c.ambient = color_model.ambient;
  c.light_direction = color_model.light_direction;
  c.background_rgb = color_model.background_rgb;
  switch (level) {
    case NoiseLevel::kOff:
      d.disparity_step_px = 0;
      d.disparity_noise_px = 0;
      d.edge_drop_probability = 0;
      d.grazing_angle_deg = 90;
      d.projector_shadow = false;
      d.random_dropout = 0;
      c.noise_std = 0;
      c.exposure_step = 0;
      c.white_balance_step = 0;
      break;
    case NoiseLevel::kDefault:
      break;
    case NoiseLevel::kHigh:
      d.disparity_noise_px = 0.15;
      d.edge_drop_probability = 0.9;
      d.edge_radius_px = 2;
      d.grazing_angle_deg = 70;
      d.random_dropout = 0.01;
      c.noise_std = 0.025;
      c.exposure_step = 0.1;
      c.exposure_limit = 0.4;
      c.white_balance_step = 0.05;
      c.white_balance_limit = 0.15;
      break;
  }
  depth_noise = d;
  color_model = c;
}

BodyShapeOptions DefaultSubjectShape() {
  BodyShapeOptions s;
  s.height = 1.72;
  s.girth = 1.08;
  s.shoulder_width = 1.05;
  s.hip_width = 1.04;
  s.arm_length = 0.98;
  s.leg_length = 1.02;
  return s;
}

bool SynthOptions::IsValid(std::string* error) const {
  if (!kinect.IsValid(error)) return false;
  std::string why;
  if (!subject_shape.IsValid(&why)) return Fail(error, "subject shape: " + why);
  if (!texture.IsValid(&why)) return Fail(error, "subject texture: " + why);
  if (bvh_path.empty() ? motion.frames < 1 : motion.frames < 0)
    return Fail(error,
                "motion.frames must be >= 1 (>= 0 with a BVH file), found " + Str(motion.frames));
  if (!(motion.frame_rate > 0))
    return Fail(error, "motion.frame_rate must be > 0, found " + Str(motion.frame_rate));
  if (background_frames < 0)
    return Fail(error, "background_frames must be >= 0, found " + Str(background_frames));
  if (!subject_position_m.allFinite() || !std::isfinite(subject_yaw_deg))
    return Fail(error, "subject placement must be finite");
  return true;
}

// ---------------------------------------------------------------------------------------------
// Colour conditions

std::vector<ColorConditions> GenerateColorConditions(const ColorModelOptions& options,
                                                     uint64_t seed, int frames) {
  std::vector<ColorConditions> out(std::max(0, frames));
  std::mt19937_64 rng(MixSeed(seed, kStreamColorWalk, 0, 0));
  std::normal_distribution<double> normal(0.0, 1.0);
  const double a = options.walk_smoothing;
  double exposure = 0, exposure_v = 0;
  Eigen::Vector3d wb = Eigen::Vector3d::Zero(), wb_v = Eigen::Vector3d::Zero();
  for (int f = 0; f < frames; ++f) {
    if (f > 0) {
      exposure_v = a * exposure_v + (1 - a) * options.exposure_step * normal(rng);
      exposure += exposure_v;
      Reflect(options.exposure_limit, &exposure, &exposure_v);
      for (int c = 0; c < 3; ++c) {
        wb_v[c] = a * wb_v[c] + (1 - a) * options.white_balance_step * normal(rng);
        wb[c] += wb_v[c];
        Reflect(options.white_balance_limit, &wb[c], &wb_v[c]);
      }
    }
    const Eigen::Vector3d centred = wb.array() - wb.mean();
    for (int c = 0; c < 3; ++c) out[f].gain[c] = std::exp(exposure + centred[c]);
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// VirtualKinect

VirtualKinect::VirtualKinect(const VirtualKinectOptions& options, const Template& subject,
                             const cv::Mat& subject_texture_bgr)
    : options_(options), subject_(subject), texture_(subject_texture_bgr) {
  std::string why;
  if (!options.IsValid(&why)) throw Error("virtual Kinect options: " + why);
  if (!subject.IsValid(&why)) throw Error("virtual Kinect subject: " + why);
  if (!subject.has_uvs()) throw Error("virtual Kinect subject: the template has no UV atlas");
  if (subject_texture_bgr.empty() || subject_texture_bgr.type() != CV_8UC3) {
    throw Error("virtual Kinect subject texture: expected a non-empty CV_8UC3 image, found type " +
                Str(subject_texture_bgr.type()));
  }
  // Depth camera.
  calibration_.depth = options.depth_intrinsics;
  calibration_.depth.world_to_camera =
      PinholeCamera::LookAt(options.depth_eye, options.depth_target, Eigen::Vector3d::UnitY());
  // Colour camera: offset and small rotation relative to the depth camera.
  PinholeCamera& color = calibration_.color;
  color.width = options.color_width;
  color.height = options.color_height;
  color.fy =
      0.5 * options.color_height / std::tan(0.5 * options.color_vertical_fov_deg * kDegToRad);
  color.fx = color.fy;
  color.cx = 0.5 * (options.color_width - 1);
  color.cy = 0.5 * (options.color_height - 1);
  Eigen::Isometry3d depth_to_color = Eigen::Isometry3d::Identity();
  depth_to_color.linear() =
      (Eigen::AngleAxisd(options.color_pitch_deg * kDegToRad, Eigen::Vector3d::UnitX()) *
       Eigen::AngleAxisd(options.color_yaw_deg * kDegToRad, Eigen::Vector3d::UnitY()))
          .toRotationMatrix();
  depth_to_color.translation() = -depth_to_color.linear() * options.color_offset_m;
  color.world_to_camera = depth_to_color * calibration_.depth.world_to_camera;
  calibration_.depth_scale = options.depth_scale;
  calibration_.frame_rate = options.frame_rate;
  // IR projector: same orientation and focal length, shifted, with a wider image.
  projector_ = calibration_.depth;
  const int m = options.depth_noise.projector_margin_px;
  projector_.width += 2 * m;
  projector_.height += 2 * m;
  projector_.cx += m;
  projector_.cy += m;
  projector_.world_to_camera =
      Translation(-options.depth_noise.projector_offset_m) * calibration_.depth.world_to_camera;
  BuildScene();

  // Scene-only buffers of the three views, and the scene's shaded albedo in the colour view.
  RasterOptions raster_options;
  raster_options.near_plane = options.near_plane_m;
  Rasterize(scene_vertices_, scene_triangles_, calibration_.depth, raster_options, &depth_scene_);
  if (options.depth_noise.projector_shadow) {
    Rasterize(scene_vertices_, scene_triangles_, projector_, raster_options, &projector_scene_);
  }
  Rasterize(scene_vertices_, scene_triangles_, calibration_.color, raster_options, &color_scene_);
  ComputeTriangleNormals(scene_vertices_, scene_triangles_, &scene_normals_);
  const ColorModelOptions& c = options.color_model;
  const Eigen::Vector3d light = c.light_direction.normalized();
  color_scene_radiance_.resize(color_scene_.depth.size());
  tbb::parallel_for(size_t{0}, color_scene_.depth.size(), [&](size_t i) {
    const int f = color_scene_.triangle_id[i];
    if (f < 0) {
      color_scene_radiance_[i] = c.background_rgb.cast<float>();
      return;
    }
    const double b1 = color_scene_.barycentric[i].x(), b2 = color_scene_.barycentric[i].y();
    const Eigen::Vector3d p =
        (1 - b1 - b2) * scene_vertices_.row(scene_triangles_(f, 0)).transpose() +
        b1 * scene_vertices_.row(scene_triangles_(f, 1)).transpose() +
        b2 * scene_vertices_.row(scene_triangles_(f, 2)).transpose();
    const double shade =
        c.ambient + (1 - c.ambient) * std::max(0.0, scene_normals_.row(f).dot(light));
    color_scene_radiance_[i] = (SceneAlbedo(p) * shade).cast<float>();
  });
}

void VirtualKinect::BuildScene() {
  const SceneOptions& s = options_.scene;
  std::vector<Eigen::Vector3d> v;
  std::vector<Eigen::Vector3i> t;
  auto grid = [&](int nu, int nv, const std::function<Eigen::Vector3d(double, double)>& at) {
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
      }
    }
  };
  const double w = s.half_width_m;
  const int nx = std::max(1, static_cast<int>(std::ceil(2 * w / s.cell_m)));
  if (s.floor) {
    // u: x from -w to w, v: z from front to wall; du x dv = (+x) x (-z) = +y (up).
    const int nz =
        std::max(1, static_cast<int>(std::ceil((s.floor_front_z_m - s.wall_z_m) / s.cell_m)));
    grid(nx, nz, [&](double a, double b) {
      return Eigen::Vector3d(-w + 2 * w * a, 0.0,
                             s.floor_front_z_m + (s.wall_z_m - s.floor_front_z_m) * b);
    });
  }
  if (s.back_wall) {
    // u: x from -w to w, v: y upwards; du x dv = +z (towards the subject and the cameras).
    const int ny = std::max(1, static_cast<int>(std::ceil(s.wall_height_m / s.cell_m)));
    grid(nx, ny, [&](double a, double b) {
      return Eigen::Vector3d(-w + 2 * w * a, s.wall_height_m * b, s.wall_z_m);
    });
  }
  scene_vertices_.resize(static_cast<int>(v.size()), 3);
  for (size_t i = 0; i < v.size(); ++i) scene_vertices_.row(i) = v[i].transpose();
  scene_triangles_.resize(static_cast<int>(t.size()), 3);
  for (size_t i = 0; i < t.size(); ++i) scene_triangles_.row(i) = t[i].transpose();
}

void VirtualKinect::RenderView(const PinholeCamera& camera, const RasterBuffers& scene,
                               const Eigen::MatrixX3d* posed, RasterBuffers* out) const {
  const int32_t offset = subject_.num_triangles();
  if (posed) {
    RasterOptions raster_options;
    raster_options.near_plane = options_.near_plane_m;
    Rasterize(*posed, subject_.triangles, camera, raster_options, out);
  } else {
    out->width = scene.width;
    out->height = scene.height;
    out->depth.assign(scene.depth.size(), std::numeric_limits<float>::infinity());
    out->triangle_id.assign(scene.depth.size(), -1);
    out->barycentric.resize(scene.depth.size());
  }
  // The subject wins ties, as when rasterising subject triangles before scene triangles.
  tbb::parallel_for(size_t{0}, scene.depth.size(), [&](size_t i) {
    if (out->triangle_id[i] >= 0 && out->depth[i] <= scene.depth[i]) return;
    out->depth[i] = scene.depth[i];
    out->triangle_id[i] = scene.triangle_id[i] >= 0 ? scene.triangle_id[i] + offset : -1;
    out->barycentric[i] = scene.barycentric[i];
  });
}

Eigen::Vector3d VirtualKinect::SceneAlbedo(const Eigen::Vector3d& x) const {
  const SceneOptions& s = options_.scene;
  const uint64_t seed = options_.seed;
  const double p = s.pattern_m;
  if (std::abs(x.y()) < 1e-6 && x.z() > s.wall_z_m + 1e-6) {
    // Floor: planks along z (width p / 2, length 4 p, staggered), grain and dark joints.
    const double plank_w = 0.5 * p, plank_l = 4 * p;
    const double fx = x.x() / plank_w;
    const int64_t i = static_cast<int64_t>(std::floor(fx));
    const double fz = x.z() / plank_l + Hash01(seed, 11, i);
    const int64_t k = static_cast<int64_t>(std::floor(fz));
    const double tone = 0.75 + 0.5 * Hash01(seed, 13 + i, k);
    const double grain =
        1.0 + 0.08 * std::sin(2 * kPi * (x.z() / (0.03 * p) + 7 * Hash01(seed, 17 + i, k)));
    Eigen::Vector3d c = Eigen::Vector3d(0.55, 0.38, 0.22) * tone * grain;
    if (Frac(fx) < 0.03 || Frac(fz) < 0.008) c *= 0.35;
    return c;
  }
  // Wall: wallpaper of diamonds, a few posters, a skirting board.
  if (x.y() < 0.1) return Eigen::Vector3d(0.9, 0.9, 0.88);
  const int num_posters = 4;
  for (int k = 0; k < num_posters; ++k) {
    const double px = -s.half_width_m + 0.5 + (2 * s.half_width_m - 1.0) * Hash01(seed, 19, k);
    const double py = 0.9 + 1.2 * Hash01(seed, 23, k);
    const double hw = 0.25 + 0.2 * Hash01(seed, 29, k), hh = 0.3 + 0.2 * Hash01(seed, 31, k);
    const double u = (x.x() - px) / hw, v = (x.y() - py) / hh;
    if (std::abs(u) < 1 && std::abs(v) < 1) {
      const Eigen::Vector3d a(Hash01(seed, 37, k), Hash01(seed, 41, k), Hash01(seed, 43, k));
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

cv::Mat VirtualKinect::RenderDepth(int frame_index, const Eigen::MatrixX3d* posed,
                                   DepthDiagnostics* diagnostics) const {
  return RenderDepthStream(frame_index, posed, kStreamFrameDepth, diagnostics);
}

cv::Mat VirtualKinect::RenderBackgroundDepth(int index, DepthDiagnostics* diagnostics) const {
  return RenderDepthStream(index, nullptr, kStreamBackgroundDepth, diagnostics);
}

cv::Mat VirtualKinect::RenderDepthStream(int frame_index, const Eigen::MatrixX3d* posed,
                                         uint64_t stream, DepthDiagnostics* diagnostics) const {
  if (posed && posed->rows() != subject_.num_vertices()) {
    throw Error("VirtualKinect: posed vertices: expected " + Str(subject_.num_vertices()) +
                " rows, found " + Str(posed->rows()));
  }
  const DepthNoiseOptions& o = options_.depth_noise;
  const PinholeCamera& cam = calibration_.depth;
  const int subject_triangles = subject_.num_triangles();
  RasterBuffers view, light;
  RenderView(cam, depth_scene_, posed, &view);
  if (o.projector_shadow) RenderView(projector_, projector_scene_, posed, &light);
  Eigen::MatrixX3d subject_normals;
  if (posed) ComputeTriangleNormals(*posed, subject_.triangles, &subject_normals);

  const int w = cam.width, h = cam.height;
  cv::Mat depth(h, w, CV_16UC1, cv::Scalar(0));
  cv::Mat true_depth, status, mask;
  if (diagnostics) {
    true_depth.create(h, w, CV_32FC1);
    status.create(h, w, CV_8UC1);
    mask.create(h, w, CV_8UC1);
  }
  const Eigen::Matrix3d rotation = cam.world_to_camera.linear();
  const double bf = o.baseline_m * cam.fx;
  const double cos_grazing = std::cos(o.grazing_angle_deg * kDegToRad);
  const double max_units = std::numeric_limits<uint16_t>::max();
  const float inf = std::numeric_limits<float>::infinity();

  tbb::parallel_for(0, h, [&](int y) {
    cv::RNG rng(MixSeed(options_.seed, stream, static_cast<uint64_t>(frame_index), y));
    auto* out = depth.ptr<uint16_t>(y);
    for (int x = 0; x < w; ++x) {
      // Draw the same numbers for every pixel whatever its fate: streams stay aligned.
      const double n_disparity = rng.gaussian(1.0);
      const double u_edge = rng.uniform(0.0, 1.0);
      const double u_drop = rng.uniform(0.0, 1.0);
      const int i = view.index(x, y);
      const int f = view.triangle_id[i];
      const float z = view.depth[i];
      DepthStatus s = DepthStatus::kValid;
      if (f < 0) {
        s = DepthStatus::kNoSurface;
      } else if (z < o.min_depth_m || z > o.max_depth_m) {
        s = DepthStatus::kOutOfRange;
      } else {
        const Eigen::Vector3d xc((x - cam.cx) / cam.fx * z, (y - cam.cy) / cam.fy * z, z);
        const Eigen::Vector3d normal =
            f < subject_triangles ? Eigen::Vector3d(subject_normals.row(f))
                                  : Eigen::Vector3d(scene_normals_.row(f - subject_triangles));
        if (std::abs((rotation * normal).dot(xc.normalized())) < cos_grazing) {
          s = DepthStatus::kGrazing;
        }
        if (s == DepthStatus::kValid && o.projector_shadow) {
          const Eigen::Vector3d xp = xc - o.projector_offset_m;
          bool lit = false;
          if (xp.z() > options_.near_plane_m) {
            const double pu = projector_.fx * xp.x() / xp.z() + projector_.cx;
            const double pv = projector_.fy * xp.y() / xp.z() + projector_.cy;
            const int u0 = static_cast<int>(std::floor(pu)), v0 = static_cast<int>(std::floor(pv));
            for (int dv = 0; dv <= 1 && !lit; ++dv) {
              for (int du = 0; du <= 1 && !lit; ++du) {
                const int uu = u0 + du, vv = v0 + dv;
                if (uu < 0 || vv < 0 || uu >= projector_.width || vv >= projector_.height) continue;
                lit = light.depth[light.index(uu, vv)] >= xp.z() - o.shadow_tolerance_m;
              }
            }
          }
          if (!lit) s = DepthStatus::kShadow;
        }
        if (s == DepthStatus::kValid && o.edge_drop_probability > 0) {
          float lo = z, hi = z;
          const int r = o.edge_radius_px;
          for (int yy = std::max(0, y - r); yy <= std::min(h - 1, y + r); ++yy) {
            for (int xx = std::max(0, x - r); xx <= std::min(w - 1, x + r); ++xx) {
              const float d = view.depth[view.index(xx, yy)];
              lo = std::min(lo, d);
              hi = std::max(hi, d);
            }
          }
          if ((hi == inf || hi - lo > o.edge_jump_m) && u_edge < o.edge_drop_probability) {
            s = DepthStatus::kEdge;
          }
        }
        if (s == DepthStatus::kValid && u_drop < o.random_dropout) s = DepthStatus::kDropout;
      }
      if (s == DepthStatus::kValid) {
        double disparity = bf / z + o.disparity_noise_px * n_disparity;
        if (o.disparity_step_px > 0) {
          disparity = std::round(disparity / o.disparity_step_px) * o.disparity_step_px;
        }
        const double units = disparity > 0 ? std::round(bf / disparity * options_.depth_scale) : 0;
        if (units >= 1 && units <= max_units) {
          out[x] = static_cast<uint16_t>(units);
        } else {
          s = DepthStatus::kOutOfRange;
        }
      }
      if (diagnostics) {
        true_depth.at<float>(y, x) = f >= 0 ? z : 0.0f;
        status.at<uint8_t>(y, x) = static_cast<uint8_t>(s);
        mask.at<uint8_t>(y, x) = (f >= 0 && f < subject_triangles) ? 255 : 0;
      }
    }
  });
  if (diagnostics) {
    diagnostics->true_depth = true_depth;
    diagnostics->status = status;
    diagnostics->subject_mask = mask;
  }
  return depth;
}

cv::Mat VirtualKinect::RenderColor(int frame_index, const Eigen::MatrixX3d* posed,
                                   const ColorConditions& conditions) const {
  if (posed && posed->rows() != subject_.num_vertices()) {
    throw Error("VirtualKinect: posed vertices: expected " + Str(subject_.num_vertices()) +
                " rows, found " + Str(posed->rows()));
  }
  const ColorModelOptions& o = options_.color_model;
  const PinholeCamera& cam = calibration_.color;
  const int subject_triangles = subject_.num_triangles();
  RasterBuffers view;
  RenderView(cam, color_scene_, posed, &view);
  Eigen::MatrixX3d vertex_normals;
  if (posed) ComputeVertexNormals(*posed, subject_.triangles, &vertex_normals);
  const Eigen::Vector3d light = o.light_direction.normalized();

  const int w = cam.width, h = cam.height;
  cv::Mat image(h, w, CV_8UC3);
  tbb::parallel_for(0, h, [&](int y) {
    cv::RNG rng(MixSeed(options_.seed, kStreamColor, static_cast<uint64_t>(frame_index), y));
    auto* out = image.ptr<cv::Vec3b>(y);
    for (int x = 0; x < w; ++x) {
      const int i = view.index(x, y);
      const int f = view.triangle_id[i];
      Eigen::Vector3d rgb;
      if (f >= 0 && f < subject_triangles) {
        const double b1 = view.barycentric[i].x(), b2 = view.barycentric[i].y(), b0 = 1 - b1 - b2;
        const Eigen::Vector2d uv = b0 * subject_.uvs.row(subject_.uv_triangles(f, 0)).transpose() +
                                   b1 * subject_.uvs.row(subject_.uv_triangles(f, 1)).transpose() +
                                   b2 * subject_.uvs.row(subject_.uv_triangles(f, 2)).transpose();
        Eigen::Vector3d n = b0 * vertex_normals.row(subject_.triangles(f, 0)).transpose() +
                            b1 * vertex_normals.row(subject_.triangles(f, 1)).transpose() +
                            b2 * vertex_normals.row(subject_.triangles(f, 2)).transpose();
        if (n.norm() > 0) n.normalize();
        const double shade = o.ambient + (1 - o.ambient) * std::max(0.0, n.dot(light));
        rgb = SampleTextureBilinear(texture_, uv) * shade;
      } else {
        rgb = color_scene_radiance_[i].cast<double>();  // the same scene point as when cached
      }
      for (int c = 0; c < 3; ++c) {
        const double value =
            rgb[c] * conditions.gain[c] + (o.noise_std > 0 ? rng.gaussian(o.noise_std) : 0.0);
        out[x][2 - c] = static_cast<uint8_t>(std::lround(255.0 * std::clamp(value, 0.0, 1.0)));
      }
    }
  });
  return image;
}

void VirtualKinect::RenderFrame(int frame_index, const Eigen::MatrixX3d* posed,
                                const ColorConditions& conditions, Frame* frame,
                                DepthDiagnostics* diagnostics) const {
  frame->index = frame_index;
  frame->depth_timestamp = frame_index / options_.frame_rate;
  frame->color_timestamp = frame->depth_timestamp;
  frame->depth = RenderDepth(frame_index, posed, diagnostics);
  frame->color = RenderColor(frame_index, posed, conditions);
}

// ---------------------------------------------------------------------------------------------
// Sequence synthesis

SynthSubject PrepareSynthSubject(const SynthOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error("synthesis options: " + why);
  SynthSubject s;
  s.subject = GenerateTemplate(options.subject_shape);
  s.texture_bgr = GenerateSubjectTexture(s.subject, options.texture);
  if (!options.bvh_path.empty()) {
    BvhRetargetOptions retarget;
    retarget.frame_rate = options.motion.frame_rate;
    s.poses = LoadBvhMotion(options.bvh_path, s.subject, retarget);
    if (options.motion.frames > 0 && static_cast<int>(s.poses.size()) > options.motion.frames) {
      s.poses.resize(options.motion.frames);
    }
    if (s.poses.empty()) throw Error("BVH file '" + options.bvh_path + "': no frames");
  } else {
    s.poses = GenerateMotion(s.subject, options.motion);
  }
  const Eigen::Matrix3d yaw =
      Eigen::AngleAxisd(options.subject_yaw_deg * kDegToRad, Eigen::Vector3d::UnitY())
          .toRotationMatrix();
  for (Pose& p : s.poses) {
    p.rotation = yaw * p.rotation;
    p.translation = yaw * p.translation + options.subject_position_m;
  }
  return s;
}

SynthSummary SynthesizeSequence(const SynthOptions& options, const std::string& out_folder,
                                const std::function<void(const SynthProgress&)>& progress) {
  if (progress) {
    SynthProgress p;
    progress(p);  // kSetup, 0 of 1: the subject is being generated
  }
  const auto start = std::chrono::steady_clock::now();
  const SynthSubject subject = PrepareSynthSubject(options);
  SynthSummary summary = SynthesizeSequence(options, subject, out_folder, progress);
  const double setup =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() -
      summary.total_seconds;
  summary.setup_seconds += setup;
  summary.total_seconds += setup;
  return summary;
}

SynthSummary SynthesizeSequence(const SynthOptions& options, const SynthSubject& s,
                                const std::string& out_folder,
                                const std::function<void(const SynthProgress&)>& progress) {
  using Clock = std::chrono::steady_clock;
  auto seconds = [](Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double>(b - a).count();
  };
  auto report = [&](SynthProgress::Stage stage, int done, int total) {
    if (!progress) return;
    SynthProgress p;
    p.stage = stage;
    p.done = done;
    p.total = total;
    progress(p);
  };
  const Clock::time_point start = Clock::now();
  SynthSummary summary;
  std::string why;
  if (!options.IsValid(&why)) throw Error("synthesis options: " + why);
  if (s.poses.empty()) throw Error("SynthesizeSequence: the prepared subject has no poses");
  VirtualKinectOptions kinect_options = options.kinect;
  kinect_options.frame_rate = options.motion.frame_rate;
  const VirtualKinect kinect(kinect_options, s.subject, s.texture_bgr);
  const Skinning skinning(s.subject);
  const int frames = static_cast<int>(s.poses.size());
  const std::vector<ColorConditions> conditions =
      GenerateColorConditions(kinect_options.color_model, kinect_options.seed, frames);
  SequenceWriter writer(out_folder, kinect.calibration());
  summary.setup_seconds = seconds(start, Clock::now());
  report(SynthProgress::Stage::kSetup, 1, 1);

  for (int b = 0; b < options.background_frames; ++b) {
    const Clock::time_point t0 = Clock::now();
    const cv::Mat depth = kinect.RenderBackgroundDepth(b);
    const Clock::time_point t1 = Clock::now();
    writer.AddBackgroundFrame(depth);
    summary.render_seconds += seconds(t0, t1);
    summary.write_seconds += seconds(t1, Clock::now());
    report(SynthProgress::Stage::kBackground, b + 1, options.background_frames);
  }
  summary.background_frames = options.background_frames;

  // Rendering frame f + 1 overlaps writing frame f (two serial, in-order stages: the files
  // are the same as a sequential loop's).
  struct Item {
    int index = 0;
    Frame frame;
    GroundTruthFrame truth;
  };
  const Clock::time_point frames_start = Clock::now();
  int next = 0;
  tbb::parallel_pipeline(
      /*max_number_of_live_tokens=*/2,
      tbb::make_filter<void, std::shared_ptr<Item>>(
          tbb::filter_mode::serial_in_order,
          [&](tbb::flow_control& control) -> std::shared_ptr<Item> {
            if (next >= frames) {
              control.stop();
              return nullptr;
            }
            const Clock::time_point t0 = Clock::now();
            auto item = std::make_shared<Item>();
            item->index = next++;
            item->truth.pose = s.poses[item->index];
            skinning.Apply(item->truth.pose, &item->truth.vertices);
            kinect.RenderFrame(item->index, &item->truth.vertices, conditions[item->index],
                               &item->frame);
            summary.render_seconds += seconds(t0, Clock::now());
            return item;
          }) &
          tbb::make_filter<std::shared_ptr<Item>, void>(
              tbb::filter_mode::serial_in_order, [&](const std::shared_ptr<Item>& item) {
                const Clock::time_point t0 = Clock::now();
                writer.AddFrame(item->frame);
                writer.AddGroundTruth(item->index, item->truth);
                summary.write_seconds += seconds(t0, Clock::now());
                report(SynthProgress::Stage::kFrames, item->index + 1, frames);
              }));
  summary.frames_seconds = seconds(frames_start, Clock::now());
  summary.frames = frames;

  report(SynthProgress::Stage::kFinish, 0, 1);
  const Clock::time_point t0 = Clock::now();
  writer.SetGroundTruthTexture(s.texture_bgr);
  if (options.write_subject_glb) {
    GlbTexture texture;
    texture.width = s.texture_bgr.cols;
    texture.height = s.texture_bgr.rows;
    texture.rgb.resize(static_cast<size_t>(texture.width) * texture.height * 3);
    for (int y = 0; y < texture.height; ++y) {
      const auto* row = s.texture_bgr.ptr<cv::Vec3b>(y);
      for (int x = 0; x < texture.width; ++x) {
        for (int c = 0; c < 3; ++c) {
          texture.rgb[(static_cast<size_t>(y) * texture.width + x) * 3 + c] = row[x][2 - c];
        }
      }
    }
    WriteTemplateGlb(writer.subject_path(), s.subject, &texture);
  }
  writer.Finish();
  summary.write_seconds += seconds(t0, Clock::now());
  summary.total_seconds = seconds(start, Clock::now());
  report(SynthProgress::Stage::kFinish, 1, 1);
  return summary;
}

}  // namespace artex
