// The synthetic "virtual Kinect" (docs/design.md "Ground truth"): renders a textured, articulated
// subject in a static scene (floor, back wall, boxes; sensors/virtual_scene.h), optionally
// with a second person, into a Kinect-like depth camera (disparity
// quantisation and noise, drop-outs at depth discontinuities and grazing angles, the IR
// projector's shadow) and a separate colour camera (Lambert shading, per-frame exposure and
// white-balance drift, sensor noise), and writes an artex sequence with ground truth
// (sensors/sequence.h): pose and posed vertices per frame, true texture, subject.glb.
// Everything is deterministic given the seeds (docs/synthesis.md).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "models/template.h"
#include "models/template_generator.h"
#include "render/camera.h"
#include "render/rasterizer.h"
#include "sensors/calibration.h"
#include "sensors/motion.h"
#include "sensors/sequence.h"
#include "sensors/subject_texture.h"
#include "sensors/virtual_scene.h"

namespace artex {

// Noise presets for both cameras ("off" = ideal sensors: exact depth up to the 16-bit unit,
// no drop-outs or shadow, constant exposure, no colour noise).
enum class NoiseLevel { kOff, kDefault, kHigh };
// "off", "default", "high"; throws artex::Error listing the valid names otherwise.
NoiseLevel ParseNoiseLevel(const std::string& name);
const char* NoiseLevelName(NoiseLevel level);

struct DepthNoiseOptions {
  // Disparity model d = b f / z (f = depth camera fx in pixels): quantised to
  // disparity_step_px after adding Gaussian noise of disparity_noise_px, so the depth noise
  // std is z^2 / (b f) * disparity_noise_px (Khoshelham & Elberink 2012).
  double baseline_m = 0.075;         // b: IR camera to projector (m), > 0
  double disparity_step_px = 0.125;  // 1/8 pixel sub-pixel disparity; 0 = no quantisation
  double disparity_noise_px = 0.07;  // Gaussian std in disparity (px); >= 0
  double min_depth_m = 0.4;          // nearer: missing (0)
  double max_depth_m = 6.0;          // farther: missing
  // Depth discontinuities: a pixel whose (2r+1)^2 neighbourhood of true depths spans more
  // than edge_jump_m (or touches a pixel without a surface) is dropped with this probability.
  double edge_jump_m = 0.08;
  int edge_radius_px = 1;
  double edge_drop_probability = 0.6;
  // Grazing angles: angle between the surface normal and the viewing ray above this: missing.
  double grazing_angle_deg = 78.0;
  // IR projector shadow: the projector sits at projector_offset_m in the depth camera frame
  // (x right); a surface point the projector cannot see (depth test against a rendering
  // from the projector, tolerance shadow_tolerance_m) gets no pattern and is missing.
  bool projector_shadow = true;
  Eigen::Vector3d projector_offset_m = Eigen::Vector3d(0.075, 0.0, 0.0);
  double shadow_tolerance_m = 0.01;
  int projector_margin_px = 64;  // the projector's image extends the camera's by this
  double random_dropout = 0.0;   // probability of an isolated missing pixel

  bool IsValid(std::string* error) const;
};

struct ColorModelOptions {
  // Lambert shading of the albedo: albedo * (ambient + (1 - ambient) max(0, n . l)).
  double ambient = 0.5;
  Eigen::Vector3d light_direction = Eigen::Vector3d(0.3, 0.8, 0.6);  // towards the light, world
  double noise_std = 0.01;  // Gaussian per channel (fraction of full scale)
  // Exposure (log gain) and white balance (log gain per channel, zero mean over channels):
  // smooth random walks, velocity v <- walk_smoothing v + (1 - walk_smoothing) N(0, step),
  // value reflected into [-limit, limit].
  double exposure_step = 0.06;
  double exposure_limit = 0.25;
  double white_balance_step = 0.03;
  double white_balance_limit = 0.08;
  double walk_smoothing = 0.8;                                         // [0, 1)
  Eigen::Vector3d background_rgb = Eigen::Vector3d(0.05, 0.05, 0.06);  // rays hitting nothing

