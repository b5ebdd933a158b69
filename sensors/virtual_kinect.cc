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
#include "models/numeric.h"
#include "models/skinning.h"
#include "models/template_io.h"
#include "render/rasterizer.h"
#include "sensors/option_text.h"
#include "sensors/synth_random.h"

namespace artex {
namespace {

using synth_random::kStreamBackgroundDepth;
using synth_random::kStreamColor;
using synth_random::kStreamColorWalk;
using synth_random::kStreamFrameDepth;
using synth_random::MixSeed;

using option_text::Fail;
using option_text::Str;

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
  const Eigen::Vector3d view = (depth_target - depth_eye).normalized();
  if (std::abs(view.y()) > 0.9999)
    return Fail(error,
                "depth_eye -> depth_target: expected a view direction not parallel to the "
                "world up +Y (look-at), found (" +
                    Str(view.x()) + ", " + Str(view.y()) + ", " + Str(view.z()) + ")");
  if (!(std::abs(depth_pitch_deg) < 90))
    return Fail(error, "depth_pitch_deg (--camera-pitch) must be in (-90, 90), found " +
                           Str(depth_pitch_deg));
  if (!(std::abs(depth_roll_deg) <= 180))
    return Fail(error, "depth_roll_deg (--camera-roll) must be in [-180, 180], found " +
                           Str(depth_roll_deg));
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
                             const cv::Mat& subject_texture_bgr,
                             const std::vector<ScenePerson>& others)
    : options_(options), subject_(subject), texture_(subject_texture_bgr), others_(others) {
  std::string why;
  if (!options.IsValid(&why)) throw Error("virtual Kinect options: " + why);
  for (int p = 0; p <= num_others(); ++p) {
    const std::string what =
        p == 0 ? std::string("virtual Kinect subject") : "virtual Kinect person " + Str(p - 1);
    const Template& body = PersonBody(p);
    const cv::Mat& texture = PersonTexture(p);
    if (!body.IsValid(&why)) throw Error(what + ": " + why);
    if (!body.has_uvs()) throw Error(what + ": the template has no UV atlas");
    if (texture.empty() || texture.type() != CV_8UC3) {
      throw Error(what + " texture: expected a non-empty CV_8UC3 image, found type " +
                  Str(texture.type()));
    }
  }
  person_offset_.assign(1, 0);
  for (int p = 0; p <= num_others(); ++p) {
    person_offset_.push_back(person_offset_.back() + PersonBody(p).num_triangles());
  }
  // Depth camera: look-at, then pitch about its x and roll about its z axis.
  calibration_.depth = options.depth_intrinsics;
  Eigen::Isometry3d tilt = Eigen::Isometry3d::Identity();
  tilt.linear() =
      (Eigen::AngleAxisd(-options.depth_roll_deg * kDegToRad, Eigen::Vector3d::UnitZ()) *
       Eigen::AngleAxisd(options.depth_pitch_deg * kDegToRad, Eigen::Vector3d::UnitX()))
          .toRotationMatrix();
  calibration_.depth.world_to_camera =
      tilt *
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
  scene_ = BuildSceneMesh(options.scene);

  // Scene-only buffers of the three views, and the scene's shaded albedo in the colour view.
  RasterOptions raster_options;
  raster_options.near_plane = options.near_plane_m;
  Rasterize(scene_.vertices, scene_.triangles, calibration_.depth, raster_options, &depth_scene_);
  if (options.depth_noise.projector_shadow) {
    Rasterize(scene_.vertices, scene_.triangles, projector_, raster_options, &projector_scene_);
  }
  Rasterize(scene_.vertices, scene_.triangles, calibration_.color, raster_options, &color_scene_);
  ComputeTriangleNormals(scene_.vertices, scene_.triangles, &scene_normals_);
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
        (1 - b1 - b2) * scene_.vertices.row(scene_.triangles(f, 0)).transpose() +
        b1 * scene_.vertices.row(scene_.triangles(f, 1)).transpose() +
        b2 * scene_.vertices.row(scene_.triangles(f, 2)).transpose();
    const double shade =
        c.ambient + (1 - c.ambient) * std::max(0.0, scene_normals_.row(f).dot(light));
    color_scene_radiance_[i] =
        (SceneAlbedo(options.scene, options.seed, scene_.part[f], p) * shade).cast<float>();
  });
}

