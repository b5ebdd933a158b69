// BVH motion capture: parsing (HIERARCHY + MOTION), forward kinematics, resampling to a
// frame rate (SLERP of local rotations) and retargeting onto a template's joints so that
// the template's bone directions follow the BVH bones in world space (docs/motions.md).
// BVH conventions used: rotation channels in degrees, applied in the listed order as
// R = R_c1 R_c2 R_c3 (intrinsic); global = global_parent * [offset, R_local]; position
// channels replace the matching OFFSET component (root: absolute position).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <istream>
#include <string>
#include <utility>
#include <vector>

#include "models/pose.h"
#include "models/template.h"
#include "sensors/motion.h"

namespace artex {

enum class BvhChannel { kXposition, kYposition, kZposition, kXrotation, kYrotation, kZrotation };

struct BvhJoint {
  std::string name;                                  // End Sites are named "<parent name>/End Site"
  int parent = -1;                                   // -1 for the root only
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();  // rest translation in the parent frame
  std::vector<BvhChannel> channels;                  // in file order; empty for End Sites
  int first_channel = 0;                             // column of channels[0] in BvhClip::values
  bool end_site = false;
};

struct BvhClip {
  std::string source;            // file name (or description) used in error messages
  std::vector<BvhJoint> joints;  // parents precede children; joints[0] is the root
  int num_channels = 0;          // sum of channel counts = columns of `values`
  double frame_time = 0.0;       // seconds per frame, > 0
  Eigen::MatrixXd values;        // frames x num_channels, as in the file (BVH units, degrees)

  int num_frames() const { return static_cast<int>(values.rows()); }
  double duration() const { return num_frames() > 0 ? (num_frames() - 1) * frame_time : 0.0; }
  int FindJoint(const std::string& name) const;  // exact name; -1 when absent
  std::vector<int> Children(int joint) const;    // direct children, End Sites included
};

// Plausibility caps (docs/reliability.md): Frame Time in [kBvhMinFrameTime, kBvhMaxFrameTime]
// seconds (100 kHz to 1 Hz); "Frames:" at most the lines that follow; a resampled clip at most
// kBvhMaxResampledFrames frames (about 9 hours at 30 Hz).
constexpr double kBvhMinFrameTime = 1e-5;
constexpr double kBvhMaxFrameTime = 1.0;
constexpr double kBvhMaxResampledFrames = 1e6;

// Parses BVH text. Throws artex::Error "<source>:<line>: <problem>" on malformed input:
// unknown keyword or channel, bad or missing number, unbalanced braces, truncated file,
// wrong number of values in a frame line, fewer/more frame lines than "Frames:".
BvhClip ParseBvh(std::istream& in, const std::string& source);
// Reads and parses a file; throws artex::Error when it cannot be opened.
BvhClip ReadBvh(const std::string& path);

// Local transform of every joint at one instant (index = BvhClip::joints).
struct BvhFrame {
  std::vector<Eigen::Quaterniond> rotations;  // local rotation (parent frame)
  std::vector<Eigen::Vector3d> translations;  // local translation (offset / position channels)
};

BvhFrame BvhRestFrame(const BvhClip& clip);           // identity rotations, OFFSETs
BvhFrame BvhFrameAt(const BvhClip& clip, int frame);  // frame in [0, num_frames)
// Time t (s) clamped to [0, duration]: SLERP of local rotations and linear interpolation of
// translations between the two neighbouring frames.
BvhFrame SampleBvh(const BvhClip& clip, double time_s);
// Number of frames at `frame_rate` covering the clip: floor(duration * rate + tolerance) + 1,
// tolerance in output frames (absorbs rounded Frame Time values such as 0.0333333).
int ResampledFrameCount(const BvhClip& clip, double frame_rate, double tolerance = 1e-3);
// Number n of leading frames such that for every f < n some joint's local rotation turns
// faster than max_deg_per_s from frame f to f + 1 (a reference pose or a jump at the start);
// at most num_frames - 1.
int CountLeadingJumpFrames(const BvhClip& clip, double max_deg_per_s);
// Frames at times k / frame_rate, k = 0 .. ResampledFrameCount - 1.
std::vector<BvhFrame> ResampleBvh(const BvhClip& clip, double frame_rate, double tolerance = 1e-3);

// Global rotation (J matrices) and position (J x 3, BVH units) of every joint.
void BvhForwardKinematics(const BvhClip& clip, const BvhFrame& frame,
                          std::vector<Eigen::Matrix3d>* rotations, Eigen::MatrixX3d* positions);

struct BvhRetargetOptions {
  double frame_rate = 30.0;  // output rate (Hz), > 0
  // Leading frames dropped before resampling: >= 0 (< frame count), or -1 = automatic,
  // CountLeadingJumpFrames(clip, leading_jump_deg_per_s). The CMU clips converted for
  // MakeHuman start with a reference pose (and some with a fast blend out of it) that is not
  // part of the motion; a real motion starting faster than the threshold would lose frames.
  int skip_frames = -1;
  double leading_jump_deg_per_s = 1500.0;  // > 0
  double resample_tolerance = 1e-3;        // see ResampledFrameCount
  // Metres per BVH unit for the root translation; 0 = automatic: the template's pelvis
  // height above its lowest vertex divided by the BVH rest root height above its lowest
  // joint / End Site.
  double translation_scale = 0.0;
  // Rotation from BVH axes to template axes (both Y up, facing +Z, left = +X for CMU files).
  Eigen::Matrix3d bvh_to_template = Eigen::Matrix3d::Identity();
  // Shift x and z so that frame 0's pelvis is above the template's rest pelvis.
  bool center_first_frame = true;
  // Vertical placement after scaling (see FloorMode): the clip's lowest foot contact on y = 0.
  FloorMode floor = FloorMode::kClipMinimum;
  // Explicit (template joint name, BVH joint name) pairs taking precedence over the built-in
  // name tables; an empty BVH name leaves the template joint unmapped. A BVH name that does
  // not exist throws artex::Error.
  std::vector<std::pair<std::string, std::string>> joint_map;