  bool IsValid(std::string* error) const;
};

struct VirtualKinectOptions {
  uint64_t seed = 1;  // noise streams and colour drift
  // Depth (IR) camera: intrinsics (width, height, fx, fy, cx, cy; its pose is ignored) placed
  // at depth_eye looking at depth_target, world up +Y, then rotated about its own axes (camera
  // frame x right, y down, z forward): first depth_pitch_deg about x (positive = looking
  // further down), then depth_roll_deg about the optical axis (positive = the camera turns
  // clockwise as seen from behind it, looking along its view, so the scene appears turned
  // anticlockwise in the image). world_to_camera = Rz(-roll) Rx(pitch) LookAt(eye, target).
  // A pitch or roll makes the floor y = 0 non-level in the camera frame.
  PinholeCamera depth_intrinsics;  // 640 x 480, f = 525
  Eigen::Vector3d depth_eye = Eigen::Vector3d(0.3, 1.2, 2.5);
  Eigen::Vector3d depth_target = Eigen::Vector3d(0.0, 1.0, 0.0);
  double depth_pitch_deg = 0.0;  // (-90, 90)
  double depth_roll_deg = 0.0;   // [-180, 180]
  // Colour camera: own resolution (default: half of 1600 x 2032, same aspect), vertical field
  // of view, principal point at the centre; pose = depth camera pose followed by
  // color_offset_m (in the depth camera frame) and a small yaw / pitch (degrees).
  int color_width = 800;
  int color_height = 1016;
  double color_vertical_fov_deg = 55.0;
  Eigen::Vector3d color_offset_m = Eigen::Vector3d(-0.06, 0.0, 0.0);
  double color_yaw_deg = 1.0;
  double color_pitch_deg = -0.5;
  double depth_scale = 1000.0;  // 16-bit depth units per metre
  double frame_rate = 30.0;     // Hz
  double near_plane_m = 0.05;

  SceneOptions scene;
  DepthNoiseOptions depth_noise;
  ColorModelOptions color_model;

  // Sets depth_noise and color_model to a preset (keeps cameras, scene and seed).
  void SetNoiseLevel(NoiseLevel level);
  bool IsValid(std::string* error) const;
};

// Exposure and white balance of one colour frame: colour = albedo * shading * gain.
struct ColorConditions {
  Eigen::Vector3d gain = Eigen::Vector3d::Ones();  // per channel (RGB), exp(exposure + wb)
};
// The conditions of frames 0 .. frames-1 (deterministic given options and seed; frame 0 is
// neutral).
std::vector<ColorConditions> GenerateColorConditions(const ColorModelOptions& options,
                                                     uint64_t seed, int frames);

// Why a depth pixel is 0.
enum class DepthStatus : uint8_t {
  kValid = 0,
  kNoSurface = 1,
  kOutOfRange = 2,
  kGrazing = 3,
  kShadow = 4,
  kEdge = 5,
  kDropout = 6,
};

// What the visible surface of a pixel belongs to.
enum class SurfaceKind : uint8_t {
  kNone = 0,
  kSubject = 1,  // the ground-truth subject
  kPerson = 2,   // another person (not in the ground truth)
  kRoom = 3,     // floor or back wall
  kBox = 4,      // a scene box
};

// Per-pixel internals of one depth rendering, for tests, previews and evaluation.
struct DepthDiagnostics {
  cv::Mat true_depth;    // CV_32FC1, exact camera depth (m) of the visible surface, 0 = none
  cv::Mat status;        // CV_8UC1, DepthStatus
  cv::Mat subject_mask;  // CV_8UC1, 255 where the visible surface is the subject
  cv::Mat surface;       // CV_8UC1, SurfaceKind
};

// A textured body rendered besides the subject (e.g. a second person); not ground truth.
struct ScenePerson {
  Template body;        // with UVs
  cv::Mat texture_bgr;  // CV_8UC3 atlas over body's UVs
};

class VirtualKinect {
 public:
  // subject: the template being rendered (must have UVs); texture: its CV_8UC3 BGR atlas;
  // others: further people that may appear in frames (see the `others_posed` overloads).
  // Throws artex::Error for invalid options, a template without UVs or a bad texture.
  VirtualKinect(const VirtualKinectOptions& options, const Template& subject,
                const cv::Mat& subject_texture_bgr, const std::vector<ScenePerson>& others = {});

  const Calibration& calibration() const { return calibration_; }
  const VirtualKinectOptions& options() const { return options_; }