VirtualKinect::PosedPeople VirtualKinect::People(
    const Eigen::MatrixX3d* subject, const std::vector<Eigen::MatrixX3d>& others) const {
  if (!others.empty() && static_cast<int>(others.size()) != num_others()) {
    throw Error("VirtualKinect: others_posed: expected " + Str(num_others()) +
                " posed people (or none), found " + Str(others.size()));
  }
  PosedPeople people(1 + num_others(), nullptr);
  people[0] = subject;
  for (size_t k = 0; k < others.size(); ++k) people[k + 1] = &others[k];
  for (int p = 0; p < static_cast<int>(people.size()); ++p) {
    if (people[p] && people[p]->rows() != PersonBody(p).num_vertices()) {
      throw Error("VirtualKinect: posed vertices of " +
                  (p == 0 ? std::string("the subject") : "person " + Str(p - 1)) + ": expected " +
                  Str(PersonBody(p).num_vertices()) + " rows, found " + Str(people[p]->rows()));
    }
  }
  return people;
}

int VirtualKinect::PersonOfTriangle(int id) const {
  for (int p = 0; p + 1 < static_cast<int>(person_offset_.size()); ++p) {
    if (id < person_offset_[p + 1]) return p;
  }
  return -1;
}

void VirtualKinect::RenderView(const PinholeCamera& camera, const RasterBuffers& scene,
                               const PosedPeople& people, RasterBuffers* out) const {
  RasterOptions raster_options;
  raster_options.near_plane = options_.near_plane_m;
  bool first = true;
  RasterBuffers person;
  for (int p = 0; p < static_cast<int>(people.size()); ++p) {
    if (!people[p]) continue;
    const int32_t offset = person_offset_[p];
    RasterBuffers* target = first ? out : &person;
    Rasterize(*people[p], PersonBody(p).triangles, camera, raster_options, target);
    if (first) {
      if (offset != 0) {
        for (int32_t& id : out->triangle_id) id = id >= 0 ? id + offset : -1;
      }
      first = false;
      continue;
    }
    // Earlier people win ties.
    tbb::parallel_for(size_t{0}, person.depth.size(), [&](size_t i) {
      if (person.triangle_id[i] < 0) return;
      if (out->triangle_id[i] >= 0 && out->depth[i] <= person.depth[i]) return;
      out->depth[i] = person.depth[i];
      out->triangle_id[i] = person.triangle_id[i] + offset;
      out->barycentric[i] = person.barycentric[i];
    });
  }
  if (first) {
    out->width = scene.width;
    out->height = scene.height;
    out->depth.assign(scene.depth.size(), std::numeric_limits<float>::infinity());
    out->triangle_id.assign(scene.depth.size(), -1);
    out->barycentric.resize(scene.depth.size());
  }
  // People win ties, as when rasterising their triangles before the scene's.
  const int32_t scene_offset = person_offset_.back();
  tbb::parallel_for(size_t{0}, scene.depth.size(), [&](size_t i) {
    if (out->triangle_id[i] >= 0 && out->depth[i] <= scene.depth[i]) return;
    out->depth[i] = scene.depth[i];
    out->triangle_id[i] = scene.triangle_id[i] >= 0 ? scene.triangle_id[i] + scene_offset : -1;
    out->barycentric[i] = scene.barycentric[i];
  });
}

cv::Mat VirtualKinect::RenderDepth(int frame_index, const Eigen::MatrixX3d* posed,
                                   DepthDiagnostics* diagnostics) const {
  return RenderDepthStream(frame_index, People(posed, {}), kStreamFrameDepth, diagnostics);
}

cv::Mat VirtualKinect::RenderDepth(int frame_index, const Eigen::MatrixX3d* posed,
                                   const std::vector<Eigen::MatrixX3d>& others_posed,
                                   DepthDiagnostics* diagnostics) const {
  return RenderDepthStream(frame_index, People(posed, others_posed), kStreamFrameDepth,
                           diagnostics);
}

cv::Mat VirtualKinect::RenderBackgroundDepth(int index, DepthDiagnostics* diagnostics) const {
  return RenderDepthStream(index, People(nullptr, {}), kStreamBackgroundDepth, diagnostics);
}

