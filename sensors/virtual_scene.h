// The virtual Kinect's world (sensors/virtual_kinect.h): the static room (floor y = 0, back
// wall, furniture-like boxes), the depth camera's placement relative to the subject, and a
// second person walking through the scene. World frame: metres, Y up, the subject starts at
// subject_position_m facing +Z (docs/synthesis.md "Conditions").
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "models/template_generator.h"
#include "sensors/motion.h"
#include "sensors/subject_texture.h"

namespace artex {

// A furniture-like box standing on the floor: footprint centre (x, z), size (width along its
// own x, height, depth along its own z) rotated by yaw_deg about +Y (right-handed: +X turns
// towards -Z), uniform albedo `rgb` in [0, 1] with darker plank joints.
struct SceneBox {
  Eigen::Vector2d center_xz = Eigen::Vector2d::Zero();
  Eigen::Vector3d size_m = Eigen::Vector3d(0.6, 0.8, 0.5);  // each > 0
  double yaw_deg = 0.0;
  Eigen::Vector3d rgb = Eigen::Vector3d(0.55, 0.45, 0.35);

  bool IsValid(std::string* error) const;
};

// The static scene: floor y = 0 and a back wall z = wall_z behind the subject, both
// procedurally textured (floor planks, patterned wall), plus `boxes`, tessellated into cells
// (the rasteriser rejects triangles crossing the near plane).
struct SceneOptions {
  bool floor = true;
  bool back_wall = true;
  double wall_z_m = -1.5;     // back wall plane (m); the subject stands near z = 0
  double half_width_m = 3.5;  // both planes span x in [-w, w]
  double wall_height_m = 3.0;
  double floor_front_z_m = 3.5;  // the floor reaches from the wall to this z
  double cell_m = 0.25;          // tessellation cell size
  double pattern_m = 0.3;        // size of the floor planks / wall pattern
  std::vector<SceneBox> boxes;   // none by default (see GenerateSceneBoxes)

  bool IsValid(std::string* error) const;
};

// Where GenerateSceneBoxes puts boxes: beside and behind the point `clear_center` (the
// subject's start), never within clear_radius_m of it (footprint circle), with footprint
// centres at |x - c.x| <= max_side_m and z in [c.z - max_behind_m, c.z + max_front_m]
// (clamped to stay clear of the back wall), sizes and yaw uniform in the ranges below.
struct BoxLayoutOptions {
  double clear_radius_m = 0.75;
  double max_side_m = 1.9;
  double max_behind_m = 1.0;
  double max_front_m = 0.4;
  double min_width_m = 0.4, max_width_m = 0.8;    // footprint width (own x)
  double min_depth_m = 0.3, max_depth_m = 0.6;    // footprint depth (own z)
  double min_height_m = 0.4, max_height_m = 1.1;  // height
  double max_yaw_deg = 30.0;                      // yaw uniform in [-max, max]

  bool IsValid(std::string* error) const;
};

// `count` boxes (alternately left and right of clear_center, footprints not overlapping
// each other when possible), deterministic given the seed. Throws artex::Error for invalid
// options or count outside [0, 32].
std::vector<SceneBox> GenerateSceneBoxes(const SceneOptions& scene, const BoxLayoutOptions& layout,
                                         int count, uint64_t seed,
                                         const Eigen::Vector3d& clear_center);

// Triangulated static scene in the world frame; part[f] tells what triangle f belongs to.
enum class ScenePart : int { kFloor = 0, kWall = 1, kBox = 2 };  // kBox + k: box k
struct SceneMesh {
  Eigen::MatrixX3d vertices;   // V x 3
  Eigen::MatrixX3i triangles;  // F x 3, counter-clockwise seen from outside (normals outward)
  std::vector<int> part;       // F: ScenePart (kBox + k for box k)
};
SceneMesh BuildSceneMesh(const SceneOptions& scene);
// Procedural albedo (linear RGB in [0, 1]) of a scene point on triangle part `part`.
Eigen::Vector3d SceneAlbedo(const SceneOptions& scene, uint64_t seed, int part,
                            const Eigen::Vector3d& point);

// Depth camera placement relative to the subject's start position p (its floor point
// (p.x, 0, p.z)): the eye at height_m above the floor y = 0, distance_m horizontally from p
// in the direction azimuth_deg about +Y (0 = +Z, in front of a subject with yaw 0; 90 = +X),
// looking at (p.x, target_height_m, p.z). The defaults reproduce the default depth_eye
// (0.3, 1.2, 2.5) and depth_target (0, 1, 0) for p = 0. Pitch and roll on top of this
// look-at are VirtualKinectOptions::depth_pitch_deg / depth_roll_deg.
struct CameraPlacement {
  double height_m = 1.2;         // > 0
  double distance_m = 2.51794;   // > 0.05
  double azimuth_deg = 6.84277;  // finite
  double target_height_m = 1.0;  // finite
  bool IsValid(std::string* error) const;
  Eigen::Vector3d Eye(const Eigen::Vector3d& subject_position) const;
  Eigen::Vector3d Target(const Eigen::Vector3d& subject_position) const;
};
// Upper-body framing for a subject of stature `stature_m`: the eye at 0.88 stature (chin
// height), 1.0 m in front, looking horizontally, so the image borders of both cameras cut the
// body above the hips (about 0.53 stature) and keep the head.
CameraPlacement UpperBodyCameraPlacement(double stature_m);

// Default body of the second person: shorter, slimmer shoulders, wider hips than the subject.
BodyShapeOptions DefaultSecondPersonShape();

// A second person, rendered into depth and colour but not part of the ground truth. It
// starts behind_m further from the depth camera than the subject's start (along the
// camera's horizontal viewing direction f) and start_across_m along the camera's
// horizontal right axis r = f x Y, walks along r at speed_m_s (negative: towards -r) facing
// its direction of travel (speed 0: stands facing the camera) while performing `motion`
// (frames and frame_rate are taken from the subject's sequence).
struct SecondPersonOptions {
  bool enabled = false;
  BodyShapeOptions shape = DefaultSecondPersonShape();
  SubjectTextureOptions texture = [] {
    SubjectTextureOptions t;
    t.seed = 2;  // its own texture; `artex synth` uses --seed + 1
    return t;
  }();
  MotionOptions motion;  // default: walk
  double behind_m = 1.2;
  double start_across_m = -1.6;
  double speed_m_s = 0.8;  // |speed| <= 5

  bool IsValid(std::string* error) const;
};

}  // namespace artex