  bool IsValid(std::string* error) const;
};

// For each template joint, the index of the BVH joint that drives it, or -1 (unmapped: it
// keeps its rest rotation relative to its parent). The root is always mapped (to the BVH
// root if no name matches). Built-in names cover the CMU skeletons (Hips/LowerBack/Spine1/
// LeftArm..., hip/abdomen/chest/lShldr..., Hips/Chest/CS_BVH/LeftShoulder...); names are
// compared case-insensitively after dropping any "prefix:" namespace. A mapped joint is
// always a BVH descendant of its nearest mapped template ancestor's BVH joint.
std::vector<int> MapBvhJoints(const BvhClip& clip, const Template& tmpl,
                              const BvhRetargetOptions& options = BvhRetargetOptions());

// Retargets a resampled BVH frame set onto the template (one Pose per output frame):
// world rotation of a mapped segment Q_k = C_k * G_k * A_k, with G_k the BVH joint's global
// rotation (in template axes), A_k the rest alignment rotating the template's bone direction
// onto the BVH rest bone direction, and C_k the minimal rotation correcting for unmapped
// BVH joints between k and its mapped child, so posed template bone directions equal the BVH
// bone directions. Leaves (no mapped child) use their parent's A. An all-zero BVH frame
// therefore poses the template in the BVH's rest pose (a T-pose for CMU clips). The root's
// rotation goes into Pose::rotation (joint 0 stays identity); the translation puts the
// pelvis centre on the scaled BVH root. Scale 1. Output frame k is at time k / frame_rate
// after the first kept frame. Throws artex::Error on an empty clip (after skip_frames) or
// invalid options.
std::vector<Pose> RetargetBvh(const BvhClip& clip, const Template& tmpl,
                              const BvhRetargetOptions& options = BvhRetargetOptions());
std::vector<Pose> LoadBvhMotion(const std::string& path, const Template& tmpl,
                                const BvhRetargetOptions& options = BvhRetargetOptions());

}  // namespace artex