cv::Mat VirtualKinect::RenderDepthStream(int frame_index, const PosedPeople& people,
                                         uint64_t stream, DepthDiagnostics* diagnostics) const {
  const DepthNoiseOptions& o = options_.depth_noise;
  const PinholeCamera& cam = calibration_.depth;
  const int subject_triangles = subject_.num_triangles();
  const int scene_offset = person_offset_.back();
  RasterBuffers view, light;
  RenderView(cam, depth_scene_, people, &view);
  if (o.projector_shadow) RenderView(projector_, projector_scene_, people, &light);
  std::vector<Eigen::MatrixX3d> normals(people.size());
  for (size_t p = 0; p < people.size(); ++p) {
    if (people[p]) ComputeTriangleNormals(*people[p], PersonBody(p).triangles, &normals[p]);
  }

  const int w = cam.width, h = cam.height;
  cv::Mat depth(h, w, CV_16UC1, cv::Scalar(0));
  cv::Mat true_depth, status, mask, surface;
  if (diagnostics) {
    true_depth.create(h, w, CV_32FC1);
    status.create(h, w, CV_8UC1);
    mask.create(h, w, CV_8UC1);
    surface.create(h, w, CV_8UC1);
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
        const int p = PersonOfTriangle(f);
        const Eigen::Vector3d normal = p >= 0
                                           ? Eigen::Vector3d(normals[p].row(f - person_offset_[p]))
                                           : Eigen::Vector3d(scene_normals_.row(f - scene_offset));
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
        SurfaceKind kind = SurfaceKind::kNone;
        if (f >= 0 && f < subject_triangles) {
          kind = SurfaceKind::kSubject;
        } else if (f >= 0 && f < scene_offset) {
          kind = SurfaceKind::kPerson;
        } else if (f >= 0) {
          kind = scene_.part[f - scene_offset] >= static_cast<int>(ScenePart::kBox)
                     ? SurfaceKind::kBox
                     : SurfaceKind::kRoom;
        }
        surface.at<uint8_t>(y, x) = static_cast<uint8_t>(kind);
      }
    }
  });
  if (diagnostics) {
    diagnostics->true_depth = true_depth;
    diagnostics->status = status;
    diagnostics->subject_mask = mask;
    diagnostics->surface = surface;
  }
  return depth;
}

cv::Mat VirtualKinect::RenderColor(int frame_index, const Eigen::MatrixX3d* posed,
                                   const ColorConditions& conditions) const {
  return RenderColorPeople(frame_index, People(posed, {}), conditions);
}

cv::Mat VirtualKinect::RenderColor(int frame_index, const Eigen::MatrixX3d* posed,
                                   const std::vector<Eigen::MatrixX3d>& others_posed,
                                   const ColorConditions& conditions) const {
  return RenderColorPeople(frame_index, People(posed, others_posed), conditions);
}

cv::Mat VirtualKinect::RenderColorPeople(int frame_index, const PosedPeople& people,
                                         const ColorConditions& conditions) const {
  const ColorModelOptions& o = options_.color_model;
  const PinholeCamera& cam = calibration_.color;
  RasterBuffers view;
  RenderView(cam, color_scene_, people, &view);
  std::vector<Eigen::MatrixX3d> vertex_normals(people.size());
  for (size_t p = 0; p < people.size(); ++p) {
    if (people[p]) ComputeVertexNormals(*people[p], PersonBody(p).triangles, &vertex_normals[p]);
  }
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
      const int p = f >= 0 ? PersonOfTriangle(f) : -1;
      if (p >= 0) {
        const Template& body = PersonBody(p);
        const Eigen::MatrixX3d& vn = vertex_normals[p];
        const int t = f - person_offset_[p];
        const double b1 = view.barycentric[i].x(), b2 = view.barycentric[i].y(), b0 = 1 - b1 - b2;
        const Eigen::Vector2d uv = b0 * body.uvs.row(body.uv_triangles(t, 0)).transpose() +
                                   b1 * body.uvs.row(body.uv_triangles(t, 1)).transpose() +
                                   b2 * body.uvs.row(body.uv_triangles(t, 2)).transpose();
        Eigen::Vector3d n = b0 * vn.row(body.triangles(t, 0)).transpose() +
                            b1 * vn.row(body.triangles(t, 1)).transpose() +
                            b2 * vn.row(body.triangles(t, 2)).transpose();
        if (n.norm() > 0) n.normalize();
        const double shade = o.ambient + (1 - o.ambient) * std::max(0.0, n.dot(light));
        rgb = SampleTextureBilinear(PersonTexture(p), uv) * shade;
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

void VirtualKinect::RenderFrame(int frame_index, const Eigen::MatrixX3d* posed,
                                const std::vector<Eigen::MatrixX3d>& others_posed,
                                const ColorConditions& conditions, Frame* frame,
                                DepthDiagnostics* diagnostics) const {
  const PosedPeople people = People(posed, others_posed);
  frame->index = frame_index;
  frame->depth_timestamp = frame_index / options_.frame_rate;
  frame->color_timestamp = frame->depth_timestamp;
  frame->depth = RenderDepthStream(frame_index, people, kStreamFrameDepth, diagnostics);
  frame->color = RenderColorPeople(frame_index, people, conditions);
}

}  // namespace artex