  // Renders frame `frame_index` (selects the noise streams) with the subject posed at
  // `posed_vertices` (V x 3 world; nullptr: empty scene). frame->depth CV_16UC1 (0 = missing),
  // frame->color CV_8UC3 BGR; timestamps frame_index / frame_rate.
  void RenderFrame(int frame_index, const Eigen::MatrixX3d* posed_vertices,
                   const ColorConditions& conditions, Frame* frame,
                   DepthDiagnostics* diagnostics = nullptr) const;
  // Depth image only (CV_16UC1), the same as RenderFrame's.
  cv::Mat RenderDepth(int frame_index, const Eigen::MatrixX3d* posed_vertices,
                      DepthDiagnostics* diagnostics = nullptr) const;
  // Empty-scene depth frame `index` for the background model (its own noise stream).
  cv::Mat RenderBackgroundDepth(int index, DepthDiagnostics* diagnostics = nullptr) const;
  cv::Mat RenderColor(int frame_index, const Eigen::MatrixX3d* posed_vertices,
                      const ColorConditions& conditions) const;
  // The same with the other people of the constructor posed at others_posed (one V_k x 3
  // world matrix per person, in constructor order; an empty vector: none in this frame).
  // Throws artex::Error for a wrong number of people or vertices.
  void RenderFrame(int frame_index, const Eigen::MatrixX3d* posed_vertices,
                   const std::vector<Eigen::MatrixX3d>& others_posed,
                   const ColorConditions& conditions, Frame* frame,
                   DepthDiagnostics* diagnostics = nullptr) const;
  cv::Mat RenderDepth(int frame_index, const Eigen::MatrixX3d* posed_vertices,
                      const std::vector<Eigen::MatrixX3d>& others_posed,
                      DepthDiagnostics* diagnostics = nullptr) const;
  cv::Mat RenderColor(int frame_index, const Eigen::MatrixX3d* posed_vertices,
                      const std::vector<Eigen::MatrixX3d>& others_posed,
                      const ColorConditions& conditions) const;

  // The scene's static geometry (floor, wall, boxes), world frame.
  const Eigen::MatrixX3d& scene_vertices() const { return scene_.vertices; }
  const Eigen::MatrixX3i& scene_triangles() const { return scene_.triangles; }
  int num_others() const { return static_cast<int>(others_.size()); }

 private:
  // Posed people of one frame: [0] the subject, [1 + k] other person k; nullptr = absent.
  using PosedPeople = std::vector<const Eigen::MatrixX3d*>;
  PosedPeople People(const Eigen::MatrixX3d* subject,
                     const std::vector<Eigen::MatrixX3d>& others) const;
  const Template& PersonBody(int p) const { return p == 0 ? subject_ : others_[p - 1].body; }
  const cv::Mat& PersonTexture(int p) const {
    return p == 0 ? texture_ : others_[p - 1].texture_bgr;
  }
  int PersonOfTriangle(int id) const;  // -1: a scene triangle
  cv::Mat RenderDepthStream(int frame_index, const PosedPeople& people, uint64_t stream,
                            DepthDiagnostics* diagnostics) const;
  cv::Mat RenderColorPeople(int frame_index, const PosedPeople& people,
                            const ColorConditions& conditions) const;
  // People and scene seen by `camera`: each present person is rasterised and z-composited
  // (earlier people win ties), then over the cached scene-only buffers (equal to rasterising
  // everything together). Person p's triangle t has id person_offset_[p] + t; scene triangle
  // s has id person_offset_.back() + s.
  void RenderView(const PinholeCamera& camera, const RasterBuffers& scene,
                  const PosedPeople& people, RasterBuffers* out) const;

  VirtualKinectOptions options_;
  Template subject_;
  cv::Mat texture_;
  std::vector<ScenePerson> others_;
  std::vector<int> person_offset_;  // 1 + others: first triangle id of each person, then the
                                    // scene's
  Calibration calibration_;
  PinholeCamera projector_;
  SceneMesh scene_;
  Eigen::MatrixX3d scene_normals_;  // per scene triangle
  // The static scene is rendered once per camera.
  RasterBuffers depth_scene_, projector_scene_, color_scene_;
  std::vector<Eigen::Vector3f> color_scene_radiance_;  // albedo * shading per colour pixel
};

// Default subject body: different from the default tracking template (BodyShapeOptions()).
BodyShapeOptions DefaultSubjectShape();

// The frame of calibration.yaml and of all ground truth written by SynthesizeSequence.
// kScene: the synthetic world (Y up, floor y = 0). kDepthCamera: the depth camera's frame
// (x right, y down, z forward): calibration.yaml has depth world_to_camera = identity and
// colour world_to_camera = the depth -> colour extrinsic, and poses (global rotation and
// translation) and vertices are expressed in that frame, as in a single-camera recording.
enum class WorldFrame { kScene, kDepthCamera };
// "scene", "camera"; throws artex::Error listing the valid names otherwise.
WorldFrame ParseWorldFrame(const std::string& name);
const char* WorldFrameName(WorldFrame frame);

struct SynthOptions {
  // Its frame_rate is replaced by motion.frame_rate; camera_placement and random_boxes are
  // applied to it (ResolveKinectOptions).
  VirtualKinectOptions kinect;
  BodyShapeOptions subject_shape = DefaultSubjectShape();
  // Non-empty: the subject is this template file (.glb, e.g. from `artex template
  // import-makehuman`) instead of the body generated from subject_shape (which is then not
  // used; kUpperBody's framing still reads subject_shape.height). The file must hold a valid
  // template with a UV atlas and the 17 joint names of DefaultJointNames() (the motions and
  // the BVH retargeting drive them); its texture, if any, is ignored: the true texture is
  // generated over its UVs from `texture` as for the generated body (LoadSubjectTemplate).
  std::string subject_template;
  SubjectTextureOptions texture;
  MotionOptions motion;
  // Non-empty: the motion is read from this BVH file and retargeted (sensors/bvh.h);
  // motion.frames then limits the number of frames (0 = all) and motion.type is ignored.
  std::string bvh_path;
  // World placement of the motion: poses are rotated by subject_yaw_deg about +Y and then
  // shifted by subject_position_m (the ground-truth poses include this transform). The
  // template faces +Z: yaw 180 turns its front away from the default camera, 90 shows the
  // camera its right side.
  Eigen::Vector3d subject_position_m = Eigen::Vector3d::Zero();
  double subject_yaw_deg = 0.0;
  // Empty-scene depth frames for the background model (static scene incl. boxes, no
  // people); 0 = none: the sequence then has no background/ folder and no background.csv.
  int background_frames = 10;
  bool write_subject_glb = true;  // groundtruth/subject.glb (textured)
  // Set: kinect.depth_eye / depth_target are replaced by this placement relative to
  // subject_position_m (pitch and roll stay kinect.depth_pitch_deg / depth_roll_deg).
  std::optional<CameraPlacement> camera_placement;
  WorldFrame world_frame = WorldFrame::kScene;
  // Boxes generated from kinect.seed (GenerateSceneBoxes around subject_position_m, layout
  // box_layout) and added to kinect.scene.boxes; [0, 32].
  int random_boxes = 0;
  BoxLayoutOptions box_layout;
  SecondPersonOptions second_person;  // disabled by default

  bool IsValid(std::string* error) const;
};

// options.kinect with the frame rate, camera placement and random boxes of `options` applied:
// the virtual Kinect SynthesizeSequence renders with. Throws artex::Error on invalid options.
VirtualKinectOptions ResolveKinectOptions(const SynthOptions& options);

struct SynthProgress {
  enum class Stage { kSetup, kBackground, kFrames, kFinish } stage = Stage::kSetup;
  int done = 0;
  int total = 0;
};

struct SynthSummary {
  int frames = 0;
  int background_frames = 0;
  double setup_seconds = 0;   // subject, texture, motion
  double render_seconds = 0;  // rendering, summed over all frames incl. background
  double write_seconds = 0;   // encoding and writing files, summed (overlaps rendering)
  double frames_seconds = 0;  // wall time of the (pipelined) frame loop
  double total_seconds = 0;
  double ms_per_frame() const { return frames ? 1000.0 * frames_seconds / frames : 0; }
};

// The subject, its texture and the posed frames of a synthesis, without rendering or files.
struct SynthSubject {
  Template subject;
  cv::Mat texture_bgr;
  std::vector<Pose> poses;  // world poses (placement applied), scene frame
  // Other people (second_person), each with one scene-frame pose per frame of `poses`.
  std::vector<ScenePerson> others;
  std::vector<std::vector<Pose>> other_poses;
};
// Reads a subject template file for SynthOptions::subject_template. Throws artex::Error naming
// `path` and what is wrong: unreadable or not an artex template GLB, no UV atlas, or missing
// joint names of DefaultJointNames() (listed).
Template LoadSubjectTemplate(const std::string& path);

// Throws artex::Error on invalid options, an unknown/unreadable BVH file or subject template
// file, or a failing generator.
SynthSubject PrepareSynthSubject(const SynthOptions& options);

// Writes a complete artex sequence to out_folder (created if missing). Throws artex::Error on
// invalid options or I/O failure; files are written atomically and frames.csv last, so an
// interrupted run leaves no readable sequence.
SynthSummary SynthesizeSequence(const SynthOptions& options, const std::string& out_folder,
                                const std::function<void(const SynthProgress&)>& progress = {});
// As above with a prepared subject (PrepareSynthSubject(options), e.g. reused across noise
// settings); options.subject_shape, texture, motion, placement and second_person are then
// not consulted (the subject's `others` are rendered).
SynthSummary SynthesizeSequence(const SynthOptions& options, const SynthSubject& subject,
                                const std::string& out_folder,
                                const std::function<void(const SynthProgress&)>& progress = {});

}  // namespace artex
